//! Top views of the whole global map: what a mapped building looks like
//! from above, over every block the map holds.
//!
//! A [`TopView`] summarises the z layers from `lo` to `hi` (one layer for
//! a view at a height, many for a projection through the height) in each
//! column of the map, as the sensors saw it:
//!
//! * **state**: occupied if any voxel of the column is occupied, else free
//!   if any is free, else unknown. A ground robot may drive through a
//!   column only if it is free at every height its body takes, so an
//!   obstacle anywhere in the band blocks the column, as in the obstacle
//!   layer of ROS's 2D costmap (between `min_obstacle_height` and
//!   `max_obstacle_height`) or octomap_server's projected map.
//! * **distance**: the least distance (metres, the global EDT, unknown
//!   voxels counted free) over the column's observed voxels: the clearance
//!   of a body spanning the band; 0 where the column holds an obstacle,
//!   none (drawn grey) where nothing was observed.
//!
//! A map wider than [`MAX_TOP_VIEW_CELLS`] voxels on either side is drawn
//! with each cell covering `k × k` columns, `k` the smallest integer that
//! fits it, summarised by the same rule (the most occupied state, the
//! least distance): a coarse view stays conservative for planning, and the
//! picture's memory stays bounded (about 5 bytes a cell, 2048² cells at
//! most) whatever the map's size.

use std::path::Path;

use edtmap_core::{GlobalMap, VoxelIndex, VoxelState, BLOCK_SIDE, FAR_DIST_SQ};

use crate::picture::{render_slice, render_states, Canvas, MapAxes, Slice, SliceStyle};
use crate::VizError;

/// Most cells along either side of a top view.
pub const MAX_TOP_VIEW_CELLS: usize = 2048;

/// Column summaries of some z layers of a map over its mapped box (see
/// the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct TopView {
    /// World x and y voxel index of the lowest corner voxel of cell (0, 0).
    origin: [i64; 2],
    /// Voxels along each side of a cell.
    cell_voxels: i64,
    width: usize,
    height: usize,
    voxel_size_m: f64,
    layers: (i32, i32),
    states: Vec<VoxelState>,
    distance_m: Vec<f32>,
}

impl TopView {
    /// The view of layers `lo..=hi` (z voxel indices) of `map` over its
    /// mapped box (every allocated occupancy block); `None` for a map
    /// without blocks or an empty range.
    pub fn new(map: &GlobalMap, (lo, hi): (i32, i32)) -> Option<TopView> {
        let (key_lo, key_hi) = map.occupancy().key_bounds()?;
        if lo > hi {
            return None;
        }
        let side = i64::from(BLOCK_SIDE);
        let origin = [0, 1].map(|a| i64::from(key_lo[a]) * side);
        let voxels = [0, 1].map(|a| (i64::from(key_hi[a]) - i64::from(key_lo[a]) + 1) * side);
        let max_cells = MAX_TOP_VIEW_CELLS as i64;
        let cell_voxels = ((voxels[0].max(voxels[1]) + max_cells - 1) / max_cells).max(1);
        let [width, height] = voxels.map(|n| ((n + cell_voxels - 1) / cell_voxels) as usize);
        let mut view = TopView {
            origin,
            cell_voxels,
            width,
            height,
            voxel_size_m: map.voxel_size_m(),
            layers: (lo, hi),
            states: vec![VoxelState::Unknown; width * height],
            distance_m: vec![f32::NAN; width * height],
        };
        view.fill(map);
        Some(view)
    }

    /// Folds every observed voxel of the layers into its cell.
    fn fill(&mut self, map: &GlobalMap) {
        let (lo, hi) = self.layers;
        let side = BLOCK_SIDE;
        for (key, block) in map.occupancy().iter() {
            let z0 = key.0[2].saturating_mul(side);
            if z0 > hi || z0.saturating_add(side - 1) < lo {
                continue;
            }
            for (offset, value) in block.log_odds.iter_stored() {
                let state = map.log_odds().state(value);
                let v = key.voxel(offset);
                if state == VoxelState::Unknown || !(lo..=hi).contains(&v.0[2]) {
                    continue;
                }
                let Some(i) = self.cell_index(v) else { continue };
                if state as u8 > self.states[i] as u8 {
                    self.states[i] = state;
                }
                // An occupied voxel is its own nearest obstacle.
                let d = if state == VoxelState::Occupied { 0.0 } else { voxel_distance_m(map, v) };
                // NaN (nothing observed yet) gives way to any distance.
                self.distance_m[i] = if self.distance_m[i].is_nan() { d } else { self.distance_m[i].min(d) };
            }
        }
    }

    /// Linear index of the cell holding the column of voxel `v`.
    fn cell_index(&self, v: VoxelIndex) -> Option<usize> {
        let (x, y) = self.cell_of(v)?;
        Some(y * self.width + x)
    }

