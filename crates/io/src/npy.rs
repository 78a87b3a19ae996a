//! Dense grids in NumPy's `.npy` format.
//!
//! Input grids: bool or any integer dtype, either byte order, 2 or 3 axes,
//! C or Fortran order; nonzero means obstacle. A C-order array of shape
//! `(a0, a1, a2)` is the grid `[a2, a1, a0]` (last axis fastest), a
//! Fortran-order one the grid `[a0, a1, a2]`, so the grid's linear order is
//! always the file's element order.
//!
//! Inputs are read strictly: the file must be a regular file holding
//! exactly the data its header promises (no trailing bytes), its header
//! dictionary must name each key once, and a bool array's bytes must be
//! 0 or 1.

mod header;

use std::fs::File;
use std::io::{BufReader, Read, Write};
use std::path::{Path, PathBuf};

use edtmap_core::{dist_sq_to_vox, EdtField, Grid3, NO_SITE};
use npyz::{DType, NpyHeader, Order, TypeChar, WriterBuilder};
use rayon::prelude::*;

use crate::IoError;

/// Element order of an array in a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArrayOrder {
    /// Row-major: the last axis varies fastest.
    C,
    /// Column-major: the first axis varies fastest.
    Fortran,
}

/// Shape and order of a 2D or 3D array, and its mapping to grid voxels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ArrayLayout {
    shape: Vec<usize>,
    order: ArrayOrder,
}

impl ArrayLayout {
    /// A layout of `shape` (2 or 3 nonzero axes) in `order`.
    pub fn new(shape: Vec<usize>, order: ArrayOrder) -> Option<Self> {
        ((shape.len() == 2 || shape.len() == 3) && !shape.contains(&0)).then_some(ArrayLayout { shape, order })
    }

    /// The array's shape, axis 0 first.
    pub fn shape(&self) -> &[usize] {
        &self.shape
    }

    /// The array's element order.
    pub fn order(&self) -> ArrayOrder {
        self.order
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }

    /// Always false: a layout has no empty axis.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Dimensions `[nx, ny, nz]` of the grid whose linear order is the
    /// file's element order.
    pub fn grid_dims(&self) -> [usize; 3] {
        let mut dims = [1; 3];
        for (k, &n) in self.shape.iter().enumerate() {
            match self.order {
                ArrayOrder::C => dims[self.shape.len() - 1 - k] = n,
                ArrayOrder::Fortran => dims[k] = n,
            }
        }
        dims
    }

    /// Array axis `k`'s coordinate of grid voxel `voxel`.
    #[inline]
    fn axis_coord(&self, voxel: [u32; 3], k: usize) -> u32 {
        match self.order {
            ArrayOrder::C => voxel[self.shape.len() - 1 - k],
            ArrayOrder::Fortran => voxel[k],
        }
    }

    fn npyz_order(&self) -> Order {
        match self.order {
            ArrayOrder::C => Order::C,
            ArrayOrder::Fortran => Order::Fortran,
        }
    }
}

/// An obstacle grid file whose header has been checked; [`read`](Self::read)
/// loads its data.
pub struct ObstacleNpy {
    path: PathBuf,
    layout: ArrayLayout,
    item_size: usize,
    /// Whether the dtype is bool, whose bytes must be 0 or 1.
    is_bool: bool,
    reader: BufReader<File>,
}

