//! The local volume: a dense box of voxels centred on the sensor, moved with
//! every update (paper §IV-A; GIE-mapping re-centres it on the robot's voxel).

use crate::{BlockKey, CoreError, Region, VoxelIndex, BLOCK_SIDE};
use serde::{Deserialize, Serialize};

/// Where the local volume sits: its size and an optional fixed height.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VolumeParams {
    /// Edge lengths of the box in metres (x, y, z).
    pub size_m: [f64; 3],
    /// Height (world z, metres) of the box centre for ground robots; `None`
    /// centres it on the sensor in z as well.
    #[serde(default)]
    pub fixed_height_m: Option<f64>,
}

impl Default for VolumeParams {
    /// GIE-mapping's default, 10 × 10 × 3 m.
    fn default() -> Self {
        VolumeParams { size_m: [10.0, 10.0, 3.0], fixed_height_m: None }
    }
}

/// A dense box of world voxels: `dims` voxels from `origin` (its lowest
/// corner voxel). Local coordinates follow [`crate::Grid3`]: x fastest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalVolume {
    /// World index of the voxel at local `(0, 0, 0)`.
    pub origin: VoxelIndex,
    /// Voxels along x, y and z.
    pub dims: [usize; 3],
    /// Voxel edge length in metres.
    pub voxel_size_m: f64,
}

impl LocalVolume {
    /// The volume of `params` centred on `centre_m` (world, metres), snapped
    /// to the voxel grid. Fails on a non-positive or non-finite size or
    /// voxel size, or a centre that is not finite.
    pub fn centred(params: &VolumeParams, voxel_size_m: f64, centre_m: [f64; 3]) -> Result<Self, CoreError> {
        check_voxel_size(voxel_size_m)?;
        let dims = volume_dims(params, voxel_size_m)?;
        let mut centre = centre_m;
        if let Some(h) = params.fixed_height_m {
            centre[2] = h;
        }
        let centre_vox = VoxelIndex::containing(centre, voxel_size_m).ok_or(CoreError::InvalidParam {
            field: "sensor position",
            value: format!("{centre:?}"),
            reason: "not a finite point in the voxel index range",
        })?;
        let origin = VoxelIndex([0, 1, 2].map(|a| centre_vox.0[a].saturating_sub((dims[a] / 2) as i32)));
        Ok(LocalVolume { origin, dims, voxel_size_m })
    }

    /// The box of world voxels the volume covers: the one box type every
    /// stage works with (the volume adds only its voxel size).
    #[inline]
    pub fn region(&self) -> Region {
        Region { origin: self.origin.0, dims: self.dims }
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.region().len()
    }

    /// Whether the volume has no voxel (never true for a built volume).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Local coordinates of world voxel `v`, if inside.
    pub fn local(&self, v: VoxelIndex) -> Option<[usize; 3]> {
        self.region().local(v)
    }

    /// World voxel at local coordinates `c`.
    pub fn world(&self, c: [usize; 3]) -> VoxelIndex {
        self.region().world(c)
    }

    /// Linear index of local coordinates `c` (x fastest).
    pub fn linear(&self, c: [usize; 3]) -> usize {
        self.region().linear(c)
    }

    /// Lowest corner of the volume in world metres.
    pub fn min_corner_m(&self) -> [f64; 3] {
        self.origin.0.map(|i| i as f64 * self.voxel_size_m)
    }

    /// Every block that overlaps the volume, z slowest then y then x.
    pub fn blocks(&self) -> Vec<BlockKey> {
        self.region().blocks()
    }

    /// The local-coordinate range `[lo, hi)` per axis that block `key` covers.
    pub fn block_span(&self, key: BlockKey) -> [std::ops::Range<usize>; 3] {
        [0, 1, 2].map(|a| {
            let first = key.0[a] as i64 * BLOCK_SIDE as i64 - self.origin.0[a] as i64;
            let lo = first.clamp(0, self.dims[a] as i64) as usize;
            let hi = (first + BLOCK_SIDE as i64).clamp(0, self.dims[a] as i64) as usize;
            lo..hi
        })
    }
}

/// Checks that a voxel size is positive and finite.
pub fn check_voxel_size(voxel_size_m: f64) -> Result<(), CoreError> {
    if voxel_size_m.is_finite() && voxel_size_m > 0.0 {
        Ok(())
    } else {
        Err(CoreError::InvalidParam {
            field: "voxel_size_m",
            value: voxel_size_m.to_string(),
            reason: "must be positive and finite",
        })
    }
}

fn volume_dims(params: &VolumeParams, voxel_size_m: f64) -> Result<[usize; 3], CoreError> {
    let mut dims = [0usize; 3];
    for (d, &s) in dims.iter_mut().zip(&params.size_m) {
        let n = (s / voxel_size_m).round();
        if !(s.is_finite() && s > 0.0 && (1.0..=1e6).contains(&n.max(1.0))) {
            return Err(CoreError::InvalidParam {
                field: "size_m",
                value: format!("{:?}", params.size_m),
                reason: "each edge must be positive, finite and under a million voxels",
            });
        }
        *d = n.max(1.0) as usize;
    }
    crate::Grid3::<u8>::voxel_count(dims)?;
    Ok(dims)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centred_volume_snaps_to_the_grid() {
        let p = VolumeParams { size_m: [1.0, 1.0, 0.4], fixed_height_m: None };
        let v = LocalVolume::centred(&p, 0.1, [0.03, -0.01, 2.0]).expect("valid");
        assert_eq!(v.dims, [10, 10, 4]);
        assert_eq!(v.origin, VoxelIndex([-5, -6, 18]));
        assert_eq!(v.local(VoxelIndex([0, -1, 20])), Some([5, 5, 2]));
        assert_eq!(v.local(VoxelIndex([5, 0, 20])), None);
    }

    #[test]
    fn fixed_height_overrides_sensor_z() {
        let p = VolumeParams { size_m: [1.0, 1.0, 1.0], fixed_height_m: Some(0.5) };
        let v = LocalVolume::centred(&p, 0.1, [0.0, 0.0, 7.0]).expect("valid");
        assert_eq!(v.origin.0[2], 0);
    }

    #[test]
    fn bad_sizes_name_the_field() {
        let p = VolumeParams::default();
        let e = LocalVolume::centred(&p, -0.1, [0.0; 3]).expect_err("negative voxel");
        assert!(e.to_string().contains("voxel_size_m"), "{e}");
        let p = VolumeParams { size_m: [1.0, f64::NAN, 1.0], fixed_height_m: None };
        assert!(LocalVolume::centred(&p, 0.1, [0.0; 3]).is_err());
    }

    #[test]
    fn block_spans_cover_the_volume_once() {
        let p = VolumeParams { size_m: [1.3, 0.7, 0.9], fixed_height_m: None };
        let v = LocalVolume::centred(&p, 0.1, [0.31, -0.77, 0.05]).expect("valid");
        let mut count = vec![0u8; v.len()];
        for key in v.blocks() {
            let [xs, ys, zs] = v.block_span(key);
            for z in zs.clone() {
                for y in ys.clone() {
                    for x in xs.clone() {
                        count[v.linear([x, y, z])] += 1;
                        assert_eq!(v.world([x, y, z]).block(), key);
                    }
                }
            }
        }
        assert!(count.iter().all(|&c| c == 1));
    }
}
