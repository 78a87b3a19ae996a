//! What the EDT counts as an obstacle: occupied voxels of the map plus
//! fixed obstacles the user knows about (forbidden zones, a prior map).

use crate::edt_map::ForbiddenZone;
use crate::layers::LAYER_VOXELS;
use crate::{BlockMap, CoreError, LogOdds, OccupancyMap, VoxelIndex, VoxelState, BLOCK_SIDE, UNOBSERVED};

/// Most blocks a set of fixed obstacles may span (about 200 MB).
pub const MAX_FIXED_BLOCKS: usize = 1 << 21;

/// One 8³ block of fixed obstacles, one bit per voxel.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[repr(C)]
pub struct FixedBlock {
    /// Bit `offset % 64` of word `offset / 64` is set for an obstacle.
    pub bits: [u64; 8],
}

impl crate::BlockHeap for FixedBlock {}

/// Fixed obstacles: voxels that count as occupied whatever the sensors say.
pub type FixedMap = BlockMap<FixedBlock>;

impl FixedMap {
    /// Makes voxel `v` a fixed obstacle.
    pub fn insert(&mut self, v: VoxelIndex) {
        let i = v.offset_in_block();
        self.get_or_insert(v.block()).bits[i / 64] |= 1 << (i % 64);
    }

    /// Whether voxel `v` is a fixed obstacle.
    pub fn contains(&self, v: VoxelIndex) -> bool {
        let i = v.offset_in_block();
        self.get(v.block()).is_some_and(|b| b.bits[i / 64] >> (i % 64) & 1 == 1)
    }

    /// Makes every voxel (of `vs` metres) that overlaps `zone` a fixed
    /// obstacle; returns how many. Fails, leaving the map as it was, on a
    /// zone that is not a box or would take the map past
    /// [`MAX_FIXED_BLOCKS`].
    pub fn add_zone(&mut self, zone: &ForbiddenZone, vs: f64) -> Result<usize, CoreError> {
        let bad = |reason| CoreError::InvalidParam {
            field: "forbidden",
            value: format!("{{ min_m = {:?}, max_m = {:?} }}", zone.min_m, zone.max_m),
            reason,
        };
        let mut lo = [0i64; 3];
        let mut hi = [0i64; 3];
        for a in 0..3 {
            let (l, h) = ((zone.min_m[a] / vs).floor(), (zone.max_m[a] / vs).ceil() - 1.0);
            if !(l.is_finite() && h.is_finite() && l <= h && l >= i32::MIN as f64 && h <= i32::MAX as f64) {
                return Err(bad("corners must be finite, inside the index range, with min_m < max_m"));
            }
            (lo[a], hi[a]) = (l as i64, h as i64);
        }
        let side = i64::from(BLOCK_SIDE);
        let blocks: i64 = (0..3).map(|a| hi[a].div_euclid(side) - lo[a].div_euclid(side) + 1).product();
        if blocks as usize + self.len() > MAX_FIXED_BLOCKS {
            return Err(bad("the zones would span more than 2^21 blocks"));
        }
        let mut count = 0;
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    self.insert(VoxelIndex([x as i32, y as i32, z as i32]));
                    count += 1;
                }
            }
        }
        Ok(count)
    }
}

/// The obstacle test of the EDT: occupied voxels of the map, unknown ones
/// too when `unknown_as_occupied` is set, and fixed obstacles.
#[derive(Debug, Clone, Copy)]
pub struct Obstacles<'a> {
    /// The occupancy map.
    pub occupancy: &'a OccupancyMap,
    /// How its log-odds read as states.
    pub log_odds: &'a LogOdds,
    /// Fixed obstacles.
    pub fixed: &'a FixedMap,
    /// Whether unknown voxels count as obstacles.
    pub unknown_as_occupied: bool,
}

