//! The 3D orchestration of the separable scans (paper Algorithm 1).

use edtmap_core::{EdtField, EdtParams, Grid3, VoxelState};
use rayon::prelude::*;

use super::envelope::{envelope, sweep_row, EnvelopeScratch, Line};
use super::shared::SharedBuf;
use super::window::{scan_windowed, Tile, Windows};
use crate::CpuError;

/// Lines per tile of the default [`ScanLayout::Tiled`], chosen by the
/// `edt_layout` benchmark (`cargo bench -p edtmap-cpu --bench edt`).
pub const DEFAULT_TILE_LANES: usize = 64;

/// Voxels of the first scan handed to one task, so short rows are batched.
const MIN_VOXELS_PER_TASK: usize = 1 << 14;

/// z slabs per thread from which the x and y scans are fused slab by slab
/// (fewer slabs would leave threads idle).
const FUSE_MIN_SLABS_PER_THREAD: usize = 4;

/// How scans along the strided axes (`y`, `z`) touch memory, and which 1D
/// kernel they run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScanLayout {
    /// One strided line at a time through the lower envelope: each element
    /// read is a new cache line (the paper's uncoalesced variant, kept for
    /// comparison).
    PerLine,
    /// `lanes` neighbouring lines gathered into a contiguous buffer so that
    /// every cache line read feeds all lanes (the CPU counterpart of the
    /// paper's coalesced transposes), each lane through the lower envelope.
    TiledEnvelope {
        /// Number of lines gathered together.
        lanes: usize,
    },
    /// Tiles as in `TiledEnvelope`, scanned with the windowed minimum
    /// vectorised across lanes where the windows are short, and with the
    /// envelope elsewhere. The default.
    Tiled {
        /// Number of lines gathered together.
        lanes: usize,
    },
}

impl Default for ScanLayout {
    fn default() -> Self {
        ScanLayout::Tiled { lanes: DEFAULT_TILE_LANES }
    }
}

impl ScanLayout {
    fn lanes(self) -> usize {
        match self {
            ScanLayout::PerLine => 1,
            ScanLayout::TiledEnvelope { lanes } | ScanLayout::Tiled { lanes } => lanes.max(1),
        }
    }

    fn windowed(self) -> bool {
        matches!(self, ScanLayout::Tiled { .. })
    }
}

/// Exact EDT of a grid of occupancy states: obstacles are occupied voxels,
/// plus unknown ones when `params.unknown_as_occupied` is set.
pub fn batch_edt(states: &Grid3<VoxelState>, params: &EdtParams) -> Result<EdtField, CpuError> {
    let unknown = params.unknown_as_occupied;
    edt_with(states, |s| s.is_obstacle(unknown), ScanLayout::default())
}

/// Exact EDT of any grid: `is_obstacle` says which voxels are obstacles.
///
/// Every voxel gets its exact squared Euclidean distance in voxel units to
/// the nearest obstacle and that obstacle's linear index; a grid without
/// obstacles yields `UNREACHABLE_DIST_SQ` and `NO_SITE` everywhere.
///
/// ```
/// use edtmap_core::Grid3;
/// use edtmap_cpu::edt::{edt_with, ScanLayout};
///
/// // One obstacle at (1, 2) in a 4 x 3 image.
/// let grid = Grid3::from_fn([4, 3, 1], |x, y, _| x == 1 && y == 2).unwrap();
/// let edt = edt_with(&grid, |&o| o, ScanLayout::default()).unwrap();
/// assert_eq!(edt.dist_sq_vox()[grid.linear([3, 0, 0])], 2 * 2 + 2 * 2);
/// assert_eq!(edt.nearest_coords(0), Some([1, 2, 0]));
/// ```
pub fn edt_with<T: Sync>(
    grid: &Grid3<T>,
    is_obstacle: impl Fn(&T) -> bool + Sync,
    layout: ScanLayout,
) -> Result<EdtField, CpuError> {
    let mut field = EdtField::empty();
    edt_into(grid, is_obstacle, layout, &mut field)?;
    Ok(field)
}

