//! Small helpers shared by the kernels: pipelines, bind group layout
//! entries and dispatch sizes.

use std::sync::atomic::Ordering;
use std::sync::Arc;

use crate::context::{Counters, GpuContext};

/// Invocations per workgroup of the one-dimensional kernels (`GROUP` in
/// the shaders).
pub(crate) const GROUP: u64 = 64;

/// Most workgroups along one dispatch dimension (WebGPU's default limit).
const MAX_GROUPS: u64 = 65535;

/// One entry point of a shader module, compiled once.
#[derive(Debug)]
pub(crate) struct Kernel {
    pipeline: wgpu::ComputePipeline,
    /// The context's counters, for the dispatches this kernel records.
    counters: Arc<Counters>,
}

impl Kernel {
    /// Compiles `entry` of `module` with a single bind group of `layout`.
    pub(crate) fn new(
        ctx: &GpuContext,
        module: &wgpu::ShaderModule,
        layout: &wgpu::BindGroupLayout,
        entry: &str,
    ) -> Self {
        Self::with_layouts(ctx, module, &[layout], entry)
    }

    /// Compiles `entry` of `module` with bind groups of `layouts`.
    pub(crate) fn with_layouts(
        ctx: &GpuContext,
        module: &wgpu::ShaderModule,
        layouts: &[&wgpu::BindGroupLayout],
        entry: &str,
    ) -> Self {
        Self::specialised(ctx, module, layouts, entry, &[])
    }

    /// Compiles `entry` of `module` with bind groups of `layouts` and the
    /// shader's overridable constants set to `constants`.
    pub(crate) fn specialised(
        ctx: &GpuContext,
        module: &wgpu::ShaderModule,
        layouts: &[&wgpu::BindGroupLayout],
        entry: &str,
        constants: &[(&str, f64)],
    ) -> Self {
        let layouts: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().map(|&l| Some(l)).collect();
        let pipeline_layout = ctx.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(entry),
            bind_group_layouts: &layouts,
            immediate_size: 0,
        });
        let pipeline = ctx.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: Some(&pipeline_layout),
            module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
            cache: None,
        });
        Kernel { pipeline, counters: ctx.counter_handle() }
    }

    /// Records one dispatch of `groups` workgroups with `group` bound at the
    /// dynamic uniform offset `offset`.
    pub(crate) fn dispatch_at(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        group: &wgpu::BindGroup,
        offset: u32,
        groups: [u32; 3],
    ) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, group, &[offset]);
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        self.counters.dispatches.fetch_add(1, Ordering::Relaxed);
    }

    /// Records one dispatch of `groups` workgroups with `bind[k]` as bind
    /// group `k`.
    pub(crate) fn dispatch(&self, pass: &mut wgpu::ComputePass<'_>, bind: &[&wgpu::BindGroup], groups: [u32; 3]) {
        self.bind(pass, bind);
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        self.counters.dispatches.fetch_add(1, Ordering::Relaxed);
    }

    /// Records one dispatch whose workgroup counts the device wrote at
    /// byte `offset` of `args`.
    pub(crate) fn dispatch_indirect(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        bind: &[&wgpu::BindGroup],
        args: &wgpu::Buffer,
        offset: u64,
    ) {
        self.bind(pass, bind);
        pass.dispatch_workgroups_indirect(args, offset);
        self.counters.dispatches.fetch_add(1, Ordering::Relaxed);
    }

    fn bind(&self, pass: &mut wgpu::ComputePass<'_>, bind: &[&wgpu::BindGroup]) {
        pass.set_pipeline(&self.pipeline);
        for (k, group) in bind.iter().enumerate() {
            pass.set_bind_group(k as u32, *group, &[]);
        }
    }
}

/// A shader with one entry point over one bind group: a uniform parameter
/// block at binding 0 (`params_bytes` long), a read-only input at 1 and
/// `outputs` outputs from 2 on, the layout of the ray-casting and
/// projection kernels. Returns the kernel, its layout and the parameter
/// buffer.
pub(crate) fn in_out_kernel(
    ctx: &GpuContext,
    file: &str,
    source: &str,
    entry: &str,
    params_bytes: u64,
    outputs: u32,
) -> (Kernel, wgpu::BindGroupLayout, wgpu::Buffer) {
    let dev = &ctx.device;
    let module = dev.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(file),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let mut entries = vec![uniform_entry(0, false), storage_entry(1, true)];
    entries.extend((0..outputs).map(|k| storage_entry(2 + k, false)));
    let layout =
        dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(entry), entries: &entries });
    let params = ctx.buffer(entry, params_bytes, wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST);
    (Kernel::new(ctx, &module, &layout, entry), layout, params)
}

/// A uniform buffer binding visible to compute shaders; `dynamic` for a
/// dynamic offset into a buffer of several parameter slots.
pub(crate) fn uniform_entry(binding: u32, dynamic: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A storage buffer binding visible to compute shaders.
pub(crate) fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Workgroups for `items` one-dimensional invocations, spread over x and y
/// (the shaders' `flat_id`).
pub(crate) fn groups_1d(items: u64) -> [u32; 3] {
    let groups = items.div_ceil(GROUP).max(1);
    [groups.min(MAX_GROUPS) as u32, groups.div_ceil(MAX_GROUPS) as u32, 1]
}

/// Expands two-bit codes, sixteen per native-endian word (voxel `i` at
/// bits `2 (i % 16)` of word `i / 16`), into one byte each, filling `out`.
pub(crate) fn unpack_codes(words: &[u8], out: &mut [u8]) {
    for (chunk, word) in out.chunks_mut(16).zip(words.chunks_exact(4)) {
        let w = u32::from_ne_bytes([word[0], word[1], word[2], word[3]]);
        for (k, o) in chunk.iter_mut().enumerate() {
            *o = ((w >> (2 * k)) & 3) as u8;
        }
    }
}