    /// The cell (x right, y up) holding the column of voxel `v`, if any.
    pub fn cell_of(&self, v: VoxelIndex) -> Option<(usize, usize)> {
        let [x, y] = [0, 1].map(|a| (i64::from(v.0[a]) - self.origin[a]).div_euclid(self.cell_voxels));
        let inside = (0..self.width as i64).contains(&x) && (0..self.height as i64).contains(&y);
        inside.then_some((x as usize, y as usize))
    }

    /// Cells along x and y.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Voxels along each side of a cell (1 unless the map is wider than
    /// [`MAX_TOP_VIEW_CELLS`] voxels).
    pub fn cell_voxels(&self) -> usize {
        self.cell_voxels as usize
    }

    /// The summarised state of cell `(x, y)` (row `y` upwards).
    pub fn state(&self, x: usize, y: usize) -> Option<VoxelState> {
        (x < self.width && y < self.height).then(|| self.states[y * self.width + x])
    }

    /// The least distance, metres, over the observed voxels of cell
    /// `(x, y)`; NaN where none was observed.
    pub fn distance_m(&self, x: usize, y: usize) -> Option<f32> {
        (x < self.width && y < self.height).then(|| self.distance_m[y * self.width + x])
    }

    /// Axes in metres with `position` and, for coarse cells, their size.
    fn axes(&self, position: &str) -> MapAxes {
        let cell_m = self.cell_voxels as f64 * self.voxel_size_m;
        let position =
            if self.cell_voxels > 1 { format!("{position}; cell {cell_m:.2} m") } else { position.to_string() };
        MapAxes { origin_m: self.origin.map(|o| o as f64 * self.voxel_size_m), cell_m, position }
    }

    /// The states, unknown grey, free white, occupied black.
    pub fn render_states(&self, title: &str, position: &str) -> Canvas {
        render_states(self.width, self.height, &self.states, title, Some(&self.axes(position)))
    }

    /// The distances in viridis from 0 to `max_m`, obstacles black, cells
    /// without an observed voxel grey.
    pub fn render_distance(&self, title: &str, position: &str, max_m: f32) -> Canvas {
        let style = SliceStyle {
            title: title.into(),
            unit: "m".into(),
            max_value: Some(max_m),
            axes: Some(self.axes(position)),
        };
        render_slice(Slice { width: self.width, height: self.height, values: &self.distance_m }, &style)
    }

    /// [`Self::render_states`], written as a PNG.
    pub fn write_states_png(&self, path: &Path, title: &str, position: &str) -> Result<(), VizError> {
        self.render_states(title, position).save_png(path)
    }

    /// [`Self::render_distance`], written as a PNG.
    pub fn write_distance_png(&self, path: &Path, title: &str, position: &str, max_m: f32) -> Result<(), VizError> {
        self.render_distance(title, position, max_m).save_png(path)
    }
}

/// Distance of voxel `v`'s centre, metres: the cutoff where none is within it.
fn voxel_distance_m(map: &GlobalMap, v: VoxelIndex) -> f32 {
    match map.entry(v).0 {
        FAR_DIST_SQ => map.params().max_distance_m as f32,
        d => (f64::from(d).sqrt() * map.voxel_size_m()) as f32,
    }
}

