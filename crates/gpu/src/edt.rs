//! The exact batch EDT on the GPU (`edt.wgsl`): init, then for each axis a
//! transpose and a scan, all in one compute pass; only the mask goes up
//! and only the distances and nearest obstacles come back.

use crate::context::GpuContext;
use crate::dispatch::{groups_1d, Kernel};
use edtmap_core::{BackendError, CoreError, EdtField, Grid3};

/// Squared diagonals at or above this could overflow the shader's `i32`
/// envelope arithmetic (its largest intermediate is twice the diagonal²).
const MAX_DIAG_SQ: u64 = 1 << 30;

/// Parameter slots, one per dispatch: init, then (transpose, scan) × 3.
const SLOTS: usize = 7;

/// Uniform parameters of one dispatch (`Params` in the shader).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    len: u32,
    count: u32,
    final_out: u32,
    total: u32,
}

/// The batch EDT kernels and their buffers, kept across calls: buffers are
/// allocated for the largest grid seen so far and reused.
#[derive(Debug)]
pub struct GpuEdt {
    ctx: GpuContext,
    init: Kernel,
    transpose: Kernel,
    scan: Kernel,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    /// Bytes between parameter slots (the device's uniform offset alignment).
    slot_bytes: u64,
    /// The parameter slots as uploaded, `slot_bytes` apart.
    packed: Vec<u8>,
    bufs: Option<Buffers>,
}

/// Device buffers for grids of up to `voxels` voxels.
#[derive(Debug)]
struct Buffers {
    voxels: usize,
    mask: wgpu::Buffer,
    out_d: wgpu::Buffer,
    out_s: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// src = A, dst = B, and the reverse (A is the other ping-pong buffer).
    a_to_b: wgpu::BindGroup,
    b_to_a: wgpu::BindGroup,
}

