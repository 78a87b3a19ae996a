//! Scores of a map against ground truth, for `--eval` and the tests.

use edtmap_core::VoxelState;

/// Occupied-voxel precision and recall over the voxels a map has observed.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct OccupancyScores {
    /// Observed voxels mapped occupied that are occupied in truth.
    pub true_positives: usize,
    /// Observed voxels mapped occupied that are free in truth.
    pub false_positives: usize,
    /// Observed voxels mapped free that are occupied in truth.
    pub false_negatives: usize,
    /// Voxels the map has observed (free or occupied).
    pub observed: usize,
}

impl OccupancyScores {
    /// Compares mapped `states` with `truth` (`true` = occupied), voxel by
    /// voxel; unknown voxels are left out.
    pub fn compare(states: &[VoxelState], truth: &[bool]) -> Self {
        let mut s = OccupancyScores::default();
        for (&state, &occupied) in states.iter().zip(truth) {
            match (state, occupied) {
                (VoxelState::Unknown, _) => continue,
                (VoxelState::Occupied, true) => s.true_positives += 1,
                (VoxelState::Occupied, false) => s.false_positives += 1,
                (VoxelState::Free, true) => s.false_negatives += 1,
                (VoxelState::Free, false) => {}
            }
            s.observed += 1;
        }
        s
    }

    /// Fraction of mapped-occupied voxels that are occupied, if any.
    pub fn precision(&self) -> Option<f64> {
        ratio(self.true_positives, self.true_positives + self.false_positives)
    }

    /// Fraction of truly occupied observed voxels mapped occupied, if any.
    pub fn recall(&self) -> Option<f64> {
        ratio(self.true_positives, self.true_positives + self.false_negatives)
    }
}

fn ratio(a: usize, b: usize) -> Option<f64> {
    (b > 0).then(|| a as f64 / b as f64)
}

/// Fraction of the voxels observed in both `a` and `b` whose states agree,
/// and how many there were.
pub fn agreement(a: &[VoxelState], b: &[VoxelState]) -> (f64, usize) {
    let both: Vec<bool> = a
        .iter()
        .zip(b)
        .filter(|(x, y)| **x != VoxelState::Unknown && **y != VoxelState::Unknown)
        .map(|(x, y)| x == y)
        .collect();
    let same = both.iter().filter(|&&s| s).count();
    (ratio(same, both.len()).unwrap_or(1.0), both.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use VoxelState::*;

    #[test]
    fn scores_count_only_observed_voxels() {
        let states = [Occupied, Occupied, Free, Free, Unknown];
        let truth = [true, false, true, false, true];
        let s = OccupancyScores::compare(&states, &truth);
        assert_eq!((s.true_positives, s.false_positives, s.false_negatives, s.observed), (1, 1, 1, 4));
        assert_eq!(s.precision(), Some(0.5));
        assert_eq!(OccupancyScores::default().recall(), None);
        assert_eq!(agreement(&[Free, Occupied, Unknown], &[Free, Free, Free]), (0.5, 2));
    }
}
