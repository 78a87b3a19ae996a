//! Scores of a map against ground truth, for `--eval` and the tests.
//!
//! * **Precision**: of the voxels the map holds occupied, the fraction whose
//!   closed cube meets a solid of the scene. A mapped obstacle that touches
//!   no solid is wrong, whatever the resolution.
//! * **Recall**: of the voxels holding a surface point that the frame's
//!   beams hit in the exact scene (the surface the sensor saw, noise-free),
//!   the fraction the map holds occupied.
//! * **Strict recall**: of the observed voxels whose cube meets a solid,
//!   the fraction mapped occupied. It is lower and says less: a voxel that a
//!   surface only clips (the far side of a pillar poking out beside its
//!   silhouette, say) is partly free, and beams that pass through its free
//!   part rightly call it free.

use crate::MapError;
use edtmap_core::exact::exact_region;
use edtmap_core::region::Region;
use edtmap_core::{GlobalMap, VoxelState, FAR_DIST_SQ};

/// Occupancy scores of one volume (or the sum of several).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct OccupancyScores {
    /// Voxels mapped occupied.
    pub mapped_occupied: usize,
    /// Voxels mapped occupied whose cube meets a solid.
    pub mapped_occupied_true: usize,
    /// Voxels holding a surface point the beams hit.
    pub seen_surface: usize,
    /// Of those, voxels mapped occupied.
    pub seen_surface_mapped: usize,
    /// Observed voxels whose cube meets a solid.
    pub truth_observed: usize,
    /// Of those, voxels mapped occupied.
    pub truth_observed_mapped: usize,
    /// Voxels the map has observed (free or occupied).
    pub observed: usize,
}

impl OccupancyScores {
    /// Compares mapped `states` with `truth` (cube meets a solid) and
    /// `seen` (holds a surface point the beams hit), voxel by voxel.
    pub fn compare(states: &[VoxelState], truth: &[bool], seen: &[bool]) -> Self {
        let mut s = OccupancyScores::default();
        for ((&state, &solid), &hit) in states.iter().zip(truth).zip(seen) {
            let occupied = state == VoxelState::Occupied;
            s.observed += usize::from(state != VoxelState::Unknown);
            s.mapped_occupied += usize::from(occupied);
            s.mapped_occupied_true += usize::from(occupied && solid);
            s.seen_surface += usize::from(hit);
            s.seen_surface_mapped += usize::from(hit && occupied);
            s.truth_observed += usize::from(solid && state != VoxelState::Unknown);
            s.truth_observed_mapped += usize::from(solid && occupied);
        }
        s
    }

    /// Adds another volume's counts.
    pub fn add(&mut self, o: &OccupancyScores) {
        self.mapped_occupied += o.mapped_occupied;
        self.mapped_occupied_true += o.mapped_occupied_true;
        self.seen_surface += o.seen_surface;
        self.seen_surface_mapped += o.seen_surface_mapped;
        self.truth_observed += o.truth_observed;
        self.truth_observed_mapped += o.truth_observed_mapped;
        self.observed += o.observed;
    }

    /// Fraction of mapped-occupied voxels that meet a solid, if any.
    pub fn precision(&self) -> Option<f64> {
        ratio(self.mapped_occupied_true, self.mapped_occupied)
    }

    /// Fraction of the seen surface's voxels mapped occupied, if any.
    pub fn recall(&self) -> Option<f64> {
        ratio(self.seen_surface_mapped, self.seen_surface)
    }

    /// Fraction of observed solid-meeting voxels mapped occupied, if any.
    pub fn strict_recall(&self) -> Option<f64> {
        ratio(self.truth_observed_mapped, self.truth_observed)
    }
}

fn ratio(a: usize, b: usize) -> Option<f64> {
    (b > 0).then(|| a as f64 / b as f64)
}

/// Fraction of the voxels observed in both `a` and `b` whose states agree,
/// and how many there were.
pub fn agreement(a: &[VoxelState], b: &[VoxelState]) -> (f64, usize) {
    let (mut same, mut both) = (0usize, 0usize);
    for (x, y) in a.iter().zip(b) {
        if *x != VoxelState::Unknown && *y != VoxelState::Unknown {
            both += 1;
            same += usize::from(x == y);
        }
    }
    (ratio(same, both).unwrap_or(1.0), both)
}

#[cfg(test)]
mod tests {
    use super::*;
    use VoxelState::*;

    #[test]
    fn scores_count_each_kind_of_voxel() {
        let states = [Occupied, Occupied, Free, Free, Unknown, Occupied];
        let truth = [true, false, true, false, true, true];
        let seen = [true, false, true, false, false, false];
        let s = OccupancyScores::compare(&states, &truth, &seen);
        assert_eq!(s.precision(), Some(2.0 / 3.0));
        assert_eq!(s.recall(), Some(0.5));
        assert_eq!(s.strict_recall(), Some(2.0 / 3.0));
        assert_eq!(s.observed, 5);
        assert_eq!(OccupancyScores::default().recall(), None);
        assert_eq!(agreement(&[Free, Occupied, Unknown], &[Free, Free, Free]), (0.5, 2));
    }
}

/// Error of a global EDT against the exact EDT of the same map's obstacles
/// (the paper's RMS error, with the mapper's own occupancy as the truth).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EdtErrors {
    /// Root mean square of the distance error, metres.
    pub rms_m: f64,
    /// Largest distance error, metres.
    pub max_m: f64,
    /// Fraction of the voxels compared whose squared distance is wrong.
    pub wrong_fraction: f64,
    /// Voxels compared: those with an obstacle within the cutoff in either.
    pub voxels: usize,
}

/// [`EdtErrors`] of `map`'s EDT over the box `region`, against an exact
/// EDT computed from its obstacles. Distances beyond the cutoff count as
/// the cutoff.
pub fn edt_errors(map: &GlobalMap, region: &Region) -> Result<EdtErrors, MapError> {
    let exact = exact_region(&mut edtmap_cpu::CpuBackend::default(), &map.obstacles(), region, map.cutoff())?;
    let vs = map.voxel_size_m();
    let cap = f64::from(map.cutoff().max_dist_sq).sqrt();
    let metres = |d: u32| if d == FAR_DIST_SQ { cap * vs } else { f64::from(d).sqrt() * vs };
    let (mut sum_sq, mut max, mut wrong, mut voxels) = (0.0, 0.0f64, 0usize, 0usize);
    for (i, &truth) in exact.iter().enumerate() {
        let (stored, _) = map.entry(region.world(region.coords(i)));
        if stored == FAR_DIST_SQ && truth == FAR_DIST_SQ {
            continue;
        }
        let err = (metres(stored) - metres(truth)).abs();
        (sum_sq, max, voxels) = (sum_sq + err * err, max.max(err), voxels + 1);
        wrong += usize::from(stored != truth);
    }
    let n = voxels.max(1) as f64;
    Ok(EdtErrors { rms_m: (sum_sq / n).sqrt(), max_m: max, wrong_fraction: wrong as f64 / n, voxels })
}

/// The box spanned by `map`'s EDT blocks, if any.
pub fn edt_extent(map: &GlobalMap) -> Option<Region> {
    map.edt().key_bounds().map(Region::of_blocks)
}
