//! Volumetric projection on the GPU (`project.wgsl`): every voxel decided
//! in `f32` with a bound on its distance from the CPU's decision
//! (`edtmap_core::ProjectJob::is_miss`); the voxels near a threshold come
//! back uncertain and the host decides them, so the result is the CPU's,
//! bit for bit.
//!
//! The host prepares what would cost the device precision: the sensor's
//! origin relative to the volume split into an integer voxel offset and a
//! fraction (so the device's coordinates are small and exact where they
//! can be), the rotation, and per pixel or beam the range below which a
//! point is free (`ProjectJob::free_below_m`, the CPU's own `f32`
//! subtraction). Depth cameras, planar scans and spinning LiDARs run here
//! (for a LiDAR also its ring elevations and the bounds between them).

use crate::context::GpuContext;
use crate::dispatch::{groups_1d, in_out_kernel, unpack_codes, Kernel};
use edtmap_core::sensor::View;
use edtmap_core::{BackendError, ProjectJob};
use std::f64::consts::TAU;

/// Uniform parameters (`ProjectParams` in the shader).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct ProjectParams {
    dims: [u32; 4],
    base: [i32; 4],
    frac: [f32; 4],
    rot: [[f32; 4]; 3],
    cam: [f32; 4],
    img: [u32; 4],
    scan: [f32; 4],
    wrap: [i32; 4],
    err: [f32; 4],
    lidar: [u32; 4],
}

/// `ProjectParams::base[3]` of a depth camera and of a planar scan.
const KIND_DEPTH: i32 = 0;
const KIND_PLANAR: i32 = 1;
const KIND_LIDAR: i32 = 2;

/// What [`GpuProject::run_kept`] read back.
#[derive(Debug)]
pub(crate) enum Kept {
    /// The uncertain voxels' indices; the codes stay on the device.
    Uncertain(Vec<u32>),
    /// Every code, into the caller's bytes: more voxels were uncertain
    /// than the list holds.
    Codes,
}

/// How many uncertain voxels the list of a volume of `voxels` holds: a
/// sixteenth of them (at least 4096), a quarter byte each as the codes.
fn list_capacity(voxels: usize) -> usize {
    (voxels / 16).max(4096).min(voxels)
}

/// Largest voxel offset the shader takes exactly (`x - n` in `f32`).
const MAX_OFFSET: f64 = (1u32 << 22) as f64;

/// Bound on the relative error of the host's `f64` arithmetic (a few
/// roundings of 2⁻⁵³, with room to spare), applied to the magnitudes involved.
const HOST_REL_ERR: f64 = 1.0 / (1u64 << 48) as f64;

/// The projection kernel and its buffers, reused across frames.
#[derive(Debug)]
pub struct GpuProject {
    ctx: GpuContext,
    kernel: Kernel,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    /// Per pixel or beam: `ProjectJob::free_below_m`.
    free_below: Vec<f32>,
    bufs: Option<Buffers>,
    /// How many uncertain voxels to read back with their count.
    uncertain_guess: usize,
    /// The most uncertain voxels the list holds, below its default.
    max_listed: usize,
}

#[derive(Debug)]
struct Buffers {
    beams: usize,
    voxels: usize,
    free_below: wgpu::Buffer,
    out: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// How many voxels are uncertain, then their indices (up to
    /// `capacity`).
    uncertain: wgpu::Buffer,
    capacity: usize,
    group: wgpu::BindGroup,
}

impl GpuProject {
    /// Compiles the kernel once for `ctx`.
    pub fn new(ctx: &GpuContext) -> Result<Self, BackendError> {
        ctx.scoped(|| {
            let (kernel, layout, params) = in_out_kernel(
                ctx,
                "project.wgsl",
                include_str!("project.wgsl"),
                "project",
                std::mem::size_of::<ProjectParams>() as u64,
                2,
            );
            GpuProject {
                ctx: ctx.clone(),
                kernel,
                layout,
                params,
                free_below: Vec::new(),
                bufs: None,
                uncertain_guess: 4096,
                max_listed: usize::MAX,
            }
        })
    }

