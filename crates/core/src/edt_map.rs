//! The global EDT: per voxel, the squared distance to the nearest obstacle
//! and the offset to that obstacle, in the same 8³ blocks as the
//! occupancy (paper §IV-C), plus the parameters of its integration.

use crate::layers::{Cell, Layers, LAYER_VOXELS};
use crate::{BlockKey, BlockMap, CoreError, VoxelIndex};
use serde::{Deserialize, Serialize};

/// Squared distance of a voxel with no obstacle within the cutoff.
pub const FAR_DIST_SQ: u32 = u32::MAX;

/// Nearest obstacle of a voxel with no obstacle within the cutoff.
pub const NO_OBSTACLE: VoxelIndex = VoxelIndex([i32::MIN; 3]);

/// Default cutoff of the global EDT, metres (GIE-mapping's cow-and-lady
/// configuration).
pub const DEFAULT_MAX_DISTANCE_M: f64 = 2.0;

/// Offset to the nearest obstacle of a voxel with no obstacle within the
/// cutoff.
pub const NO_OFFSET: [i16; 3] = [i16::MIN; 3];

/// One 8³ block of the global EDT, voxels at [`VoxelIndex::offset_in_block`].
///
/// Each voxel keeps only the offset from it to its nearest obstacle, six
/// bytes: its squared distance follows from it, and within the cutoff (at
/// most 10 000 voxels, [`GlobalParams::cutoff`]) every component fits an
/// `i16`. A distance that disagrees with its obstacle cannot be stored.
///
/// Stored by layer ([`Layers`]): a block whose voxels within the cutoff
/// all lie in one layer holds that layer alone (a planar map's blocks).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EdtBlock {
    /// Nearest obstacle less the voxel's own index, [`NO_OFFSET`] beyond
    /// the cutoff.
    pub to_nearest: Layers<[i16; 3]>,
}

impl Cell for [i16; 3] {
    const EMPTY: [i16; 3] = NO_OFFSET;
    const EMPTY_LAYER: &'static [[i16; 3]; LAYER_VOXELS] = &[NO_OFFSET; LAYER_VOXELS];
}

impl crate::BlockHeap for EdtBlock {
    fn heap_bytes(&self) -> usize {
        self.to_nearest.heap_bytes()
    }
}

impl EdtBlock {
    /// Whether no voxel of the block has an obstacle within the cutoff.
    pub fn is_far(&self) -> bool {
        self.to_nearest.is_empty()
    }

    /// Frees the block's voxels if none has an obstacle within the cutoff;
    /// returns whether it did (the block is [`Self::is_far`] and need not
    /// be kept).
    pub fn trim(&mut self) -> bool {
        self.to_nearest.trim()
    }

    /// Squared distance of the voxel at `offset`, voxels², [`FAR_DIST_SQ`]
    /// beyond the cutoff.
    #[inline]
    pub fn dist_sq(&self, offset: usize) -> u32 {
        offset_dist_sq(self.to_nearest[offset])
    }

    /// Squared distance and offset to the nearest obstacle of the voxel at
    /// `offset`, as [`Self::dist_sq`] and [`Self::to_nearest`] hold them.
    #[inline]
    pub fn stored(&self, offset: usize) -> (u32, [i16; 3]) {
        let o = self.to_nearest[offset];
        (offset_dist_sq(o), o)
    }

    /// World index of the nearest obstacle of the voxel at `offset` of the
    /// block at `key`, [`NO_OBSTACLE`] beyond the cutoff.
    #[inline]
    pub fn nearest(&self, key: BlockKey, offset: usize) -> VoxelIndex {
        from_offset(key.voxel(offset), self.to_nearest[offset])
    }

    /// Squared distance and nearest obstacle of the voxel at `offset` of
    /// the block at `key`.
    #[inline]
    pub fn entry(&self, key: BlockKey, offset: usize) -> (u32, VoxelIndex) {
        (self.dist_sq(offset), self.nearest(key, offset))
    }

