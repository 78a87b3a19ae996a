//! Exact integration, host side: a frame changes occupancy only inside its
//! window `W`, so only voxels within the cutoff of `W` can change their
//! truncated distance, and their obstacles lie within the cutoff of those
//! voxels. One exact batch EDT of `W` grown twice by the reach, from the
//! global obstacles, therefore gives every voxel of `W` grown once its
//! exact new value; they are written back where they changed. The batch
//! EDT is the backend's; the rest is shared.

use crate::region::{copy_in, fill_mask, write_back, Packing, Region, WriteBack, FAR};
use crate::{BackendError, BatchEdt, Cutoff, EdtField, EdtMap, Grid3, Obstacles, FAR_DIST_SQ, NO_SITE};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Reusable buffers of the exact integration.
#[derive(Debug, Default)]
pub struct ExactBuffers {
    mask: Grid3<bool>,
    field: EdtField,
    old: Vec<u64>,
    cur: Vec<AtomicU64>,
}

/// Recomputes `packing.region` of `map` exactly from `obstacles`, with the
/// batch EDT of `edt` (of one layer on a planar map: the region must be
/// one layer thick there, as the integration stage's tiles are).
pub fn recompute_exact<E: BatchEdt + ?Sized>(
    edt: &mut E,
    map: &mut EdtMap,
    obstacles: &Obstacles<'_>,
    packing: &Packing,
    buf: &mut ExactBuffers,
) -> Result<WriteBack, BackendError> {
    if packing.cutoff.planar && packing.region.dims[2] > 1 {
        let what = format!("a planar map's recomputation over {} layers at once", packing.region.dims[2]);
        return Err(crate::CoreError::Unsupported(what).into());
    }
    fill_mask(obstacles, &packing.source, &mut buf.mask)?;
    edt.batch_edt(&buf.mask, &mut buf.field)?;
    copy_in(map, packing, &mut buf.old, &mut buf.cur);
    let (dist, near) = (buf.field.dist_sq_vox(), buf.field.nearest());
    let max = packing.cutoff.max_dist_sq;
    buf.cur.par_iter().enumerate().for_each(|(i, cur)| {
        let s = packing.source.linear(packing.region_in_source(packing.region.coords(i)));
        let value =
            if near[s] == NO_SITE || dist[s] > max { FAR } else { (u64::from(dist[s]) << 32) | u64::from(near[s]) };
        cur.store(value, Relaxed);
    });
    Ok(write_back(map, packing, &packing.region.blocks(), &buf.old, &buf.cur))
}

/// The exact EDT of the global obstacles truncated at `cutoff`, for every
/// voxel of `region`: squared distances, [`FAR_DIST_SQ`] beyond the cutoff
/// (the ground truth of the evaluation), with the batch EDT of `edt`; on a
/// planar map, a batch EDT of each layer.
pub fn exact_region<E: BatchEdt + ?Sized>(
    edt: &mut E,
    obstacles: &Obstacles<'_>,
    region: &Region,
    cutoff: Cutoff,
) -> Result<Vec<u32>, BackendError> {
    if cutoff.planar && region.dims[2] > 1 {
        let mut out = Vec::with_capacity(region.len());
        for z in 0..region.dims[2] {
            let layer = Region {
                origin: [region.origin[0], region.origin[1], region.origin[2] + z as i32],
                dims: [region.dims[0], region.dims[1], 1],
            };
            out.extend(exact_region(edt, obstacles, &layer, cutoff)?);
        }
        return Ok(out);
    }
    let packing = Packing::new(*region, cutoff)?;
    let mut mask = Grid3::default();
    let mut field = EdtField::empty();
    fill_mask(obstacles, &packing.source, &mut mask)?;
    edt.batch_edt(&mask, &mut field)?;
    let dist = field.dist_sq_vox();
    Ok((0..region.len())
        .into_par_iter()
        .map(|i| {
            let d = dist[packing.source.linear(packing.region_in_source(region.coords(i)))];
            if d > cutoff.max_dist_sq {
                FAR_DIST_SQ
            } else {
                d
            }
        })
        .collect())
}
