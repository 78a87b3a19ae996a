//! The whole global map: occupancy, global EDT and fixed obstacles, with
//! the parameters that say how to read them. Plain data: the backends
//! update it, the queries read it, the map file stores it.

use crate::{
    CoreError, Cutoff, EdtMap, FixedMap, GlobalParams, LogOdds, Obstacles, OccupancyMap, OccupancyParams, VoxelIndex,
    VoxelState,
};

/// The global map, as layers over one voxel grid (nvblox's layer cake):
/// log-odds occupancy, the global EDT and fixed obstacles, with the one
/// voxel size and the parameters that say how to read them. The layers are
/// reached through methods; the EDT is that of [`GlobalMap::obstacles`]
/// within the cutoff, which the pipeline keeps true.
#[derive(Debug, Clone)]
pub struct GlobalMap {
    voxel_size_m: f64,
    occupancy: OccupancyMap,
    edt: EdtMap,
    fixed: FixedMap,
    occupancy_params: OccupancyParams,
    log_odds: LogOdds,
    params: GlobalParams,
    cutoff: Cutoff,
}

impl GlobalMap {
    /// An empty map, checking every parameter; forbidden zones are laid
    /// down as fixed obstacles.
    pub fn new(voxel_size_m: f64, occupancy_params: OccupancyParams, params: GlobalParams) -> Result<Self, CoreError> {
        let mut map = Self::from_layers(
            voxel_size_m,
            occupancy_params,
            params,
            OccupancyMap::new(),
            EdtMap::new(),
            FixedMap::new(),
        )?;
        for zone in &map.params.forbidden {
            map.fixed.add_zone(zone, voxel_size_m)?;
        }
        Ok(map)
    }

    /// A map of the given layers (a map file read back, say), checking
    /// every parameter; the fixed obstacles are taken as they are
    /// (forbidden zones are not laid down again).
    pub fn from_layers(
        voxel_size_m: f64,
        occupancy_params: OccupancyParams,
        params: GlobalParams,
        occupancy: OccupancyMap,
        edt: EdtMap,
        fixed: FixedMap,
    ) -> Result<Self, CoreError> {
        crate::check_voxel_size(voxel_size_m)?;
        let log_odds = occupancy_params.log_odds()?;
        let cutoff = params.cutoff(voxel_size_m)?;
        params.check_forbidden()?;
        Ok(GlobalMap { voxel_size_m, occupancy, edt, fixed, occupancy_params, log_odds, params, cutoff })
    }

    /// The log-odds occupancy layer.
    pub fn occupancy(&self) -> &OccupancyMap {
        &self.occupancy
    }

    /// The occupancy layer, to fuse observations into.
    pub fn occupancy_mut(&mut self) -> &mut OccupancyMap {
        &mut self.occupancy
    }

    /// The global EDT layer.
    pub fn edt(&self) -> &EdtMap {
        &self.edt
    }

    /// The global EDT layer, to drop blocks from (map clearing); the
    /// integration writes it through [`Self::edt_and_obstacles`].
    pub fn edt_mut(&mut self) -> &mut EdtMap {
        &mut self.edt
    }

    /// The fixed-obstacle layer (forbidden zones, a prior map).
    pub fn fixed_obstacles(&self) -> &FixedMap {
        &self.fixed
    }

    /// The fixed-obstacle layer, to add to. The EDT does not follow by
    /// itself: the mapper lays new fixed obstacles down.
    pub fn fixed_obstacles_mut(&mut self) -> &mut FixedMap {
        &mut self.fixed
    }

    /// The probabilities behind the log-odds.
    pub fn occupancy_params(&self) -> &OccupancyParams {
        &self.occupancy_params
    }

    /// How log-odds read as states.
    pub fn log_odds(&self) -> &LogOdds {
        &self.log_odds
    }

    /// Parameters of the global EDT.
    pub fn params(&self) -> &GlobalParams {
        &self.params
    }

    /// The cutoff in voxels.
    pub fn cutoff(&self) -> Cutoff {
        self.cutoff
    }

    /// Fuses `obs` into the occupancy layer.
    pub fn fuse(&mut self, obs: &crate::Observations) -> crate::FuseReport {
        crate::fuse::fuse(&mut self.occupancy, obs, &self.log_odds)
    }

    /// The occupancy layer, mutable, beside its log-odds parameters: what a
    /// backend's fusion ([`crate::Backend::fuse`]) needs in one borrow.
    pub fn occupancy_and_log_odds(&mut self) -> (&mut OccupancyMap, &LogOdds) {
        (&mut self.occupancy, &self.log_odds)
    }

    /// Voxel edge length in metres.
    pub fn voxel_size_m(&self) -> f64 {
        self.voxel_size_m
    }