impl GpuEdt {
    /// Compiles the kernels once for `ctx`.
    pub fn new(ctx: &GpuContext) -> Result<Self, BackendError> {
        ctx.scoped(|| {
            let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("edt.wgsl"),
                source: wgpu::ShaderSource::Wgsl(include_str!("edt.wgsl").into()),
            });
            let storage = |binding, read_only| crate::dispatch::storage_entry(binding, read_only);
            let entries = [
                crate::dispatch::uniform_entry(0, true),
                storage(1, true),
                storage(2, true),
                storage(3, false),
                storage(4, false),
                storage(5, false),
                storage(6, false),
            ];
            let layout = ctx.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("edt"),
                entries: &entries,
            });
            let slot_bytes = u64::from(ctx.limits().min_uniform_buffer_offset_alignment).max(16);
            let params = ctx.buffer("edt params", slot_bytes * SLOTS as u64, wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST);
            let kernel = |entry| Kernel::new(ctx, &module, &layout, entry);
            GpuEdt {
                ctx: ctx.clone(),
                init: kernel("init"),
                transpose: kernel("transpose"),
                scan: kernel("scan"),
                layout,
                params,
                slot_bytes,
                packed: vec![0; slot_bytes as usize * SLOTS],
                bufs: None,
            }
        })
    }

    /// The EDT of `mask` (true = obstacle) into `out`, bit-identical to
    /// the CPU backend's.
    pub fn run(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        let dims = mask.dims();
        let n = EdtField::check_dims(dims)?;
        let diag_sq: u64 = dims.iter().map(|&d| (d as u64 - 1).pow(2)).sum();
        if diag_sq >= MAX_DIAG_SQ {
            return Err(CoreError::TooLarge { dims, reason: "squared diagonal of 2^30 or more (the GPU's 32-bit arithmetic)" }.into());
        }
        self.ensure_buffers(n)?;
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        let [nx, ny, nz] = dims.map(|d| d as u32);
        let total = n as u32;
        let slots: [Params; SLOTS] = [
            Params { total, ..Params::default() },
            Params { len: nx, count: ny * nz, ..Params::default() },
            Params { len: nx, count: ny * nz, ..Params::default() },
            Params { len: ny, count: nz * nx, ..Params::default() },
            Params { len: ny, count: nz * nx, ..Params::default() },
            Params { len: nz, count: nx * ny, ..Params::default() },
            Params { len: nz, count: nx * ny, final_out: 1, total },
        ];
        for (k, p) in slots.iter().enumerate() {
            let at = k * self.slot_bytes as usize;
            self.packed[at..at + 16].copy_from_slice(bytemuck::bytes_of(p));
        }
        let packed = &self.packed;
        let bytes_out = 4 * n as u64;
        self.ctx.scoped(|| {
            let q = &self.ctx.queue;
            q.write_buffer(&self.params, 0, packed);
            write_mask(q, &bufs.mask, mask.as_slice());
            let mut enc = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("edt") });
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("edt"), timestamp_writes: None });
                let offset = |k: usize| (k as u64 * self.slot_bytes) as u32;
                self.init.dispatch_at(&mut pass, &bufs.b_to_a, offset(0), groups_1d(n as u64));
                let axes = [(nx, ny * nz), (ny, nz * nx), (nz, nx * ny)];
                for (axis, &(len, count)) in axes.iter().enumerate() {
                    let tiles = u64::from(count).div_ceil(16);
                    let t_groups = [len.div_ceil(16), tiles.min(65535) as u32, tiles.div_ceil(65535) as u32];
                    self.transpose.dispatch_at(&mut pass, &bufs.a_to_b, offset(1 + 2 * axis), t_groups);
                    self.scan.dispatch_at(&mut pass, &bufs.b_to_a, offset(2 + 2 * axis), groups_1d(u64::from(count)));
                }
            }
            enc.copy_buffer_to_buffer(&bufs.out_d, 0, &bufs.staging, 0, bytes_out);
            enc.copy_buffer_to_buffer(&bufs.out_s, 0, &bufs.staging, bytes_out, bytes_out);
            q.submit([enc.finish()]);
        })?;
        let (dist, nearest) = out.prepare(dims)?;
        self.ctx.read_back(&bufs.staging, 2 * bytes_out, |bytes| {
            let (d, s) = bytes.split_at(bytes_out as usize);
            copy_words(d, dist);
            copy_words(s, nearest);
        })
    }

    /// Allocates the buffers for `n` voxels unless those in place are large
    /// enough.
    fn ensure_buffers(&mut self, n: usize) -> Result<(), BackendError> {
        if self.bufs.as_ref().is_some_and(|b| b.voxels >= n) {
            return Ok(());
        }
        self.bufs = None;
        let n64 = n as u64;
        for (what, bytes) in [("the EDT's pair buffers", 8 * n64), ("the EDT's output", 4 * n64)] {
            self.ctx.check_buffer(what, bytes)?;
        }
        let bufs = self.ctx.scoped(|| {
            let buffer = |label, size, usage| self.ctx.buffer(label, size, usage);
            let storage = wgpu::BufferUsages::STORAGE;
            let mask = buffer("edt mask", n64.div_ceil(4) * 4, storage | wgpu::BufferUsages::COPY_DST);
            let a = buffer("edt A", 8 * n64, storage);
            let b = buffer("edt B", 8 * n64, storage);
            let stack = buffer("edt stack", 8 * n64, storage);
            let out_d = buffer("edt distances", 4 * n64, storage | wgpu::BufferUsages::COPY_SRC);
            let out_s = buffer("edt nearest", 4 * n64, storage | wgpu::BufferUsages::COPY_SRC);
            let staging = buffer("edt staging", 8 * n64, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
            let group = |src: &wgpu::Buffer, dst: &wgpu::Buffer| {
                let params = wgpu::BufferBinding { buffer: &self.params, offset: 0, size: wgpu::BufferSize::new(16) };
                let mut resources = vec![wgpu::BindingResource::Buffer(params)];
                resources.extend([&mask, src, dst, &stack, &out_d, &out_s].map(|b| b.as_entire_binding()));
                self.ctx.bind_group("edt", &self.layout, &resources)
            };
            let (a_to_b, b_to_a) = (group(&a, &b), group(&b, &a));
            Buffers { voxels: n, mask, out_d, out_s, staging, a_to_b, b_to_a }
        })?;
        self.bufs = Some(bufs);
        Ok(())
    }
}

/// Uploads the mask, one byte per voxel, padded to whole words.
fn write_mask(queue: &crate::context::CountingQueue, buffer: &wgpu::Buffer, mask: &[bool]) {
    // SAFETY: `bool` is one byte holding 0 or 1, so a `[bool]` is a valid
    // `[u8]` of the same length.
    let bytes = unsafe { std::slice::from_raw_parts(mask.as_ptr().cast::<u8>(), mask.len()) };
    let whole = bytes.len() / 4 * 4;
    if whole > 0 {
        queue.write_buffer(buffer, 0, &bytes[..whole]);
    }
    if whole < bytes.len() {
        let mut tail = [0u8; 4];
        tail[..bytes.len() - whole].copy_from_slice(&bytes[whole..]);
        queue.write_buffer(buffer, whole as u64, &tail);
    }
}

/// Copies native-endian `u32`s from `bytes` into `out`.
pub(crate) fn copy_words(bytes: &[u8], out: &mut [u32]) {
    match bytemuck::try_cast_slice::<u8, u32>(bytes) {
        Ok(words) => out.copy_from_slice(words),
        Err(_) => {
            for (o, b) in out.iter_mut().zip(bytes.chunks_exact(4)) {
                *o = u32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
            }
        }
    }
}
