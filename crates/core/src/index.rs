//! World voxel and block indices.
//!
//! A point `p` (metres, world frame) lies in voxel `floor(p / voxel_size_m)`;
//! voxels are grouped into blocks of [`BLOCK_SIDE`]³, and a voxel's block
//! key is its index divided (rounding down) by [`BLOCK_SIDE`].

/// Voxels along each side of a block.
pub const BLOCK_SIDE: i32 = 8;
/// Voxels in one block.
pub const BLOCK_VOXELS: usize = (BLOCK_SIDE * BLOCK_SIDE * BLOCK_SIDE) as usize;

/// Index of a voxel in the unbounded world grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct VoxelIndex(pub [i32; 3]);

/// Key of an 8³ block in the unbounded world grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct BlockKey(pub [i32; 3]);

impl VoxelIndex {
    /// The voxel holding world point `p` (metres), or `None` when `p` is not
    /// finite or lies outside the `i32` index range.
    pub fn containing(p: [f64; 3], voxel_size_m: f64) -> Option<VoxelIndex> {
        let mut out = [0i32; 3];
        const LIMIT: f64 = 2147483648.0; // 2³¹
        for (o, &c) in out.iter_mut().zip(&p) {
            let q = c / voxel_size_m;
            // floor(q) lies in the i32 range exactly when −2³¹ ≤ q < 2³¹
            // (false for NaN). Truncation, less one below a negative
            // fraction, is the floor, without a call to libm's `floor`.
            if !(-LIMIT..LIMIT).contains(&q) {
                return None;
            }
            let t = q as i64;
            *o = (t - i64::from((t as f64) > q)) as i32;
        }
        Some(VoxelIndex(out))
    }

    /// Centre of the voxel in metres.
    pub fn centre(self, voxel_size_m: f64) -> [f64; 3] {
        self.0.map(|i| (i as f64 + 0.5) * voxel_size_m)
    }

    /// The block holding this voxel.
    #[inline]
    pub fn block(self) -> BlockKey {
        BlockKey(self.0.map(|i| i.div_euclid(BLOCK_SIDE)))
    }

    /// Position of this voxel inside its block, `x + 8 (y + 8 z)`.
    #[inline]
    pub fn offset_in_block(self) -> usize {
        let [x, y, z] = self.0.map(|i| i.rem_euclid(BLOCK_SIDE) as usize);
        x + 8 * (y + 8 * z)
    }
}

impl BlockKey {
    /// Every block overlapping the voxels from `first` to `last` inclusive,
    /// z slowest then y then x.
    pub fn span(first: VoxelIndex, last: VoxelIndex) -> Vec<BlockKey> {
        let (lo, hi) = (first.block().0, last.block().0);
        let mut keys = Vec::new();
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    keys.push(BlockKey([x, y, z]));
                }
            }
        }
        keys
    }

    /// The block's first voxel (lowest coordinates).
    #[inline]
    pub fn first_voxel(self) -> VoxelIndex {
        VoxelIndex(self.0.map(|b| b * BLOCK_SIDE))
    }

    /// The voxel at `offset` (as from [`VoxelIndex::offset_in_block`]).
    #[inline]
    pub fn voxel(self, offset: usize) -> VoxelIndex {
        let side = BLOCK_SIDE as usize;
        let local = [offset % side, (offset / side) % side, offset / (side * side)];
        let first = self.first_voxel().0;
        VoxelIndex([0, 1, 2].map(|a| first[a] + local[a] as i32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn negative_coordinates_round_down() {
        let v = VoxelIndex::containing([-0.05, 0.05, -0.2], 0.1).expect("finite");
        assert_eq!(v, VoxelIndex([-1, 0, -2]));
        assert_eq!(v.block(), BlockKey([-1, 0, -1]));
        assert_eq!(v.offset_in_block(), 7 + 8 * 8 * 6);
        assert_eq!(v.block().voxel(v.offset_in_block()), v);
    }

    #[test]
    fn non_finite_points_have_no_voxel() {
        assert_eq!(VoxelIndex::containing([f64::NAN, 0.0, 0.0], 0.1), None);
        assert_eq!(VoxelIndex::containing([1e12, 0.0, 0.0], 0.1), None);
        assert_eq!(VoxelIndex::containing([f64::NEG_INFINITY, 0.0, 0.0], 0.1), None);
    }

    /// The definition with libm's floor: `floor(p / s)` when it is in the
    /// `i32` range.
    fn containing_by_floor(p: [f64; 3], s: f64) -> Option<VoxelIndex> {
        let v = p.map(|c| (c / s).floor());
        v.iter()
            .all(|v| v.is_finite() && *v >= i32::MIN as f64 && *v <= i32::MAX as f64)
            .then(|| VoxelIndex(v.map(|v| v as i32)))
    }

    #[test]
    fn containing_is_the_floor_at_the_edges() {
        let edges = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            -0.5,
            1e-300,
            -1e-300,
            2147483647.0,
            2147483647.5,
            2147483648.0,
            -2147483648.0,
            -2147483648.5,
            -2147483649.0,
            4503599627370495.5,
            -4503599627370495.5,
            f64::MAX,
            f64::INFINITY,
            f64::NAN,
        ];
        for a in edges {
            let p = [a, -a, a * 0.5];
            assert_eq!(VoxelIndex::containing(p, 1.0), containing_by_floor(p, 1.0), "{p:?}");
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 5000, rng_seed: proptest::test_runner::RngSeed::Fixed(0x1D5), ..Default::default() })]
        #[test]
        fn containing_is_the_floor(p in proptest::array::uniform3(-1e9f64..1e9), k in -3i32..3, s in 0.01f64..1.0) {
            // Points on voxel faces and near them, and anywhere.
            let on_face = p.map(|c| (c / s).round() * s + k as f64 * f64::EPSILON * c.abs());
            for q in [p, on_face] {
                proptest::prop_assert_eq!(VoxelIndex::containing(q, s), containing_by_floor(q, s));
            }
        }
    }
}