impl Obstacles<'_> {
    /// Whether voxel `v` is an obstacle.
    pub fn contains(&self, v: VoxelIndex) -> bool {
        let state = self.log_odds.state(self.occupancy.log_odds(v));
        state.is_obstacle(self.unknown_as_occupied) || self.fixed.contains(v)
    }

    /// Which voxels of block `key` are obstacles: bit `o % 64` of word `o /
    /// 64` for the voxel at offset `o`; two hash lookups for the whole block.
    pub fn block_bits(&self, key: crate::BlockKey) -> [u64; 8] {
        let unknown = VoxelState::Unknown.is_obstacle(self.unknown_as_occupied);
        // `LogOdds::state` as one comparison per voxel (UNOBSERVED, -inf, is
        // never above the threshold).
        let occupied = self.log_odds.occupied;
        let mut out = match self.occupancy.get(key) {
            Some(b) => b.log_odds.mask_where(|l| l > occupied || (unknown && l == UNOBSERVED)),
            None => [if unknown { u64::MAX } else { 0 }; 8],
        };
        if let Some(b) = self.fixed.get(key) {
            for (w, f) in out.iter_mut().zip(&b.bits) {
                *w |= f;
            }
        }
        out
    }

    /// Fills `out[i]` with whether voxel `start + (i, 0, 0)` is an obstacle,
    /// one hash lookup per block the row crosses.
    pub fn fill_row(&self, start: VoxelIndex, out: &mut [bool]) {
        let mut x = 0;
        while x < out.len() {
            let v = VoxelIndex([start.0[0] + x as i32, start.0[1], start.0[2]]);
            let run = (BLOCK_SIDE - v.0[0].rem_euclid(BLOCK_SIDE)) as usize;
            let end = (x + run).min(out.len());
            let base = v.offset_in_block();
            let row = &mut out[x..end];
            match self.occupancy.get(v.block()) {
                None => row.fill(VoxelState::Unknown.is_obstacle(self.unknown_as_occupied)),
                Some(b) => {
                    // A row of a block lies in one layer.
                    let cells = &b.log_odds.layer_or_empty(base / LAYER_VOXELS)[base % LAYER_VOXELS..];
                    for (o, &l) in row.iter_mut().zip(cells) {
                        *o = self.log_odds.state(l).is_obstacle(self.unknown_as_occupied);
                    }
                }
            }
            if let Some(b) = self.fixed.get(v.block()) {
                for (k, o) in row.iter_mut().enumerate() {
                    *o |= b.bits[(base + k) / 64] >> ((base + k) % 64) & 1 == 1;
                }
            }
            x = end;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::OccupancyParams;

    #[test]
    fn zone_covers_overlapping_voxels() {
        let mut fixed = FixedMap::new();
        let zone = ForbiddenZone { min_m: [-0.2, 0.0, 0.0], max_m: [0.6, 0.5, 0.1] };
        assert_eq!(fixed.add_zone(&zone, 0.5).expect("valid"), 3);
        for x in -1..=1 {
            assert!(fixed.contains(VoxelIndex([x, 0, 0])));
        }
        assert!(!fixed.contains(VoxelIndex([2, 0, 0])) && !fixed.contains(VoxelIndex([0, 1, 0])));
        let huge = ForbiddenZone { min_m: [0.0; 3], max_m: [1e5, 1e5, 1e3] };
        assert!(fixed.add_zone(&huge, 0.5).expect_err("too large").to_string().contains("forbidden"));
        assert_eq!(fixed.len(), 2, "x = -1 and x = 0..1 lie in two blocks");
    }

    #[test]
    fn rows_match_single_voxel_test() {
        let lo = OccupancyParams::default().log_odds().expect("defaults");
        let mut map = OccupancyMap::new();
        let mut fixed = FixedMap::new();
        for x in [-9, -3, 0, 5, 12] {
            let v = VoxelIndex([x, 2, -1]);
            map.get_or_insert(v.block()).log_odds.set(v.offset_in_block(), lo.max);
        }
        map.get_or_insert(VoxelIndex([1, 2, -1]).block())
            .log_odds
            .set(VoxelIndex([1, 2, -1]).offset_in_block(), lo.min);
        fixed.insert(VoxelIndex([7, 2, -1]));
        for unknown_as_occupied in [false, true] {
            let obs = Obstacles { occupancy: &map, log_odds: &lo, fixed: &fixed, unknown_as_occupied };
            let mut row = vec![false; 30];
            obs.fill_row(VoxelIndex([-11, 2, -1]), &mut row);
            for (i, &o) in row.iter().enumerate() {
                assert_eq!(o, obs.contains(VoxelIndex([-11 + i as i32, 2, -1])), "x = {}", i as i32 - 11);
            }
            // Whole blocks as bits, with and without occupancy or fixed
            // obstacles in them.
            for key in [VoxelIndex([-9, 2, -1]).block(), VoxelIndex([5, 2, -1]).block(), crate::BlockKey([4, 4, 4])] {
                let bits = obs.block_bits(key);
                for o in 0..crate::BLOCK_VOXELS {
                    let v = VoxelIndex(
                        [0, 1, 2].map(|a| key.0[a] * crate::BLOCK_SIDE + [o % 8, o / 8 % 8, o / 64][a] as i32),
                    );
                    assert_eq!(bits[o / 64] >> (o % 64) & 1 == 1, obs.contains(v), "{:?}", v);
                }
            }
        }
    }
}
