//! Exact integration: a frame changes occupancy only inside its window
//! `W`, so only voxels within the cutoff of `W` can change their truncated
//! distance, and their obstacles lie within the cutoff of those voxels. One
//! exact batch EDT of `W` grown twice by the reach, from the global
//! obstacles, therefore gives every voxel of `W` grown once its exact new
//! value; they are written back where they changed.

use super::region::{copy_in, write_back, Packing, Region, WriteBack, FAR};
use crate::edt::{edt_into, ScanLayout};
use crate::CpuError;
use edtmap_core::{Cutoff, EdtField, EdtMap, Grid3, Obstacles, FAR_DIST_SQ, NO_SITE};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Reusable buffers of the exact integration.
#[derive(Debug)]
pub struct ExactBuffers {
    mask: Grid3<bool>,
    field: EdtField,
    old: Vec<u64>,
    cur: Vec<AtomicU64>,
}

impl Default for ExactBuffers {
    fn default() -> Self {
        ExactBuffers { mask: Grid3::from_vec([1, 1, 1], vec![false]).expect("one voxel"), field: EdtField::empty(), old: Vec::new(), cur: Vec::new() }
    }
}

/// Recomputes `packing.region` of `map` exactly from `obstacles`.
pub fn integrate_exact(map: &mut EdtMap, obstacles: &Obstacles<'_>, packing: &Packing, buf: &mut ExactBuffers) -> Result<WriteBack, CpuError> {
    exact_field(obstacles, &packing.source, &mut buf.mask, &mut buf.field)?;
    copy_in(map, packing, &mut buf.old, &mut buf.cur);
    let (dist, near) = (buf.field.dist_sq_vox(), buf.field.nearest());
    let max = packing.cutoff.max_dist_sq;
    buf.cur.par_iter().enumerate().for_each(|(i, cur)| {
        let s = packing.source.linear(packing.region_in_source(packing.region.coords(i)));
        let value = if near[s] == NO_SITE || dist[s] > max { FAR } else { (u64::from(dist[s]) << 32) | u64::from(near[s]) };
        cur.store(value, Relaxed);
    });
    Ok(write_back(map, packing, &packing.region.blocks(), &buf.old, &buf.cur))
}

/// The exact EDT of the global obstacles truncated at `cutoff`, for every
/// voxel of `region`: squared distances, [`FAR_DIST_SQ`] beyond the cutoff.
pub fn exact_region(obstacles: &Obstacles<'_>, region: &Region, cutoff: Cutoff) -> Result<Vec<u32>, CpuError> {
    let packing = Packing::new(*region, cutoff)?;
    let mut mask = Grid3::from_vec([1, 1, 1], vec![false])?;
    let mut field = EdtField::empty();
    exact_field(obstacles, &packing.source, &mut mask, &mut field)?;
    let dist = field.dist_sq_vox();
    Ok((0..region.len())
        .into_par_iter()
        .map(|i| {
            let d = dist[packing.source.linear(packing.region_in_source(region.coords(i)))];
            if d > cutoff.max_dist_sq { FAR_DIST_SQ } else { d }
        })
        .collect())
}

/// The batch EDT of `source` from the global obstacles.
fn exact_field(obstacles: &Obstacles<'_>, source: &Region, mask: &mut Grid3<bool>, field: &mut EdtField) -> Result<(), CpuError> {
    fill_mask(obstacles, source, mask)?;
    edt_into(mask, |&o| o, ScanLayout::default(), field)
}

/// Fills `mask` (resized to `region`) with the obstacles of `region`.
pub fn fill_mask(obstacles: &Obstacles<'_>, region: &Region, mask: &mut Grid3<bool>) -> Result<(), CpuError> {
    let source = region;
    if mask.dims() != source.dims {
        *mask = Grid3::from_vec(source.dims, vec![false; Grid3::<bool>::voxel_count(source.dims)?])?;
    }
    let nx = source.dims[0];
    mask.as_mut_slice().par_chunks_mut(nx).enumerate().for_each(|(row, out)| {
        let (y, z) = (row % source.dims[1], row / source.dims[1]);
        obstacles.fill_row(source.world([0, y, z]), out);
    });
    Ok(())
}