    /// Sets the voxel at `offset` of the block at `key`; fails, changing
    /// nothing, where `nearest` lies more than `i16::MAX` voxels from it on
    /// some axis (no obstacle within a cutoff does) or `dist_sq` is not its
    /// squared distance ([`FAR_DIST_SQ`] with [`NO_OBSTACLE`]).
    pub fn set(&mut self, key: BlockKey, offset: usize, dist_sq: u32, nearest: VoxelIndex) -> Result<(), EntryError> {
        let voxel = key.voxel(offset);
        let o = to_offset(voxel, nearest).ok_or(EntryError::TooFar { voxel, nearest })?;
        if offset_dist_sq(o) != dist_sq {
            return Err(EntryError::Mismatch { voxel, dist_sq, nearest });
        }
        self.to_nearest.set(offset, o);
        Ok(())
    }

    /// Sets the voxel at `offset` of the block at `key` to an entry that a
    /// backend computed within a cutoff: its obstacle lies within the
    /// offsets' range, its distance is the obstacle's. (Any other would be
    /// a backend's bug: caught in debug builds, stored as no obstacle.)
    #[inline]
    pub fn put(&mut self, key: BlockKey, offset: usize, dist_sq: u32, nearest: VoxelIndex) {
        if let Err(e) = self.set(key, offset, dist_sq, nearest) {
            debug_assert!(false, "{e}");
            self.to_nearest.set(offset, NO_OFFSET);
        }
    }
}

/// An entry [`EdtBlock`] cannot hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EntryError {
    /// The obstacle is more than `i16::MAX` voxels away on some axis.
    #[error("voxel {:?}: its nearest obstacle {:?} lies more than 32767 voxels away on some axis", .voxel.0, .nearest.0)]
    TooFar {
        /// The voxel.
        voxel: VoxelIndex,
        /// Its obstacle.
        nearest: VoxelIndex,
    },
    /// The squared distance is not the obstacle's.
    #[error("voxel {:?} {}", .voxel.0, mismatch(*.dist_sq, *.nearest, *.voxel))]
    Mismatch {
        /// The voxel.
        voxel: VoxelIndex,
        /// The squared distance given.
        dist_sq: u32,
        /// The obstacle given.
        nearest: VoxelIndex,
    },
}

/// How `dist_sq` disagrees with `nearest` as seen from `voxel`.
fn mismatch(dist_sq: u32, nearest: VoxelIndex, voxel: VoxelIndex) -> String {
    if dist_sq == FAR_DIST_SQ {
        format!("is beyond the cutoff but names a nearest obstacle {:?}", nearest.0)
    } else if nearest == NO_OBSTACLE {
        format!("holds dist_sq {dist_sq} but names no nearest obstacle")
    } else {
        let actual: u128 =
            (0..3).map(|a| u128::from((i64::from(voxel.0[a]) - i64::from(nearest.0[a])).unsigned_abs()).pow(2)).sum();
        format!("holds dist_sq {dist_sq} but its nearest obstacle {:?} lies at dist_sq {actual}", nearest.0)
    }
}

/// The squared length of offset `o`, [`FAR_DIST_SQ`] for [`NO_OFFSET`]
/// (at most 3 · 32767², below it).
#[inline]
pub(crate) fn offset_dist_sq(o: [i16; 3]) -> u32 {
    if o[0] == i16::MIN {
        return FAR_DIST_SQ;
    }
    o.iter().map(|&c| (i32::from(c) * i32::from(c)) as u32).sum()
}

/// The offset from `v` to `nearest` ([`NO_OFFSET`] for [`NO_OBSTACLE`]),
/// `None` where a component does not fit an `i16` (or is its least value,
/// which marks no obstacle).
#[inline]
fn to_offset(v: VoxelIndex, nearest: VoxelIndex) -> Option<[i16; 3]> {
    if nearest == NO_OBSTACLE {
        return Some(NO_OFFSET);
    }
    let mut out = [0i16; 3];
    for ((o, &n), &at) in out.iter_mut().zip(&nearest.0).zip(&v.0) {
        *o = i16::try_from(i64::from(n) - i64::from(at)).ok().filter(|&d| d != i16::MIN)?;
    }
    Some(out)
}

