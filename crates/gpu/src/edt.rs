//! The exact batch EDT on the GPU (`edt.wgsl`): a scan along x straight
//! from the mask bits into the layout the scan along y reads, that scan, a
//! transpose and the scan along z, all in one compute pass (four
//! dispatches); only the mask goes up
//! (one bit per voxel) and only the distances and nearest obstacles come
//! back, or stay on the device for the exact integration (`exact.rs`).

use crate::context::GpuContext;
use crate::dispatch::{groups_1d, Kernel};
use edtmap_core::{BackendError, CoreError, EdtField, Grid3};

/// Squared diagonals at or above this could overflow the shader's `i32`
/// envelope arithmetic (its largest intermediate is twice the diagonal²).
const MAX_DIAG_SQ: u64 = 1 << 30;

/// Parameter slots, one per dispatch: the scan along x straight from the
/// mask, the scan along y, a transpose, the scan along z.
const SLOTS: usize = 4;

/// Uniform parameters of one dispatch (`BatchEdtParams` in the shader).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct BatchEdtParams {
    len: u32,
    count: u32,
    aux: u32,
    total: u32,
    /// The grid's origin within its first block, when the scan along x
    /// reads resident blocks ([`Mask::Blocks`]).
    o8: [u32; 4],
    /// The grid's blocks along x and y.
    nb: [u32; 4],
}

/// Bytes of [`BatchEdtParams`].
const PARAMS_BYTES: u64 = std::mem::size_of::<BatchEdtParams>() as u64;

/// Where the batch EDT's obstacles come from.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Mask<'a> {
    /// The grid's own bits, uploaded (one bit per voxel).
    Bits(&'a Grid3<bool>),
    /// Blocks resident on the device (`obstacles.rs`): a grid of `dims`
    /// voxels whose first voxel is at `o8` within its first block, and
    /// per block of the grid its slot in `pool` (`slots`, x fastest,
    /// `nb` blocks per axis), or `EMPTY` / `FULL`.
    Blocks { dims: [usize; 3], o8: [u32; 3], nb: [u32; 3], pool: &'a wgpu::Buffer, slots: &'a wgpu::Buffer },
}

/// The batch EDT kernels and their buffers, kept across calls: buffers are
/// allocated for the largest grid seen so far and reused.
#[derive(Debug)]
pub struct GpuEdt {
    ctx: GpuContext,
    scan_x: Kernel,
    /// `scan_x` reading resident blocks ([`Mask::Blocks`]).
    scan_x_blocks: Kernel,
    transpose: Kernel,
    scan: Kernel,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    /// Bytes between parameter slots (the device's uniform offset alignment).
    slot_bytes: u64,
    /// The parameter slots as uploaded, `slot_bytes` apart.
    packed: Vec<u8>,
    /// The mask as uploaded, one bit per voxel.
    bits: Vec<u32>,
    bufs: Option<Buffers>,
}

