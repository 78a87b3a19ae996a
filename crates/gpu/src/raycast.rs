//! Ray casting on the GPU (`raycast.wgsl`): the host sets the rays up
//! (`edtmap_core::fixed_ray::prepare_rays`, shared with the CPU), the
//! device walks them, the observation codes come back, two bits per voxel
//! (unpacked to a byte each on the host).

use crate::context::GpuContext;
use crate::dispatch::{groups_1d, in_out_kernel, unpack_codes, Kernel};
use edtmap_core::fixed_ray::{fixed_scale, FixedRay};
use edtmap_core::BackendError;

/// Uniform parameters (`RaycastParams` in the shader).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct RaycastParams {
    dims: [u32; 4],
    q: u32,
    rays: u32,
    pad: [u32; 2],
}

/// Bytes of one [`FixedRay`]: eight `u32`s, no padding.
const RAY_BYTES: u64 = 32;
const _: () = assert!(std::mem::size_of::<FixedRay>() == RAY_BYTES as usize);

/// The ray-casting kernel and its buffers, reused across frames.
#[derive(Debug)]
pub struct GpuRaycast {
    ctx: GpuContext,
    kernel: Kernel,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    bufs: Option<Buffers>,
}

#[derive(Debug)]
struct Buffers {
    rays: usize,
    voxels: usize,
    ray_buf: wgpu::Buffer,
    obs: wgpu::Buffer,
    staging: wgpu::Buffer,
    group: wgpu::BindGroup,
}

impl GpuRaycast {
    /// Compiles the kernel once for `ctx`.
    pub fn new(ctx: &GpuContext) -> Result<Self, BackendError> {
        ctx.scoped(|| {
            let (kernel, layout, params) = in_out_kernel(
                ctx,
                "raycast.wgsl",
                include_str!("raycast.wgsl"),
                "cast_rays",
                std::mem::size_of::<RaycastParams>() as u64,
                1,
            );
            GpuRaycast { ctx: ctx.clone(), kernel, layout, params, bufs: None }
        })
    }

    /// Walks `rays` (set up at scale `q` for a volume of `dims`) into
    /// `bits`, one byte per voxel (two bits each on the way back).
    /// `Ok(false)` when `q` does not fit `dims`
    /// (the CPU then walks nothing either, so it is left to it).
    pub fn run(
        &mut self,
        rays: &[FixedRay],
        q: u32,
        dims: [usize; 3],
        bits: &mut Vec<u8>,
    ) -> Result<bool, BackendError> {
        if !self.encode(rays, q, dims, true)? {
            return Ok(false);
        }
        let voxels: usize = dims.iter().product();
        let words = voxels.div_ceil(16) as u64;
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        bits.resize(voxels, 0);
        self.ctx.read_back(&bufs.staging, 4 * words, |b| unpack_codes(b, bits))?;
        Ok(true)
    }

    /// [`Self::run`] with the codes left on the device ([`Self::codes`]),
    /// nothing read back.
    pub(crate) fn run_kept(&mut self, rays: &[FixedRay], q: u32, dims: [usize; 3]) -> Result<bool, BackendError> {
        self.encode(rays, q, dims, false)
    }

    /// The codes of the last walk, two bits per voxel (sixteen to a word),
    /// on the device.
    pub(crate) fn codes(&self) -> Option<&wgpu::Buffer> {
        self.bufs.as_ref().map(|b| &b.obs)
    }

    /// Records and submits the walk, with the codes' copy for reading
    /// back when `download`; `Ok(false)` when `q` does not fit `dims`.
    fn encode(&mut self, rays: &[FixedRay], q: u32, dims: [usize; 3], download: bool) -> Result<bool, BackendError> {
        let fits = fixed_scale(dims).is_ok_and(|max| q >= 1 && q <= max);
        if !fits {
            return Ok(false);
        }
        let voxels: usize = dims.iter().product();
        let words = voxels.div_ceil(16) as u64;
        self.ensure_buffers(rays.len().max(1), voxels)?;
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        let params = RaycastParams {
            dims: [dims[0] as u32, dims[1] as u32, dims[2] as u32, voxels as u32],
            q,
            rays: rays.len() as u32,
            pad: [0; 2],
        };
        // SAFETY: `FixedRay` is `repr(C)`, eight `u32`s with no padding
        // (asserted above), so its bytes are plain data.
        let ray_bytes =
            unsafe { std::slice::from_raw_parts(rays.as_ptr().cast::<u8>(), rays.len() * RAY_BYTES as usize) };
        self.ctx.scoped(|| {
            let q = &self.ctx.queue;
            q.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
            if !ray_bytes.is_empty() {
                q.write_buffer(&bufs.ray_buf, 0, ray_bytes);
            }
            let mut enc =
                self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("raycast") });
            enc.clear_buffer(&bufs.obs, 0, Some(4 * words));
            {
                let mut pass = self.ctx.pass(&mut enc, "raycast");
                if !rays.is_empty() {
                    self.kernel.dispatch(&mut pass, &[&bufs.group], groups_1d(rays.len() as u64));
                }
            }
            if download {
                enc.copy_buffer_to_buffer(&bufs.obs, 0, &bufs.staging, 0, 4 * words);
            }
            q.submit([enc.finish()]);
        })?;
        Ok(true)
    }

    fn ensure_buffers(&mut self, rays: usize, voxels: usize) -> Result<(), BackendError> {
        if self.bufs.as_ref().is_some_and(|b| b.rays >= rays && b.voxels >= voxels) {
            return Ok(());
        }
        let (rays, voxels) = self.bufs.as_ref().map_or((rays, voxels), |b| (b.rays.max(rays), b.voxels.max(voxels)));
        self.bufs = None;
        let words = voxels.div_ceil(16) as u64;
        self.ctx.check_buffer("the rays", RAY_BYTES * rays as u64)?;
        self.ctx.check_buffer("the observation bits", 4 * words)?;
        let bufs = self.ctx.scoped(|| {
            let buffer = |label, size, usage| self.ctx.buffer(label, size, usage);
            let ray_buf = buffer(
                "raycast rays",
                RAY_BYTES * rays as u64,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            );
            let obs = buffer(
                "raycast obs",
                4 * words,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            );
            let staging =
                buffer("raycast staging", 4 * words, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
            let group = self.ctx.bind_group(
                "raycast",
                &self.layout,
                &[&self.params, &ray_buf, &obs].map(|b| b.as_entire_binding()),
            );
            Buffers { rays, voxels, ray_buf, obs, staging, group }
        })?;
        self.bufs = Some(bufs);
        Ok(())
    }
}
