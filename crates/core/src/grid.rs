use crate::CoreError;

/// A dense 3D grid of voxels, `x` varying fastest (see the crate docs).
///
/// 2D data is a grid with `nz = 1`; any axis may have length 1.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid3<T> {
    dims: [usize; 3],
    data: Vec<T>,
}

/// A grid of one voxel holding `T::default()`: a buffer to be resized.
impl<T: Default> Default for Grid3<T> {
    fn default() -> Self {
        Grid3 { dims: [1, 1, 1], data: vec![T::default()] }
    }
}

impl<T> Grid3<T> {
    /// Checks that `dims` has no empty axis and that its voxel count fits in
    /// `usize`; returns the voxel count.
    pub fn voxel_count(dims: [usize; 3]) -> Result<usize, CoreError> {
        if let Some(axis) = dims.iter().position(|&n| n == 0) {
            return Err(CoreError::EmptyAxis { axis, dims });
        }
        dims.iter()
            .try_fold(1usize, |acc, &n| acc.checked_mul(n))
            .ok_or(CoreError::TooLarge { dims, reason: "voxel count overflows usize" })
    }

    /// Wraps `data` (one element per voxel, `x` fastest) as a grid.
    pub fn from_vec(dims: [usize; 3], data: Vec<T>) -> Result<Self, CoreError> {
        let expected = Self::voxel_count(dims)?;
        if data.len() != expected {
            return Err(CoreError::LengthMismatch { dims, expected, actual: data.len() });
        }
        Ok(Grid3 { dims, data })
    }

    /// Builds a grid by calling `f(x, y, z)` for every voxel.
    pub fn from_fn(dims: [usize; 3], mut f: impl FnMut(usize, usize, usize) -> T) -> Result<Self, CoreError> {
        let count = Self::voxel_count(dims)?;
        let mut data = Vec::with_capacity(count);
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    data.push(f(x, y, z));
                }
            }
        }
        Ok(Grid3 { dims, data })
    }

    /// Dimensions `[nx, ny, nz]` in voxels.
    #[inline]
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Number of voxels.
    #[inline]
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// Always false: a grid has at least one voxel.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// Linear index of voxel `(x, y, z)`; the caller keeps it in bounds.
    #[inline]
    pub fn linear(&self, [x, y, z]: [usize; 3]) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// Voxel coordinates `[x, y, z]` of a linear index.
    #[inline]
    pub fn coords(&self, linear: usize) -> [usize; 3] {
        coords_of(self.dims, linear)
    }

    /// The voxel at `[x, y, z]`, or `None` outside the grid.
    #[inline]
    pub fn get(&self, [x, y, z]: [usize; 3]) -> Option<&T> {
        let [nx, ny, nz] = self.dims;
        (x < nx && y < ny && z < nz).then(|| &self.data[self.linear([x, y, z])])
    }

    /// Mutable access to the voxel at `[x, y, z]`, or `None` outside the grid.
    #[inline]
    pub fn get_mut(&mut self, [x, y, z]: [usize; 3]) -> Option<&mut T> {
        let [nx, ny, nz] = self.dims;
        let i = self.linear([x, y, z]);
        (x < nx && y < ny && z < nz).then(move || &mut self.data[i])
    }

    /// The voxels in linear order.
    #[inline]
    pub fn as_slice(&self) -> &[T] {
        &self.data
    }

    /// The voxels in linear order, mutable.
    #[inline]
    pub fn as_mut_slice(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// Consumes the grid and returns its voxels in linear order.
    pub fn into_vec(self) -> Vec<T> {
        self.data
    }
}

/// Voxel coordinates `[x, y, z]` of `linear` in a grid of dimensions `dims`.
#[inline]
pub(crate) fn coords_of(dims: [usize; 3], linear: usize) -> [usize; 3] {
    let x = linear % dims[0];
    let yz = linear / dims[0];
    [x, yz % dims[1], yz / dims[1]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_and_coords_are_inverse() {
        let g = Grid3::from_fn([3, 4, 5], |x, y, z| (x, y, z)).expect("valid dims");
        for (i, &(x, y, z)) in g.as_slice().iter().enumerate() {
            assert_eq!(g.linear([x, y, z]), i);
            assert_eq!(g.coords(i), [x, y, z]);
        }
    }

    #[test]
    fn empty_axis_is_rejected() {
        assert_eq!(Grid3::<u8>::from_vec([2, 0, 1], vec![]), Err(CoreError::EmptyAxis { axis: 1, dims: [2, 0, 1] }));
    }

    #[test]
    fn length_mismatch_is_rejected() {
        assert!(matches!(
            Grid3::from_vec([2, 2, 1], vec![0u8; 3]),
            Err(CoreError::LengthMismatch { expected: 4, actual: 3, .. })
        ));
    }

    #[test]
    fn out_of_bounds_get_is_none() {
        let g = Grid3::from_vec([2, 1, 1], vec![1u8, 2]).expect("valid dims");
        assert_eq!(g.get([1, 0, 0]), Some(&2));
        assert_eq!(g.get([2, 0, 0]), None);
    }
}