/// The obstacle at offset `o` from `v` ([`NO_OBSTACLE`] for [`NO_OFFSET`]).
#[inline]
fn from_offset(v: VoxelIndex, o: [i16; 3]) -> VoxelIndex {
    if o[0] == i16::MIN {
        return NO_OBSTACLE;
    }
    VoxelIndex([0, 1, 2].map(|a| v.0[a].wrapping_add(i32::from(o[a]))))
}

/// The global EDT: unbounded, blocks allocated where some voxel has an
/// obstacle within the cutoff. A missing block is all [`FAR_DIST_SQ`].
pub type EdtMap = BlockMap<EdtBlock>;

impl EdtMap {
    /// Squared distance and nearest obstacle of voxel `v`.
    pub fn entry(&self, v: VoxelIndex) -> (u32, VoxelIndex) {
        match self.get(v.block()) {
            Some(b) => {
                let o = b.to_nearest[v.offset_in_block()];
                (offset_dist_sq(o), from_offset(v, o))
            }
            None => (FAR_DIST_SQ, NO_OBSTACLE),
        }
    }
}

/// Which neighbours a wavefront reaches in one step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(try_from = "u8", into = "u8")]
pub enum Connectivity {
    /// Face neighbours (GIE-mapping's only choice).
    Six,
    /// Face and edge neighbours.
    Eighteen,
    /// Face, edge and corner neighbours.
    #[default]
    TwentySix,
}

impl Connectivity {
    /// The neighbour offsets, faces first.
    pub fn offsets(self) -> Vec<[i32; 3]> {
        let max_nonzero = match self {
            Connectivity::Six => 1,
            Connectivity::Eighteen => 2,
            Connectivity::TwentySix => 3,
        };
        let mut out = Vec::new();
        for dz in -1i32..=1 {
            for dy in -1i32..=1 {
                for dx in -1i32..=1 {
                    let n = dx.abs() + dy.abs() + dz.abs();
                    if n >= 1 && n <= max_nonzero {
                        out.push([dx, dy, dz]);
                    }
                }
            }
        }
        out.sort_by_key(|o| o.iter().map(|c| c.abs()).sum::<i32>());
        out
    }
}

impl TryFrom<u8> for Connectivity {
    type Error = String;
    fn try_from(n: u8) -> Result<Self, String> {
        match n {
            6 => Ok(Connectivity::Six),
            18 => Ok(Connectivity::Eighteen),
            26 => Ok(Connectivity::TwentySix),
            _ => Err(format!("connectivity = {n}: must be 6, 18 or 26")),
        }
    }
}

impl From<Connectivity> for u8 {
    fn from(c: Connectivity) -> u8 {
        match c {
            Connectivity::Six => 6,
            Connectivity::Eighteen => 18,
            Connectivity::TwentySix => 26,
        }
    }
}

/// How each frame's batch EDT is merged into the global EDT.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum IntegrationMode {
    /// The paper's Algorithms 2 and 3: the batch EDT of the window every
    /// frame, raise and lower wavefronts outside it. Approximate: off by a
    /// fraction of a voxel where a Voronoi cell is not connected through
    /// the neighbourhood. The GPU's design.
    Wavefront,
    /// The exact EDT of the map's obstacles after every frame, updated from
    /// the obstacles the frame changed: on the CPU, the separable EDT's
    /// passes kept between frames and redone only along the lines through
    /// changes; on a GPU, an exact batch EDT of the changed blocks grown by
    /// the cutoff. The default.
    #[default]
    Exact,
}