/// Device buffers for grids of up to `voxels` voxels.
#[derive(Debug)]
struct Buffers {
    voxels: usize,
    mask: wgpu::Buffer,
    /// Where the last scan leaves the pairs (`dst` of `b_to_a`).
    a: wgpu::Buffer,
    /// The other pair buffer, and Meijster's stack.
    b: wgpu::Buffer,
    stack: wgpu::Buffer,
    /// For reading the pairs back, made on the first [`GpuEdt::run`].
    staging: Option<wgpu::Buffer>,
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
                storage(5, true),
            ];
            let layout = ctx
                .device
                .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("edt"), entries: &entries });
            // A power of two at least the alignment and the parameters.
            let slot_bytes =
                u64::from(ctx.limits().min_uniform_buffer_offset_alignment).max(PARAMS_BYTES.next_power_of_two());
            let params = ctx.buffer(
                "edt params",
                slot_bytes * SLOTS as u64,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            );
            let kernel = |entry| Kernel::new(ctx, &module, &layout, entry);
            GpuEdt {
                ctx: ctx.clone(),
                scan_x: kernel("scan_x"),
                scan_x_blocks: Kernel::specialised(ctx, &module, &[&layout], "scan_x", &[("FROM_BLOCKS", 1.0)]),
                transpose: kernel("transpose"),
                scan: kernel("scan"),
                layout,
                params,
                slot_bytes,
                packed: vec![0; slot_bytes as usize * SLOTS],
                bits: Vec::new(),
                bufs: None,
            }
        })
    }

    /// The EDT of `mask` (true = obstacle) into `out`, bit-identical to
    /// the CPU backend's.
    pub fn run(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        let dims = mask.dims();
        let n = EdtField::check_dims(dims)?;
        let mut enc = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("edt") });
        self.encode(mask, &mut enc)?;
        let bytes = 8 * n as u64;
        let bufs = self.bufs.as_mut().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        if bufs.staging.is_none() {
            let size = 8 * bufs.voxels as u64;
            bufs.staging = Some(self.ctx.scoped(|| {
                self.ctx.buffer("edt staging", size, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST)
            })?);
        }
        let staging = bufs.staging.as_ref().ok_or_else(|| BackendError::Device("staging missing".into()))?;
        self.ctx.scoped(|| {
            enc.copy_buffer_to_buffer(&bufs.a, 0, staging, 0, bytes);
            self.ctx.queue.submit([enc.finish()]);
        })?;
        let (dist, nearest) = out.prepare(dims)?;
        self.ctx.read_back(staging, bytes, |bytes| {
            for ((d, s), pair) in dist.iter_mut().zip(nearest.iter_mut()).zip(bytes.chunks_exact(8)) {
                *d = u32::from_ne_bytes([pair[0], pair[1], pair[2], pair[3]]);
                *s = u32::from_ne_bytes([pair[4], pair[5], pair[6], pair[7]]);
            }
        })
    }

    /// Uploads `mask` (one bit per voxel) and records its EDT into `enc`,
    /// leaving the result on the device: [`Self::output`] then holds the
    /// squared distances and the nearest obstacles' linear indices
    /// ([`edtmap_core::NO_SITE`] where there is none), for a later stage
    /// to read there.
    pub(crate) fn encode(&mut self, mask: &Grid3<bool>, enc: &mut wgpu::CommandEncoder) -> Result<(), BackendError> {
        self.encode_mask(Mask::Bits(mask), enc)
    }

    /// [`Self::encode`] with the obstacles from `mask`: uploaded bits or
    /// blocks already on the device, which then upload nothing.
    pub(crate) fn encode_mask(&mut self, mask: Mask<'_>, enc: &mut wgpu::CommandEncoder) -> Result<(), BackendError> {
        let dims = match mask {
            Mask::Bits(bits) => bits.dims(),
            Mask::Blocks { dims, .. } => dims,
        };
        let n = EdtField::check_dims(dims)?;
        let diag_sq: u64 = dims.iter().map(|&d| (d as u64 - 1).pow(2)).sum();
        if diag_sq >= MAX_DIAG_SQ {
            return Err(CoreError::TooLarge {
                dims,
                reason: "squared diagonal of 2^30 or more (the GPU's 32-bit arithmetic)",
            }
            .into());
        }
        self.ensure_buffers(n)?;
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        let [nx, ny, nz] = dims.map(|d| d as u32);
        let total = n as u32;
        let (o8, nb) = match mask {
            Mask::Bits(_) => ([0; 4], [0; 4]),
            Mask::Blocks { o8, nb, .. } => ([o8[0], o8[1], o8[2], 0], [nb[0], nb[1], nb[2], 0]),
        };
        let slots: [BatchEdtParams; SLOTS] = [
            BatchEdtParams { len: nx, count: ny * nz, aux: nz, total, o8, nb },
            BatchEdtParams { len: ny, count: nz * nx, ..BatchEdtParams::default() },
            BatchEdtParams { len: nz, count: nx * ny, ..BatchEdtParams::default() },
            BatchEdtParams { len: nz, count: nx * ny, ..BatchEdtParams::default() },
        ];
        for (k, p) in slots.iter().enumerate() {
            let at = k * self.slot_bytes as usize;
            self.packed[at..at + PARAMS_BYTES as usize].copy_from_slice(bytemuck::bytes_of(p));
        }
        if let Mask::Bits(bits) = mask {
            pack_bits(bits.as_slice(), &mut self.bits);
        }
        let packed = &self.packed;
        self.ctx.scoped(|| {
            let q = &self.ctx.queue;
            q.write_buffer(&self.params, 0, packed);
            // The scan along x reads the uploaded bits, or the pool in
            // place of them with the grid's slot table.
            let from_blocks;
            let (scan_x, first) = match mask {
                Mask::Bits(_) => {
                    q.write_buffer(&bufs.mask, 0, bytemuck::cast_slice(&self.bits));
                    (&self.scan_x, &bufs.a_to_b)
                }
                Mask::Blocks { pool, slots, .. } => {
                    from_blocks = self.group([pool, &bufs.a, &bufs.b, &bufs.stack, slots]);
                    (&self.scan_x_blocks, &from_blocks)
                }
            };
            let mut pass = self.ctx.pass(enc, "edt");
            let offset = |k: usize| (k as u64 * self.slot_bytes) as u32;
            // x straight from the obstacles into B as [z x y]; y from B into
            // A; A transposed into B as [x y z]; z from B into A.
            scan_x.dispatch_at(&mut pass, first, offset(0), groups_1d(u64::from(ny * nz)));
            self.scan.dispatch_at(&mut pass, &bufs.b_to_a, offset(1), groups_1d(u64::from(nz * nx)));
            let tiles = u64::from(nx * ny).div_ceil(16);
            let t_groups = [nz.div_ceil(16), tiles.min(65535) as u32, tiles.div_ceil(65535) as u32];
            self.transpose.dispatch_at(&mut pass, &bufs.a_to_b, offset(2), t_groups);
            self.scan.dispatch_at(&mut pass, &bufs.b_to_a, offset(3), groups_1d(u64::from(nx * ny)));
        })
    }

    /// The device buffer [`Self::encode`] leaves its result in: per voxel
    /// a pair of `u32`, the squared distance and the nearest obstacle.
    pub(crate) fn output(&self) -> Option<&wgpu::Buffer> {
        self.bufs.as_ref().map(|b| &b.a)
    }

    /// Allocates the buffers for `n` voxels unless those in place are large
    /// enough.
    fn ensure_buffers(&mut self, n: usize) -> Result<(), BackendError> {
        if self.bufs.as_ref().is_some_and(|b| b.voxels >= n) {
            return Ok(());
        }
        self.bufs = None;
        let n64 = n as u64;
        self.ctx.check_buffer("the EDT's pair buffers", 8 * n64)?;
        let bufs = self.ctx.scoped(|| {
            let buffer = |label, size, usage| self.ctx.buffer(label, size, usage);
            let storage = wgpu::BufferUsages::STORAGE;
            let mask = buffer("edt mask", n64.div_ceil(32) * 4, storage | wgpu::BufferUsages::COPY_DST);
            let a = buffer("edt A", 8 * n64, storage | wgpu::BufferUsages::COPY_SRC);
            let b = buffer("edt B", 8 * n64, storage);
            let stack = buffer("edt stack", 8 * n64, storage);
            // The slot table is not read when the mask is the grid's bits.
            let (a_to_b, b_to_a) =
                (self.group([&mask, &a, &b, &stack, &mask]), self.group([&mask, &b, &a, &stack, &mask]));
            Buffers { voxels: n, mask, a, b, stack, staging: None, a_to_b, b_to_a }
        })?;
        self.bufs = Some(bufs);
        Ok(())
    }
}