impl ObstacleNpy {
    /// Opens `path` (a regular file) and validates its header: each key
    /// once, dtype, number of axes, empty axes, size limits of the EDT, and
    /// that the data is all there and nothing follows it.
    pub fn open(path: &Path) -> Result<Self, IoError> {
        let (file, file_len) = crate::files::open_input(path, u64::MAX)?;
        let mut reader = BufReader::new(file);
        let header_bytes = header::read_header_bytes(path, &mut reader, file_len)?;
        let header = NpyHeader::from_reader(&header_bytes[..])
            .map_err(|e| IoError::NotNpy { path: path.into(), reason: e.to_string() })?;
        let item_size = obstacle_item_size(path, &header.dtype())?;
        let layout = checked_layout(path, &header)?;
        let data_start = header_bytes.len() as u64;
        let expected = layout.len() as u64 * item_size as u64;
        let actual = file_len.saturating_sub(data_start);
        if actual < expected {
            return Err(IoError::Truncated { path: path.into(), expected, actual });
        }
        if actual > expected {
            let reason = format!(
                "{} bytes after the data: shape {:?} of {} gives {expected} bytes after the {data_start}-byte header, the file has {actual}",
                actual - expected,
                layout.shape(),
                header.dtype().descr()
            );
            return Err(IoError::NpyData { path: path.into(), reason });
        }
        let is_bool = matches!(header.dtype(), DType::Plain(ts) if ts.type_char() == TypeChar::Bool);
        Ok(ObstacleNpy { path: path.into(), layout, item_size, is_bool, reader })
    }

    /// The array's shape and order.
    pub fn layout(&self) -> &ArrayLayout {
        &self.layout
    }

    /// Bytes per element in the file.
    pub fn item_size(&self) -> usize {
        self.item_size
    }

    /// Reads the data: `true` where an element is nonzero.
    pub fn read(mut self) -> Result<Grid3<bool>, IoError> {
        let bytes = self.layout.len() * self.item_size;
        let mut raw = Vec::new();
        raw.try_reserve_exact(bytes).map_err(|_| IoError::BadShape {
            path: self.path.clone(),
            shape: self.layout.shape.iter().map(|&n| n as u64).collect(),
            reason: format!("cannot allocate {bytes} bytes"),
        })?;
        (&mut self.reader).take(bytes as u64).read_to_end(&mut raw).map_err(|e| IoError::io(&self.path, e))?;
        if self.is_bool {
            check_bools(&self.path, &raw)?;
        }
        let obstacles: Vec<bool> =
            raw.par_chunks_exact(self.item_size).map(|item| item.iter().any(|&b| b != 0)).collect();
        Grid3::from_vec(self.layout.grid_dims(), obstacles).map_err(|e| IoError::BadShape {
            path: self.path,
            shape: self.layout.shape.iter().map(|&n| n as u64).collect(),
            reason: e.to_string(),
        })
    }
}

/// Refuses bool data with a byte other than 0 or 1 (NumPy never writes
/// one: such a file is damaged or not what it says).
fn check_bools(path: &Path, raw: &[u8]) -> Result<(), IoError> {
    match raw.par_iter().position_first(|&b| b > 1) {
        Some(at) => Err(IoError::NpyData {
            path: path.into(),
            reason: format!("bool element {at} (in file order) has byte value {}: a bool is 0 or 1", raw[at]),
        }),
        None => Ok(()),
    }
}

fn obstacle_item_size(path: &Path, dtype: &DType) -> Result<usize, IoError> {
    let unsupported = || IoError::UnsupportedDtype { path: path.into(), dtype: dtype.descr() };
    match dtype {
        DType::Plain(ts) if matches!(ts.type_char(), TypeChar::Bool | TypeChar::Int | TypeChar::Uint) => {
            ts.num_bytes().filter(|&n| n > 0).ok_or_else(unsupported)
        }
        _ => Err(unsupported()),
    }
}

fn checked_layout(path: &Path, header: &NpyHeader) -> Result<ArrayLayout, IoError> {
    let shape = header.shape().to_vec();
    let bad = |reason: String| IoError::BadShape { path: path.into(), shape: shape.clone(), reason };
    if shape.len() != 2 && shape.len() != 3 {
        return Err(bad(format!("ndim {}, expected 2 or 3", shape.len())));
    }
    if let Some(axis) = shape.iter().position(|&n| n == 0) {
        return Err(bad(format!("axis {axis} has length 0")));
    }
    let usize_shape: Vec<usize> = shape
        .iter()
        .map(|&n| usize::try_from(n).map_err(|_| bad("axis too long for this machine".into())))
        .collect::<Result<_, _>>()?;
    let order = match header.order() {
        Order::C => ArrayOrder::C,
        Order::Fortran => ArrayOrder::Fortran,
    };
    let layout = ArrayLayout::new(usize_shape, order).ok_or_else(|| bad("invalid shape".into()))?;
    EdtField::check_dims(layout.grid_dims()).map_err(|e| bad(format!("too large: {e}")))?;
    Ok(layout)
}