    /// The EDT's obstacle test (unknown voxels are free).
    pub fn obstacles(&self) -> Obstacles<'_> {
        Obstacles {
            occupancy: &self.occupancy,
            log_odds: &self.log_odds,
            fixed: &self.fixed,
            unknown_as_occupied: false,
        }
    }

    /// The EDT, mutable, beside the obstacle test that reads the other
    /// layers: what an integration needs in one borrow.
    pub fn edt_and_obstacles(&mut self) -> (&mut EdtMap, Obstacles<'_>) {
        let obstacles = Obstacles {
            occupancy: &self.occupancy,
            log_odds: &self.log_odds,
            fixed: &self.fixed,
            unknown_as_occupied: false,
        };
        (&mut self.edt, obstacles)
    }

    /// Occupancy state of voxel `v` as the sensors saw it.
    pub fn state(&self, v: VoxelIndex) -> VoxelState {
        self.log_odds.state(self.occupancy.log_odds(v))
    }

    /// Squared distance (voxels²) and nearest obstacle of voxel `v`.
    pub fn entry(&self, v: VoxelIndex) -> (u32, VoxelIndex) {
        self.edt.entry(v)
    }

    /// Memory held by the blocks, bytes ([`crate::BlockMap::bytes`]).
    pub fn bytes(&self) -> usize {
        self.occupancy.bytes() + self.edt.bytes() + self.fixed.bytes()
    }

    /// The lowest and highest z index of the voxels the sensors observed
    /// (free or occupied); `None` when none was.
    pub fn observed_z_range(&self) -> Option<(i32, i32)> {
        let mut range: Option<(i32, i32)> = None;
        for (key, block) in self.occupancy.iter() {
            for (offset, value) in block.log_odds.iter_stored() {
                if self.log_odds.state(value) != VoxelState::Unknown {
                    let z = key.voxel(offset).0[2];
                    range = Some(range.map_or((z, z), |(lo, hi)| (lo.min(z), hi.max(z))));
                }
            }
        }
        range
    }

    /// Whether every observed voxel lies in one z layer: the map of a
    /// planar sensor (a 2D LiDAR), whose layers above and below are never
    /// seen. `false` for a map with nothing observed.
    pub fn is_planar(&self) -> bool {
        self.observed_z_range().is_some_and(|(lo, hi)| lo == hi)
    }

    /// Exploration frontiers: observed free voxels with an unknown face
    /// neighbour, sorted. In a planar map ([`Self::is_planar`]) only the
    /// four neighbours in the plane count: the unseen layers above and
    /// below it are not where exploration goes on.
    pub fn frontiers(&self) -> Vec<VoxelIndex> {
        let faces = if self.is_planar() { &FACES[..4] } else { &FACES[..] };
        let mut out = Vec::new();
        for (key, block) in self.occupancy.iter() {
            for (offset, value) in block.log_odds.iter_stored() {
                if self.log_odds.state(value) != VoxelState::Free {
                    continue;
                }
                let v = key.voxel(offset);
                let unknown_next = faces.iter().any(|d| {
                    let n = VoxelIndex([v.0[0] + d[0], v.0[1] + d[1], v.0[2] + d[2]]);
                    self.state(n) == VoxelState::Unknown
                });
                if unknown_next {
                    out.push(v);
                }
            }
        }
        out.sort_unstable();
        out
    }
}

/// The six face neighbours, the four in the xy plane first.
const FACES: [[i32; 3]; 6] = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frontiers_are_free_voxels_beside_unknown() {
        let mut map = GlobalMap::new(0.1, OccupancyParams::default(), GlobalParams::default()).expect("defaults");
        let lo = *map.log_odds();
        // A free 3 x 1 x 1 bar next to an occupied voxel, all else unknown.
        for x in 0..3 {
            let v = VoxelIndex([x, 0, 0]);
            map.occupancy_mut().get_or_insert(v.block()).log_odds.set(v.offset_in_block(), lo.min);
        }
        let wall = VoxelIndex([3, 0, 0]);
        map.occupancy_mut().get_or_insert(wall.block()).log_odds.set(wall.offset_in_block(), lo.max);
        assert_eq!(map.frontiers(), vec![VoxelIndex([0, 0, 0]), VoxelIndex([1, 0, 0]), VoxelIndex([2, 0, 0])]);
        assert_eq!(map.state(wall), VoxelState::Occupied);
        assert!(map.obstacles().contains(wall));
    }

    #[test]
    fn frontiers_of_a_planar_map_are_in_its_plane() {
        let mut map = GlobalMap::new(0.1, OccupancyParams::default(), GlobalParams::default()).expect("defaults");
        let lo = *map.log_odds();
        // A free 5 x 5 square in layer z = 3, walled on its x = 5 side; the
        // layers above and below are unknown.
        for x in 0..6 {
            for y in 0..5 {
                let v = VoxelIndex([x, y, 3]);
                map.occupancy_mut()
                    .get_or_insert(v.block())
                    .log_odds
                    .set(v.offset_in_block(), if x == 5 { lo.max } else { lo.min });
            }
        }
        assert_eq!(map.observed_z_range(), Some((3, 3)));
        assert!(map.is_planar());
        // Free voxels at x = 0 or y = 0 or y = 4 (unknown beside them in the
        // plane); x = 4 has the wall beside it.
        let expected: Vec<VoxelIndex> = (0..5)
            .flat_map(|x| (0..5).map(move |y| VoxelIndex([x, y, 3])))
            .filter(|v| v.0[0] == 0 || v.0[1] == 0 || v.0[1] == 4)
            .collect();
        assert_eq!(map.frontiers(), expected);
        // One more observed layer makes the map 3D: every free voxel of the
        // square has unknown above or below.
        let above = VoxelIndex([9, 9, 4]);
        map.occupancy_mut().get_or_insert(above.block()).log_odds.set(above.offset_in_block(), lo.max);
        assert!(!map.is_planar());
        assert_eq!(map.frontiers().len(), 25);
    }

    #[test]
    fn forbidden_zones_are_obstacles() {
        let zone = crate::ForbiddenZone { min_m: [1.0, 1.0, 0.0], max_m: [1.2, 1.1, 0.1] };
        let params = GlobalParams { forbidden: vec![zone], ..Default::default() };
        let map = GlobalMap::new(0.1, OccupancyParams::default(), params).expect("valid");
        assert!(map.obstacles().contains(VoxelIndex([11, 10, 0])));
        assert!(!map.obstacles().contains(VoxelIndex([12, 10, 0])));
        assert_eq!(map.state(VoxelIndex([11, 10, 0])), VoxelState::Unknown, "the sensors never saw it");
    }
}