/// A box of space that counts as an obstacle whatever the sensors say
/// (paper §III, domain knowledge), world metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForbiddenZone {
    /// Lowest corner, metres.
    pub min_m: [f64; 3],
    /// Highest corner, metres.
    pub max_m: [f64; 3],
}

/// Parameters of the global EDT.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GlobalParams {
    /// Cutoff: no distance beyond this is stored or propagated, metres.
    pub max_distance_m: f64,
    /// Neighbourhood of the wavefronts.
    pub connectivity: Connectivity,
    /// Wavefront (the paper's) or exact integration.
    pub mode: IntegrationMode,
    /// Boxes that always count as obstacles.
    pub forbidden: Vec<ForbiddenZone>,
    /// A planar map: distances are measured within each horizontal layer
    /// of voxels (a 2D EDT per layer, as a planar LiDAR's map needs), and
    /// no distance is kept above or below the layers that hold obstacles.
    /// Needs the exact mode. Written to a map file only when set, so other
    /// maps' files stay as they were.
    #[serde(skip_serializing_if = "is_false")]
    pub planar: bool,
}

fn is_false(b: &bool) -> bool {
    !*b
}

impl Default for GlobalParams {
    fn default() -> Self {
        GlobalParams {
            max_distance_m: DEFAULT_MAX_DISTANCE_M,
            connectivity: Connectivity::default(),
            mode: IntegrationMode::default(),
            forbidden: Vec::new(),
            planar: false,
        }
    }
}

impl GlobalParams {
    /// The cutoff as a squared distance and a reach per axis, in voxels of
    /// `voxel_size_m`; fails on a cutoff that is not positive and finite,
    /// below one voxel, or beyond 10 000 voxels, and on a planar map in
    /// wavefront mode.
    pub fn cutoff(&self, voxel_size_m: f64) -> Result<Cutoff, CoreError> {
        if self.planar && self.mode != IntegrationMode::Exact {
            return Err(CoreError::InvalidParam {
                field: "planar",
                value: "true".to_string(),
                reason: "a planar map needs mode = \"exact\" (the wavefronts are three-dimensional)",
            });
        }
        // The tolerance keeps 0.6 m / 0.2 m at 3 voxels, not 2.999….
        let vox = self.max_distance_m / voxel_size_m * (1.0 + 1e-9);
        if !(1.0..=10_000.0).contains(&vox) {
            return Err(CoreError::InvalidParam {
                field: "max_distance_m",
                value: self.max_distance_m.to_string(),
                reason: "must be at least one voxel and at most 10000 voxels",
            });
        }
        let max_dist_sq = (vox * vox).floor() as u32;
        Ok(Cutoff { max_dist_sq, reach: vox.floor() as i32, planar: self.planar })
    }

    /// Checks every forbidden zone: finite corners, min below max.
    pub fn check_forbidden(&self) -> Result<(), CoreError> {
        for z in &self.forbidden {
            let ok = (0..3).all(|a| z.min_m[a].is_finite() && z.max_m[a].is_finite() && z.min_m[a] < z.max_m[a]);
            if !ok {
                return Err(CoreError::InvalidParam {
                    field: "forbidden",
                    value: format!("{{ min_m = {:?}, max_m = {:?} }}", z.min_m, z.max_m),
                    reason: "corners must be finite with min_m < max_m on every axis",
                });
            }
        }
        Ok(())
    }
}

/// The cutoff in voxel units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cutoff {
    /// Largest squared distance stored, voxels².
    pub max_dist_sq: u32,
    /// Largest distance along one axis, voxels: every voxel within the
    /// cutoff of `v` lies within `reach` of it on each axis (on x and y
    /// only, for a planar map).
    pub reach: i32,
    /// Distances within each horizontal layer ([`GlobalParams::planar`]).
    pub planar: bool,
}

