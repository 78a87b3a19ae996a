//! The checks a map passes before it is written and after it is read, so a
//! file this crate writes is always one it reads back.

use edtmap_core::{
    check_voxel_size, BlockKey, BlockMap, CoreError, Cutoff, EdtMap, GlobalMap, GlobalParams, OccupancyMap,
    OccupancyParams, BLOCK_SIDE, BLOCK_VOXELS, FAR_DIST_SQ,
};

use super::layout::Payload;
use super::MapFileError;

/// Lowest block key on each axis whose voxels have `i32` indices.
const MIN_KEY: i32 = i32::MIN / BLOCK_SIDE;
/// Highest such block key.
const MAX_KEY: i32 = i32::MAX.div_euclid(BLOCK_SIDE);

/// Checks the keys, log-odds and EDT entries (a [`GlobalMap`] has valid
/// parameters and one voxel size by construction).
pub(super) fn check_contents(map: &GlobalMap) -> Result<(), MapFileError> {
    check_keys(map.occupancy())?;
    check_keys(map.edt())?;
    check_keys(map.fixed_obstacles())?;
    check_log_odds(map.occupancy())?;
    check_edt(map.edt(), map.cutoff())
}

/// Validates the parameters as the mapper does; returns the EDT cutoff.
pub(super) fn check_params(
    voxel_size_m: f64,
    occupancy: &OccupancyParams,
    global: &GlobalParams,
) -> Result<Cutoff, MapFileError> {
    let invalid = |e: CoreError| MapFileError::InvalidParams(e.to_string());
    check_voxel_size(voxel_size_m).map_err(invalid)?;
    occupancy.log_odds().map_err(invalid)?;
    let cutoff = global.cutoff(voxel_size_m).map_err(invalid)?;
    global.check_forbidden().map_err(invalid)?;
    Ok(cutoff)
}

/// The map's blocks in ascending key order, so the first problem reported
/// does not depend on hash order.
fn sorted<B: Default>(map: &BlockMap<B>) -> Vec<(BlockKey, &B)> {
    let mut blocks: Vec<_> = map.iter().collect();
    blocks.sort_unstable_by_key(|&(key, _)| key);
    blocks
}

/// Every key's voxels must have `i32` indices.
fn check_keys<B: Payload>(map: &BlockMap<B>) -> Result<(), MapFileError> {
    sorted(map).into_iter().try_for_each(|(key, _)| check_key::<B>(key))
}

/// A key's voxels must have `i32` indices (checked by the reader before
/// it decodes the block, whose voxels it may need).
pub(super) fn check_key<B: Payload>(key: BlockKey) -> Result<(), MapFileError> {
    if key.0.iter().any(|&c| !(MIN_KEY..=MAX_KEY).contains(&c)) {
        return Err(MapFileError::Corrupt(format!(
            "block key {:?} in the {} section lies outside the voxel index range",
            key.0,
            B::SECTION
        )));
    }
    Ok(())
}

/// A log-odds is finite or [`edtmap_core::UNOBSERVED`] (−∞).
fn check_log_odds(map: &OccupancyMap) -> Result<(), MapFileError> {
    for (key, block) in sorted(map) {
        if let Some(i) = block.log_odds.iter().position(|v| v.is_nan() || v == f32::INFINITY) {
            let v = key.voxel(i);
            return Err(MapFileError::Corrupt(format!(
                "occupancy voxel {:?} holds log-odds {}",
                v.0, block.log_odds[i]
            )));
        }
    }
    Ok(())
}

/// Every EDT entry lies within the cutoff or beyond it, and on a planar
/// map in its voxel's layer. (That its
/// distance is its obstacle's, or far with none, the block itself keeps:
/// the reader refuses any other as it reads it.)
fn check_edt(map: &EdtMap, cutoff: Cutoff) -> Result<(), MapFileError> {
    for (key, block) in sorted(map) {
        for i in 0..BLOCK_VOXELS {
            let d = block.dist_sq(i);
            if d != FAR_DIST_SQ && d > cutoff.max_dist_sq {
                return Err(MapFileError::Corrupt(format!(
                    "EDT voxel {:?} holds offset {:?} to its nearest obstacle, dist_sq {d}, beyond the cutoff's {}",
                    key.voxel(i).0,
                    block.to_nearest[i],
                    cutoff.max_dist_sq
                )));
            }
            if cutoff.planar && d != FAR_DIST_SQ && block.to_nearest[i][2] != 0 {
                return Err(MapFileError::Corrupt(format!(
                    "EDT voxel {:?} of a planar map holds offset {:?} to its nearest obstacle, outside its layer",
                    key.voxel(i).0,
                    block.to_nearest[i]
                )));
            }
        }
    }
    Ok(())
}