/// The z layer of `map` with the most observed voxels (the lowest on a
/// tie), `None` when nothing is observed: where a top view at a height
/// shows most.
pub fn densest_layer(map: &GlobalMap) -> Option<i32> {
    let mut counts = std::collections::BTreeMap::<i32, usize>::new();
    for (key, block) in map.occupancy().iter() {
        for (offset, value) in block.log_odds.iter_stored() {
            if map.log_odds().state(value) != VoxelState::Unknown {
                *counts.entry(key.voxel(offset).0[2]).or_default() += 1;
            }
        }
    }
    counts
        .into_iter()
        .fold(None, |best: Option<(i32, usize)>, (z, n)| match best {
            Some((_, m)) if m >= n => best,
            _ => Some((z, n)),
        })
        .map(|(z, _)| z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::picture::{MapLayout, STATE_RGB};
    use edtmap_core::{GlobalParams, OccupancyParams};

    /// A map of 0.1 m voxels with the given voxels set free or occupied.
    fn map_with(free: &[[i32; 3]], occupied: &[[i32; 3]]) -> GlobalMap {
        let mut map = GlobalMap::new(0.1, OccupancyParams::default(), GlobalParams::default()).expect("defaults");
        let lo = *map.log_odds();
        for (voxels, value) in [(free, lo.min), (occupied, lo.max)] {
            for &v in voxels {
                let v = VoxelIndex(v);
                map.occupancy_mut().get_or_insert(v.block()).log_odds.set(v.offset_in_block(), value);
            }
        }
        map
    }

    /// Free 8 x 8 squares in layers 2 and 5 of block (0, 0, 0) with an
    /// obstacle at (3, 3, 2) and one at (6, 6, 5); an unobserved block at
    /// x = 16..24; the layers between unknown.
    fn building() -> GlobalMap {
        let mut free = Vec::new();
        for z in [2, 5] {
            free.extend(
                (0..8).flat_map(|x| (0..8).map(move |y| [x, y, z])).filter(|&v| v != [3, 3, 2] && v != [6, 6, 5]),
            );
        }
        let mut map = map_with(&free, &[[3, 3, 2], [6, 6, 5]]);
        map.occupancy_mut().get_or_insert(VoxelIndex([16, 0, 0]).block());
        map
    }

    #[test]
    fn a_view_at_a_height_is_the_layer_s_states() {
        let map = building();
        let view = TopView::new(&map, (2, 2)).expect("a view");
        assert_eq!((view.size(), view.cell_voxels()), ((24, 8), 1));
        for y in 0..8 {
            for x in 0..24 {
                let v = VoxelIndex([x, y, 2]);
                assert_eq!(view.cell_of(v), Some((x as usize, y as usize)));
                assert_eq!(view.state(x as usize, y as usize), Some(map.state(v)), "{v:?}");
            }
        }
        assert_eq!(view.state(3, 3), Some(VoxelState::Occupied));
        assert_eq!(view.state(6, 6), Some(VoxelState::Free), "the obstacle at z = 5 is not in layer 2");
        // Distances: 0 on the obstacle, the map's own elsewhere (the
        // cutoff: this map has no EDT), none where unknown.
        assert_eq!(view.distance_m(3, 3), Some(0.0));
        assert_eq!(view.distance_m(0, 0), Some(voxel_distance_m(&map, VoxelIndex([0, 0, 2]))));
        assert!(view.distance_m(20, 4).is_some_and(f32::is_nan));

        // The picture: each cell in its state's colour where the layout
        // puts it, y upwards.
        let canvas = view.render_states("t", "z = 0.25 m");
        let layout = MapLayout::new(24, 8, Some(&view.axes("z = 0.25 m")));
        let colour = |x, y| {
            let (px, py) = layout.cell(x, y, 8);
            canvas.pixel(px + layout.scale / 2, py + layout.scale / 2)
        };
        assert_eq!(colour(3, 3), Some(STATE_RGB[VoxelState::Occupied as usize]));
        assert_eq!(colour(3, 4), Some(STATE_RGB[VoxelState::Free as usize]));
        assert_eq!(colour(20, 3), Some(STATE_RGB[VoxelState::Unknown as usize]));
        let distances = view.render_distance("t", "z = 0.25 m", 2.0);
        let (px, py) = layout.cell(3, 3, 8);
        assert_eq!(distances.pixel(px + layout.scale / 2, py + layout.scale / 2), Some(crate::picture::OBSTACLE_RGB));
    }

    #[test]
    fn a_projection_blocks_a_column_with_an_obstacle_at_any_height() {
        let map = building();
        let view = TopView::new(&map, (0, 7)).expect("a view");
        let rank = |s: VoxelState| s as u8;
        for y in 0..8 {
            for x in 0..24 {
                let column = (0..8).map(|z| map.state(VoxelIndex([x, y, z]))).max_by_key(|s| rank(*s)).expect("layers");
                assert_eq!(view.state(x as usize, y as usize), Some(column), "column ({x}, {y})");
            }
        }
        assert_eq!((view.state(3, 3), view.state(6, 6)), (Some(VoxelState::Occupied), Some(VoxelState::Occupied)));
        assert_eq!(view.distance_m(6, 6), Some(0.0));
        // Layers 3 and 4 alone were never observed.
        let between = TopView::new(&map, (3, 4)).expect("a view");
        assert!((0..8).all(|x| between.state(x, 0) == Some(VoxelState::Unknown)));
        assert!(TopView::new(&map, (4, 3)).is_none());
    }

    #[test]
    fn a_wide_map_is_drawn_in_coarse_cells_that_keep_its_obstacles() {
        // Two blocks 100 000 voxels apart: 100 008 voxels along x.
        let map = map_with(&[[0, 0, 0], [100_002, 5, 0]], &[[100_003, 5, 0]]);
        let view = TopView::new(&map, (0, 0)).expect("a view");
        let k = 100_008_usize.div_ceil(MAX_TOP_VIEW_CELLS);
        assert_eq!((view.cell_voxels(), view.size()), (k, (100_008_usize.div_ceil(k), 1)));
        assert!(view.size().0 <= MAX_TOP_VIEW_CELLS);
        // The free and the occupied voxel share a cell: it is occupied.
        let (x, y) = view.cell_of(VoxelIndex([100_003, 5, 0])).expect("inside");
        assert_eq!(view.cell_of(VoxelIndex([100_002, 5, 0])), Some((x, y)));
        assert_eq!(view.state(x, y), Some(VoxelState::Occupied));
        assert_eq!(view.state(0, 0), Some(VoxelState::Free));
        assert!(view.axes("z").position.contains("cell 4.90 m"));
    }

    #[test]
    fn densest_layer_counts_observed_voxels() {
        assert_eq!(densest_layer(&building()), Some(2), "layers 2 and 5 tie at 64: the lower");
        assert_eq!(densest_layer(&map_with(&[[0, 0, 1], [1, 0, 1], [0, 0, 7]], &[])), Some(1));
        assert_eq!(densest_layer(&map_with(&[], &[])), None);
    }
}