impl Cutoff {
    /// How far the cutoff reaches along each axis, voxels: `reach`, and 0
    /// along z for a planar map.
    pub fn pad(&self) -> [i32; 3] {
        [self.reach, self.reach, if self.planar { 0 } else { self.reach }]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn connectivity_counts() {
        assert_eq!(Connectivity::Six.offsets().len(), 6);
        assert_eq!(Connectivity::Eighteen.offsets().len(), 18);
        assert_eq!(Connectivity::TwentySix.offsets().len(), 26);
        assert!(Connectivity::try_from(8).is_err());
    }

    #[test]
    fn cutoff_in_voxels() {
        let p = GlobalParams { max_distance_m: 2.0, ..Default::default() };
        let c = p.cutoff(0.2).expect("valid");
        assert_eq!((c.max_dist_sq, c.reach), (100, 10));
        let c = GlobalParams { max_distance_m: 0.6, ..Default::default() }.cutoff(0.2).expect("valid");
        assert_eq!((c.max_dist_sq, c.reach), (9, 3));
        let c = p.cutoff(0.3).expect("valid");
        assert_eq!((c.max_dist_sq, c.reach), (44, 6));
        assert!(p.cutoff(5.0).is_err());
        let bad = GlobalParams { max_distance_m: f64::NAN, ..Default::default() };
        assert!(bad.cutoff(0.1).expect_err("NaN cutoff").to_string().contains("max_distance_m"));
    }

    #[test]
    fn offsets_hold_every_obstacle_within_the_largest_cutoff() {
        // About the largest cutoff a GlobalParams allows: the offsets
        // round-trip with their distances, one voxel further on an axis
        // than an i16 holds is refused, and so is a distance that is not
        // the obstacle's; a refused entry changes nothing.
        let reach = GlobalParams { max_distance_m: 9_999.0, ..Default::default() }.cutoff(1.0).expect("largest").reach;
        assert_eq!(reach, 9_999);
        let key = BlockKey([1_000_000, -1, -7_000]);
        let mut b = EdtBlock::default();
        for offset in [0, 7, 63, 511] {
            let v = key.voxel(offset);
            for d in [[0, 0, 0], [reach, -reach, 1], [-reach, 3, reach], [-32767, 32767, 32767]] {
                let n = VoxelIndex([0, 1, 2].map(|a| v.0[a] + d[a]));
                let dist_sq = d.iter().map(|&c| (i64::from(c) * i64::from(c)) as u32).sum();
                b.set(key, offset, dist_sq, n).expect("within range");
                assert_eq!(b.entry(key, offset), (dist_sq, n), "{offset} {d:?}");
            }
            let far = VoxelIndex([v.0[0] - 32768, v.0[1], v.0[2]]);
            assert_eq!(b.set(key, offset, 32768 * 32768, far), Err(EntryError::TooFar { voxel: v, nearest: far }));
            let near = VoxelIndex([v.0[0] + 1, v.0[1], v.0[2]]);
            for (d, n) in [(2, near), (FAR_DIST_SQ, near), (0, NO_OBSTACLE)] {
                let err = b.set(key, offset, d, n).expect_err("mismatch");
                assert_eq!(err, EntryError::Mismatch { voxel: v, dist_sq: d, nearest: n });
            }
            assert_eq!(b.to_nearest[offset], [-32767, 32767, 32767], "refused entries changed nothing");
            b.set(key, offset, FAR_DIST_SQ, NO_OBSTACLE).expect("none");
            assert_eq!(b.entry(key, offset), (FAR_DIST_SQ, NO_OBSTACLE));
        }
        assert!(b.is_far());
        let mut map = EdtMap::new();
        let v = key.voxel(100);
        map.get_or_insert(key).set(key, 100, 2, VoxelIndex([v.0[0] + 1, v.0[1] - 1, v.0[2]])).expect("near");
        assert_eq!(map.entry(v), (2, VoxelIndex([v.0[0] + 1, v.0[1] - 1, v.0[2]])));
        assert_eq!(map.entry(key.voxel(101)), (FAR_DIST_SQ, NO_OBSTACLE));
        assert!(!map.get(key).expect("made").is_far());
    }
}