    /// Decides every voxel of `job.volume` into `bits`, one byte per voxel
    /// (two bits each on the way back)
    /// (see `Backend::project_volume`). `Ok(false)` for geometry beyond
    /// the shader's exact range (a sensor millions of
    /// voxels away, a scan of more than 2²⁴ beams per turn).
    pub fn run(&mut self, job: &ProjectJob<'_>, bits: &mut Vec<u8>) -> Result<bool, BackendError> {
        let voxels = job.volume.len();
        let words = voxels.div_ceil(16) as u64;
        if !self.encode(job, |enc, bufs| enc.copy_buffer_to_buffer(&bufs.out, 0, &bufs.staging, 0, 4 * words))? {
            return Ok(false);
        }
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        bits.resize(voxels, 0);
        self.ctx.read_back(&bufs.staging, 4 * words, |b| unpack_codes(b, bits))?;
        Ok(true)
    }

    /// [`Self::run`] with the codes left on the device ([`Self::codes`])
    /// and only the uncertain voxels read back: their linear indices, in
    /// no particular order ([`Kept::Uncertain`]). `Ok(None)` where the
    /// kernel does not apply.
    ///
    /// The count comes back with as many indices as the last frame had
    /// and a quarter more (one round trip); only a frame with more needs a
    /// second. The list holds a sixteenth of the voxels (a quarter byte
    /// each, as the codes); a frame with more uncertain voxels reads every
    /// code back into `bits` instead, as [`Self::run`] does
    /// ([`Kept::Codes`]).
    pub(crate) fn run_kept(&mut self, job: &ProjectJob<'_>, bits: &mut Vec<u8>) -> Result<Option<Kept>, BackendError> {
        let voxels = job.volume.len();
        let guess = self.uncertain_guess.min(list_capacity(voxels)).min(self.max_listed);
        if !self.encode(job, |enc, bufs| {
            enc.copy_buffer_to_buffer(&bufs.uncertain, 0, &bufs.staging, 0, 4 + 4 * guess as u64)
        })? {
            return Ok(None);
        }
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        let (mut list, mut count) = (Vec::new(), 0);
        let capacity = bufs.capacity;
        self.ctx.read_back(&bufs.staging, 4 + 4 * guess as u64, |b| {
            count = u32::from_ne_bytes([b[0], b[1], b[2], b[3]]) as usize;
            if count <= capacity {
                list = vec![0u32; count];
                let have = count.min(guess);
                crate::edt::copy_words(&b[4..4 + 4 * have], &mut list[..have]);
            }
        })?;
        if count > voxels {
            return Err(BackendError::Device(format!("the projection listed {count} uncertain voxels of {voxels}")));
        }
        if count > capacity {
            let words = voxels.div_ceil(16) as u64;
            self.ctx.scoped(|| {
                let mut enc = self
                    .ctx
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("project codes") });
                enc.copy_buffer_to_buffer(&bufs.out, 0, &bufs.staging, 0, 4 * words);
                self.ctx.queue.submit([enc.finish()]);
            })?;
            bits.resize(voxels, 0);
            self.ctx.read_back(&bufs.staging, 4 * words, |b| unpack_codes(b, bits))?;
            return Ok(Some(Kept::Codes));
        }
        if count > guess {
            let bytes = 4 * (count - guess) as u64;
            self.ctx.scoped(|| {
                let mut enc = self
                    .ctx
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("project uncertain") });
                enc.copy_buffer_to_buffer(&bufs.uncertain, 4 + 4 * guess as u64, &bufs.staging, 0, bytes);
                self.ctx.queue.submit([enc.finish()]);
            })?;
            self.ctx.read_back(&bufs.staging, bytes, |b| crate::edt::copy_words(b, &mut list[guess..]))?;
        }
        if list.iter().any(|&i| i as usize >= voxels) {
            return Err(BackendError::Device("the projection listed an uncertain voxel outside the volume".into()));
        }
        self.uncertain_guess = count + count / 4 + 256;
        Ok(Some(Kept::Uncertain(list)))
    }

    /// The codes of the last projection, two bits per voxel (sixteen to a
    /// word), on the device.
    pub(crate) fn codes(&self) -> Option<&wgpu::Buffer> {
        self.bufs.as_ref().map(|b| &b.out)
    }

    /// Records and submits the projection of `job` and `copy` after it;
    /// `Ok(false)` where the kernel does not apply.
    fn encode(
        &mut self,
        job: &ProjectJob<'_>,
        copy: impl FnOnce(&mut wgpu::CommandEncoder, &Buffers),
    ) -> Result<bool, BackendError> {
        let Some(params) = self.prepare(job) else { return Ok(false) };
        let voxels = job.volume.len();
        let words = voxels.div_ceil(16) as u64;
        self.ensure_buffers(self.free_below.len(), voxels)?;
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        self.ctx.scoped(|| {
            let q = &self.ctx.queue;
            q.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
            q.write_buffer(&bufs.free_below, 0, bytemuck::cast_slice(&self.free_below));
            let mut enc =
                self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("project") });
            enc.clear_buffer(&bufs.uncertain, 0, Some(4));
            {
                let mut pass = self.ctx.pass(&mut enc, "project");
                self.kernel.dispatch(&mut pass, &[&bufs.group], groups_1d(words));
            }
            copy(&mut enc, bufs);
            q.submit([enc.finish()]);
        })?;
        Ok(true)
    }

    /// The shader's parameters for `job`, with `self.free_below` filled;
    /// `None` where the shader does not apply.
    fn prepare(&mut self, job: &ProjectJob<'_>) -> Option<ProjectParams> {
        let geom = job.voxel_to_sensor();
        let s = geom.voxel_size_m;
        let dims = job.volume.dims;
        let voxels = u32::try_from(job.volume.len()).ok()?;
        let mut p = ProjectParams {
            dims: [dims[0] as u32, dims[1] as u32, dims[2] as u32, voxels],
            ..ProjectParams::default()
        };
        let mut magnitude = 0.0;
        for (k, &dim) in dims.iter().enumerate() {
            // d / s = x + 1/2 - o / s = (x - n) - f, with n an integer.
            let a = geom.origin_m[k] / s - 0.5;
            let n = a.round();
            let exact = n.abs() + (dim as f64) < MAX_OFFSET;
            if !exact {
                return None;
            }
            p.base[k] = n as i32;
            p.frac[k] = (a - n) as f32;
            p.rot[k] = [geom.rot[k][0] as f32, geom.rot[k][1] as f32, geom.rot[k][2] as f32, 0.0];
            magnitude += dim as f64 * s + geom.origin_m[k].abs();
        }
        p.frac[3] = s as f32;
        p.err[0] = (HOST_REL_ERR * magnitude) as f32;
        self.free_below.clear();
        match job.view {
            View::Pinhole { camera: cam, image: img } => {
                p.base[3] = KIND_DEPTH;
                p.cam = [cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32];
                p.img = [img.width, img.height, 0, 0];
                let pixels = img.width as usize * img.height as usize;
                self.free_below.extend((0..pixels).map(|i| job.free_below_m(img.depth_m(i), &cam.range)));
            }
            View::Sweep { scan } => {
                p.base[3] = KIND_PLANAR;
                let inc = scan.angle_increment_rad;
                // LaserScan::beam wraps the indices i >= floor(turn) with
                // |i - turn| < 1 to beam 0.
                let turn = TAU / inc.abs();
                let exact = turn < MAX_OFFSET && scan.ranges.len() < 1 << 24;
                if !exact {
                    return None;
                }
                let first = turn.floor();
                let last = if (first + 1.0 - turn).abs() < 1.0 { first + 1.0 } else { first };
                p.wrap = [first as i32, last as i32, 0, 0];
                p.img = [0, 0, scan.ranges.len() as u32, 0];
                let sign = if inc < 0.0 { -1.0 } else { 1.0 };
                p.scan =
                    [scan.angle_min_rad.rem_euclid(TAU) as f32, sign, inc.abs() as f32, job.planar_half_thickness_m];
                p.err[1] = (HOST_REL_ERR * (scan.angle_min_rad.abs() + 4.0 * TAU)) as f32;
                self.free_below.extend(scan.ranges.iter().map(|&d| job.free_below_m(d, &scan.range)));
            }
            View::Rings { lidar, scan } => {
                p.base[3] = KIND_LIDAR;
                let rings = &lidar.ring_elevations_rad;
                let beams = scan.ranges.len();
                if beams != rings.len() * lidar.azimuth_bins || beams + 2 * rings.len() + 1 >= u32::MAX as usize {
                    return None;
                }
                p.lidar = [lidar.azimuth_bins as u32, rings.len() as u32, beams as u32, (beams + rings.len()) as u32];
                // The radius SpinningLidar::ring_passes_at is given.
                p.scan[3] = (job.volume.voxel_size_m / 2.0) as f32;
                self.free_below.extend(scan.ranges.iter().map(|&d| job.free_below_m(d, &lidar.range)));
                self.free_below.extend(rings.iter().map(|&e| e as f32));
                // Ring k is the nearest on [bound k, bound k + 1): the fan's
                // ends, and the midpoints between rings.
                let (lo, hi) = lidar.fan_rad();
                self.free_below.push(lo as f32);
                self.free_below.extend(rings.windows(2).map(|w| ((w[0] + w[1]) / 2.0) as f32));
                self.free_below.push(hi as f32);
            }
        }
        Some(p)
    }

    /// Lists at most `voxels` uncertain voxels for [`Self::run_kept`]
    /// (default: a sixteenth of the volume); a frame with more reads every
    /// code back.
    pub(crate) fn limit_list(&mut self, voxels: usize) {
        self.max_listed = voxels;
        self.bufs = None;
    }

    fn ensure_buffers(&mut self, beams: usize, voxels: usize) -> Result<(), BackendError> {
        let beams = beams.max(1);
        if self.bufs.as_ref().is_some_and(|b| b.beams >= beams && b.voxels >= voxels) {
            return Ok(());
        }
        let (beams, voxels) =
            self.bufs.as_ref().map_or((beams, voxels), |b| (b.beams.max(beams), b.voxels.max(voxels)));
        self.bufs = None;
        let words = voxels.div_ceil(16).max(1) as u64;
        self.ctx.check_buffer("the free ranges of the pixels or beams", 4 * beams as u64)?;
        self.ctx.check_buffer("the projection bits", 4 * words)?;
        let capacity = list_capacity(voxels).min(self.max_listed);
        self.ctx.check_buffer("the projection's uncertain voxels", 4 + 4 * capacity as u64)?;
        let bufs = self.ctx.scoped(|| {
            let buffer = |label, size, usage| self.ctx.buffer(label, size, usage);
            let free_below = buffer(
                "project free ranges",
                4 * beams as u64,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            );
            let out = buffer("project bits", 4 * words, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC);
            let uncertain = buffer(
                "project uncertain",
                4 + 4 * capacity as u64,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            );
            // The codes, or the uncertain voxels' list.
            let staging = buffer(
                "project staging",
                (4 * words).max(4 + 4 * capacity as u64),
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            );
            let group = self.ctx.bind_group(
                "project",
                &self.layout,
                &[&self.params, &free_below, &out, &uncertain].map(|b| b.as_entire_binding()),
            );
            Buffers { beams, voxels, free_below, out, staging, uncertain, capacity, group }
        })?;
        self.bufs = Some(bufs);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    /// `atan2_acc` of `project.wgsl`, line for line, with both divisions
    /// scaled by `1 + e` (the shader's division is within 2.5 ulp).
    fn atan2_acc(y: f32, x: f32, e: f32) -> f32 {
        use std::f32::consts::PI;
        let (ax, ay) = (x.abs(), y.abs());
        let a = (ax.min(ay) / ax.max(ay) * (1.0 + e)).min(1.0);
        let (mut t, mut base) = (a, 0.0);
        if a > 0.414_213_57 {
            t = (a - 1.0) / (a + 1.0) * (1.0 + e);
            base = PI / 4.0;
        }
        let t2 = t * t;
        let mut s = -1.0 / 15.0;
        for c in [1.0 / 13.0, -1.0 / 11.0, 1.0 / 9.0, -1.0 / 7.0, 1.0 / 5.0, -1.0 / 3.0] {
            s = c + t2 * s;
        }
        let mut ang = base + (t + t * t2 * s);
        if ay > ax {
            ang = PI / 2.0 - ang;
        }
        if x < 0.0 {
            ang = PI - ang;
        }
        if y < 0.0 {
            ang = -ang;
        }
        ang
    }

    #[test]
    fn shader_atan2_is_within_its_bound() {
        // ANGLE_ERR in the shader: 4e-6 rad; the analysis gives 1.6e-6.
        let five_u = 5.0 * f32::EPSILON / 2.0;
        let mut worst = 0f64;
        for k in 0..200_000 {
            let angle = -std::f64::consts::PI + std::f64::consts::TAU * k as f64 / 200_000.0;
            let r = 0.01 + (k % 97) as f64;
            let (x, y) = ((r * angle.cos()) as f32, (r * angle.sin()) as f32);
            let exact = f64::from(y).atan2(f64::from(x));
            for e in [-five_u, 0.0, five_u] {
                let got = f64::from(atan2_acc(y, x, e));
                // The same direction: compare modulo a turn (±π).
                let d = (got - exact).abs();
                worst = worst.max(d.min((d - std::f64::consts::TAU).abs()));
            }
        }
        assert!(worst < 2e-6, "atan2 error {worst} rad");
    }
}