impl GpuEdt {
    /// A bind group of the kernels' layout: the parameters, then `buffers`
    /// at bindings 1 to 5 (mask, src, dst, stack, slots).
    fn group(&self, buffers: [&wgpu::Buffer; 5]) -> wgpu::BindGroup {
        let params = wgpu::BufferBinding { buffer: &self.params, offset: 0, size: wgpu::BufferSize::new(PARAMS_BYTES) };
        let mut resources = vec![wgpu::BindingResource::Buffer(params)];
        resources.extend(buffers.map(|b| b.as_entire_binding()));
        self.ctx.bind_group("edt", &self.layout, &resources)
    }
}

/// Packs `mask` into `bits`, one bit per voxel, voxel `i` at bit `i % 32`
/// of word `i / 32`.
fn pack_bits(mask: &[bool], bits: &mut Vec<u32>) {
    bits.clear();
    bits.extend(mask.chunks(32).map(|chunk| chunk.iter().enumerate().fold(0u32, |w, (k, &b)| w | (u32::from(b) << k))));
}

/// Copies native-endian `u32`s from `bytes` into `out`.
pub(crate) fn copy_words(bytes: &[u8], out: &mut [u32]) {
    out.copy_from_slice(&as_words(bytes));
}

/// `bytes` as native-endian `u32`s: the bytes themselves where aligned (a
/// mapped read-back is on every backend), else a copy.
pub(crate) fn as_words(bytes: &[u8]) -> std::borrow::Cow<'_, [u32]> {
    match bytemuck::try_cast_slice::<u8, u32>(bytes) {
        Ok(words) => std::borrow::Cow::Borrowed(words),
        Err(_) => std::borrow::Cow::Owned(
            bytes.chunks_exact(4).map(|b| u32::from_ne_bytes([b[0], b[1], b[2], b[3]])).collect(),
        ),
    }
}