/// Distances in voxels as `f32`, in the grid's (and the file's) order:
/// `0` on obstacles, `inf` where the grid has no obstacle. `out` is
/// overwritten, keeping its allocation.
pub fn distance_array(field: &EdtField, out: &mut Vec<f32>) {
    out.resize(field.dist_sq_vox().len(), 0.0);
    out.par_iter_mut().zip(field.dist_sq_vox()).for_each(|(o, &d)| *o = dist_sq_to_vox(d));
}

/// Nearest-obstacle array indices as `i32`, in file order for an array of
/// shape `layout.shape() + (ndim,)` in the layout's order. Voxels without an
/// obstacle get `-1`. `out` is overwritten, keeping its allocation.
pub fn nearest_array(layout: &ArrayLayout, field: &EdtField, out: &mut Vec<i32>) {
    let ndim = layout.shape.len();
    let split = CoordSplit::new(field.dims());
    // Array axis k of the nearest obstacle of a voxel whose site is `site`.
    let array_coords = |site: u32| -> [i32; 3] {
        if site == NO_SITE {
            return [-1; 3];
        }
        let voxel = split.coords(site);
        std::array::from_fn(|k| if k < ndim { layout.axis_coord(voxel, k) as i32 } else { 0 })
    };
    let nearest = field.nearest();
    out.resize(nearest.len() * ndim, 0);
    const CHUNK: usize = 1 << 12;
    match layout.order {
        // Trailing axis fastest: the ndim indices of a voxel are adjacent.
        ArrayOrder::C => {
            let chunks = out.par_chunks_mut(ndim * CHUNK).zip(nearest.par_chunks(CHUNK));
            chunks.for_each(|(out, sites)| {
                for (o, &site) in out.chunks_exact_mut(ndim).zip(sites) {
                    o.copy_from_slice(&array_coords(site)[..ndim]);
                }
            });
        }
        // Trailing axis slowest: one plane of indices per array axis.
        ArrayOrder::Fortran => {
            let (first, rest) = out.split_at_mut(nearest.len());
            let (second, third) = rest.split_at_mut(nearest.len());
            let mut planes = [first, second, third];
            let planes = &mut planes[..ndim];
            for (k, plane) in planes.iter_mut().enumerate() {
                plane.par_chunks_mut(CHUNK).zip(nearest.par_chunks(CHUNK)).for_each(|(o, sites)| {
                    for (v, &site) in o.iter_mut().zip(sites) {
                        *v = array_coords(site)[k];
                    }
                });
            }
        }
    }
}

/// Splits linear indices into voxel coordinates with multiply-shift
/// division (exact for every `u32` numerator; Lemire et al. 2019).
struct CoordSplit {
    nx: u64,
    ny: u64,
    inv_nx: u64,
    inv_ny: u64,
}

impl CoordSplit {
    fn new(dims: [usize; 3]) -> Self {
        let (nx, ny) = (dims[0] as u64, dims[1] as u64);
        let inv = |d: u64| (u64::MAX / d).wrapping_add(1);
        CoordSplit { nx, ny, inv_nx: inv(nx), inv_ny: inv(ny) }
    }

    #[inline]
    fn div(n: u64, inv: u64, d: u64) -> u64 {
        if d == 1 {
            n
        } else {
            ((u128::from(inv) * u128::from(n)) >> 64) as u64
        }
    }

    #[inline]
    fn coords(&self, linear: u32) -> [u32; 3] {
        let n = u64::from(linear);
        let yz = Self::div(n, self.inv_nx, self.nx);
        let z = Self::div(yz, self.inv_ny, self.ny);
        [(n - yz * self.nx) as u32, (yz - z * self.ny) as u32, z as u32]
    }
}