/// [`edt_with`] into an existing field, reusing its memory: the form to
/// call once per frame.
pub fn edt_into<T: Sync>(
    grid: &Grid3<T>,
    is_obstacle: impl Fn(&T) -> bool + Sync,
    layout: ScanLayout,
    field: &mut EdtField,
) -> Result<(), CpuError> {
    edt_slice_into(grid.as_slice(), grid.dims(), is_obstacle, layout, field)
}

/// [`edt_into`] of voxels held in any slice (one per voxel, `x` fastest,
/// `dims = [nx, ny, nz]`), so that borrowed data needs no copy into a
/// [`Grid3`].
pub fn edt_slice_into<T: Sync>(
    voxels: &[T],
    dims: [usize; 3],
    is_obstacle: impl Fn(&T) -> bool + Sync,
    layout: ScanLayout,
    field: &mut EdtField,
) -> Result<(), CpuError> {
    let expected = Grid3::<()>::voxel_count(dims)?;
    if voxels.len() != expected {
        let actual = voxels.len();
        return Err(edtmap_core::CoreError::LengthMismatch { dims, expected, actual }.into());
    }
    let (dist, near) = field.prepare(dims)?;
    let [nx, ny, nz] = dims;
    let y_lines = |outer| LineSet { outer, outer_stride: nx * ny, len: ny, stride: nx, nx };
    if nz >= FUSE_MIN_SLABS_PER_THREAD * rayon::current_num_threads() {
        // Scan x then y one z slab at a time, so the y scan reads the slab
        // from cache.
        let slab = nx * ny;
        dist.par_chunks_mut(slab)
            .zip(near.par_chunks_mut(slab))
            .zip(voxels.par_chunks(slab))
            .enumerate()
            .for_each_init(TileScratch::default, |scratch, (z, ((dist, near), voxels))| {
                scan_x_rows(voxels, &is_obstacle, nx, z * slab, dist, near);
                if ny > 1 {
                    scan_strided_serial(&y_lines(1), layout, dist, near, scratch);
                }
            });
    } else {
        scan_x(voxels, &is_obstacle, nx, dist, near);
        if ny > 1 {
            scan_strided(&y_lines(nz), layout, dist, near);
        }
    }
    // The z scan across slabs; a length-1 axis is already exact.
    if nz > 1 {
        let lines = LineSet { outer: ny, outer_stride: nx, len: nz, stride: nx * ny, nx };
        scan_strided(&lines, layout, dist, near);
    }
    Ok(())
}

/// First scan: every contiguous row along x, rows in parallel.
fn scan_x<T: Sync>(
    voxels: &[T],
    is_obstacle: &(impl Fn(&T) -> bool + Sync),
    nx: usize,
    dist: &mut [u32],
    near: &mut [u32],
) {
    let chunk = (MIN_VOXELS_PER_TASK / nx).max(1) * nx;
    dist.par_chunks_mut(chunk).zip(near.par_chunks_mut(chunk)).zip(voxels.par_chunks(chunk)).enumerate().for_each(
        |(task, ((dist, near), voxels))| {
            scan_x_rows(voxels, is_obstacle, nx, task * chunk, dist, near);
        },
    );
}

/// First scan of consecutive rows whose first voxel has linear index `base`.
fn scan_x_rows<T>(
    voxels: &[T],
    is_obstacle: &impl Fn(&T) -> bool,
    nx: usize,
    base: usize,
    dist: &mut [u32],
    near: &mut [u32],
) {
    let rows = dist.chunks_mut(nx).zip(near.chunks_mut(nx)).zip(voxels.chunks(nx));
    for (r, ((dist, near), row)) in rows.enumerate() {
        sweep_row(|x| is_obstacle(&row[x]), (base + r * nx) as u32, dist, near);
    }
}

/// A family of parallel lines along one strided axis.
///
/// Line `(o, x)` starts at voxel `o * outer_stride + x` for `o < outer`,
/// `x < nx`, and its `len` elements are `stride` apart.
struct LineSet {
    outer: usize,
    outer_stride: usize,
    len: usize,
    stride: usize,
    nx: usize,
}

/// Per-task buffers of one tile: `lanes` lines of `len` elements each,
/// element-major (element `i` of lane `w` at `i * lanes + w`), so that a
/// voxel row of the volume is one contiguous run of the buffer.
#[derive(Default)]
struct TileScratch {
    f: Vec<u32>,
    site: Vec<u32>,
    out_f: Vec<u32>,
    out_site: Vec<u32>,
    envelope: EnvelopeScratch,
    windows: Windows,
}

/// Auxiliary scan of every line of `lines`, tiles of `lanes` neighbouring
/// lines in parallel.
fn scan_strided(lines: &LineSet, layout: ScanLayout, dist: &mut [u32], near: &mut [u32]) {
    let tiles_per_outer = lines.nx.div_ceil(layout.lanes());
    let (dist, near) = (SharedBuf::new(dist), SharedBuf::new(near));
    (0..lines.outer * tiles_per_outer).into_par_iter().for_each_init(
        TileScratch::default,
        // SAFETY: distinct tiles own disjoint voxels (see `tile_extent`).
        |scratch, tile| unsafe { scan_tile(lines, tile, layout, dist, near, scratch) },
    );
}

/// [`scan_strided`] on the calling thread only.
fn scan_strided_serial(
    lines: &LineSet,
    layout: ScanLayout,
    dist: &mut [u32],
    near: &mut [u32],
    scratch: &mut TileScratch,
) {
    let (dist, near) = (SharedBuf::new(dist), SharedBuf::new(near));
    for tile in 0..lines.outer * lines.nx.div_ceil(layout.lanes()) {
        // SAFETY: this thread has exclusive access to the buffers.
        unsafe { scan_tile(lines, tile, layout, dist, near, scratch) };
    }
}

/// First voxel and number of lanes of tile number `tile`.
///
/// Tile `(outer, x0)` covers the voxels `start + i * stride + w` for
/// `i < len`, `w < width`. Distinct tiles differ in `outer` (disjoint planes
/// or rows) or in `x0` (disjoint x ranges), so they share no voxel.
fn tile_extent(lines: &LineSet, tile: usize, lanes: usize) -> (usize, usize) {
    let tiles_per_outer = lines.nx.div_ceil(lanes);
    let (outer, x0) = (tile / tiles_per_outer, (tile % tiles_per_outer) * lanes);
    (outer * lines.outer_stride + x0, lanes.min(lines.nx - x0))
}

/// Gathers one tile into `scratch`, scans it, scatters it back.
///
/// # Safety
/// The tile's voxels are in bounds and accessed by no other task.
unsafe fn scan_tile(
    lines: &LineSet,
    tile: usize,
    layout: ScanLayout,
    dist: SharedBuf,
    near: SharedBuf,
    s: &mut TileScratch,
) {
    let lanes = layout.lanes();
    let (start, width) = tile_extent(lines, tile, lanes);
    let len = lines.len;
    for buf in [&mut s.f, &mut s.site, &mut s.out_f, &mut s.out_site] {
        buf.resize(lanes * len, 0);
    }
    for i in 0..len {
        let row = start + i * lines.stride;
        let (f, site) = (&mut s.f[i * lanes..][..lanes], &mut s.site[i * lanes..][..lanes]);
        for w in 0..width {
            // SAFETY: the caller owns the tile.
            unsafe {
                f[w] = dist.read(row + w);
                site[w] = near.read(row + w);
            }
        }
        // Padding lanes of a narrow tile repeat lane 0, so they change
        // neither the windows nor which rows are empty; their results are
        // discarded.
        let (f0, site0) = (f[0], site[0]);
        f[width..].fill(f0);
        site[width..].fill(site0);
    }
    let tile = Tile { f: &s.f, site: &s.site, lanes };
    let windowed = layout.windowed();
    if !(windowed && scan_windowed(&tile, &mut s.out_f, &mut s.out_site, &mut s.windows)) {
        for w in 0..width {
            let line = Line { f: &s.f[w..], site: &s.site[w..], stride: lanes, n: len };
            envelope(line, &mut s.out_f[w..], &mut s.out_site[w..], &mut s.envelope);
        }
    }
    for i in 0..len {
        let row = start + i * lines.stride;
        for w in 0..width {
            // SAFETY: the caller owns the tile.
            unsafe {
                dist.write(row + w, s.out_f[i * lanes + w]);
                near.write(row + w, s.out_site[i * lanes + w]);
            }
        }
    }
}