/// Writes `data` (file order) as an `.npy` array of `shape` in `order`.
fn write_array<T: npyz::AutoSerialize>(
    path: &Path,
    shape: &[usize],
    order: Order,
    data: &[T],
    to_le: impl Fn(&T, &mut Vec<u8>) + Sync,
) -> Result<(), IoError> {
    let expected: usize = shape.iter().product();
    if expected != data.len() {
        return Err(IoError::BadData {
            path: path.into(),
            reason: format!("shape {shape:?} needs {expected} values, got {}", data.len()),
        });
    }
    let shape_u64: Vec<u64> = shape.iter().map(|&n| n as u64).collect();
    let mut file = crate::files::AtomicFile::create(path)?;
    let w = npyz::WriteOptions::<T>::new()
        .default_dtype()
        .shape(&shape_u64)
        .order(order)
        .writer(&mut file)
        .write_header_only()
        .map_err(|e| IoError::io(path, e))?;
    let mut buf = Vec::with_capacity(1 << 16);
    for chunk in data.chunks(1 << 14) {
        buf.clear();
        chunk.iter().for_each(|v| to_le(v, &mut buf));
        w.write_all(&buf).map_err(|e| IoError::io(path, e))?;
    }
    w.flush().map_err(|e| IoError::io(path, e))?;
    file.commit()
}

/// Writes distances (from [`distance_array`]) as a `float32` array of the
/// layout's shape and order.
pub fn write_distances(path: &Path, layout: &ArrayLayout, dist: &[f32]) -> Result<(), IoError> {
    write_array(path, &layout.shape, layout.npyz_order(), dist, |v, b| b.extend_from_slice(&v.to_le_bytes()))
}

/// Writes bytes (voxel states, say) as a `uint8` array of the layout's
/// shape and order.
pub fn write_bytes(path: &Path, layout: &ArrayLayout, data: &[u8]) -> Result<(), IoError> {
    write_array(path, &layout.shape, layout.npyz_order(), data, |v, b| b.push(*v))
}

/// Writes nearest-obstacle indices (from [`nearest_array`]) as an `int32`
/// array of shape `layout.shape() + (ndim,)` in the layout's order.
pub fn write_nearest(path: &Path, layout: &ArrayLayout, idx: &[i32]) -> Result<(), IoError> {
    let mut shape = layout.shape.clone();
    shape.push(layout.shape.len());
    write_array(path, &shape, layout.npyz_order(), idx, |v, b| b.extend_from_slice(&v.to_le_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coord_split_is_exact() {
        for dims in [[1, 1, 1], [7, 3, 5], [256, 256, 256], [1, 9, 4], [46340, 46340, 1]] {
            let split = CoordSplit::new(dims);
            let total = (dims[0] * dims[1] * dims[2]) as u64;
            let step = (total / 5000).max(1);
            for n in (0..total).step_by(step as usize).chain([total - 1]) {
                let (x, y, z) =
                    (n % dims[0] as u64, n / dims[0] as u64 % dims[1] as u64, n / (dims[0] * dims[1]) as u64);
                assert_eq!(split.coords(n as u32), [x as u32, y as u32, z as u32], "{dims:?} {n}");
            }
        }
    }

    #[test]
    fn layouts_map_axes() {
        let c = ArrayLayout::new(vec![4, 5, 6], ArrayOrder::C).expect("valid");
        assert_eq!(c.grid_dims(), [6, 5, 4]);
        assert_eq!(c.axis_coord([1, 2, 3], 0), 3);
        let f = ArrayLayout::new(vec![4, 5], ArrayOrder::Fortran).expect("valid");
        assert_eq!(f.grid_dims(), [4, 5, 1]);
        assert_eq!(f.axis_coord([1, 2, 0], 1), 2);
        assert!(ArrayLayout::new(vec![4], ArrayOrder::C).is_none());
        assert!(ArrayLayout::new(vec![4, 0], ArrayOrder::C).is_none());
    }
}
