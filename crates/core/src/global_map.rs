//! The whole global map: occupancy, global EDT and fixed obstacles, with
//! the parameters that say how to read them. Plain data: the backends
//! update it, the queries read it, the map file stores it.

use crate::{
    BlockMap, CoreError, Cutoff, EdtMap, GlobalParams, LogOdds, Obstacles, OccupancyMap, OccupancyParams, StaticMap,
    VoxelIndex, VoxelState,
};

/// The global map. Its fields are public so a backend can update the
/// occupancy and the EDT in one borrow; keep them consistent (the EDT is
/// that of [`GlobalMap::obstacles`] within the cutoff).
#[derive(Debug, Clone)]
pub struct GlobalMap {
    /// Log-odds occupancy.
    pub occupancy: OccupancyMap,
    /// The global EDT.
    pub edt: EdtMap,
    /// Fixed obstacles: forbidden zones, a prior map.
    pub fixed: StaticMap,
    /// The probabilities behind `log_odds`.
    pub occupancy_params: OccupancyParams,
    /// How log-odds read as states.
    pub log_odds: LogOdds,
    /// Parameters of the global EDT.
    pub params: GlobalParams,
    /// The cutoff in voxels.
    pub cutoff: Cutoff,
}

impl GlobalMap {
    /// An empty map, checking every parameter; forbidden zones are laid
    /// down as fixed obstacles.
    pub fn new(voxel_size_m: f64, occupancy_params: OccupancyParams, params: GlobalParams) -> Result<Self, CoreError> {
        crate::check_voxel_size(voxel_size_m)?;
        let log_odds = occupancy_params.log_odds()?;
        let cutoff = params.cutoff(voxel_size_m)?;
        params.check_forbidden()?;
        let mut fixed = StaticMap::new(voxel_size_m)?;
        for zone in &params.forbidden {
            fixed.add_zone(zone)?;
        }
        Ok(GlobalMap {
            occupancy: OccupancyMap::new(voxel_size_m)?,
            edt: EdtMap::new(voxel_size_m)?,
            fixed,
            occupancy_params,
            log_odds,
            params,
            cutoff,
        })
    }

    /// Voxel edge length in metres.
    pub fn voxel_size_m(&self) -> f64 {
        self.occupancy.voxel_size_m()
    }

    /// The EDT's obstacle test (unknown voxels are free).
    pub fn obstacles(&self) -> Obstacles<'_> {
        Obstacles { occupancy: &self.occupancy, log_odds: &self.log_odds, fixed: &self.fixed, unknown_as_occupied: false }
    }

    /// The EDT, mutable, beside the obstacle test that reads the other
    /// layers: what an integration needs in one borrow.
    pub fn edt_and_obstacles(&mut self) -> (&mut EdtMap, Obstacles<'_>) {
        let obstacles = Obstacles { occupancy: &self.occupancy, log_odds: &self.log_odds, fixed: &self.fixed, unknown_as_occupied: false };
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

    /// Memory held by the blocks, bytes (payloads plus key and pointer).
    pub fn bytes(&self) -> usize {
        fn layer<B: Default>(m: &BlockMap<B>) -> usize {
            m.len() * (std::mem::size_of::<B>() + 3 * 4 + std::mem::size_of::<usize>())
        }
        layer(&self.occupancy) + layer(&self.edt) + layer(&self.fixed)
    }

    /// Exploration frontiers: observed free voxels with an unknown face
    /// neighbour, sorted.
    pub fn frontiers(&self) -> Vec<VoxelIndex> {
        let mut out = Vec::new();
        for (key, block) in self.occupancy.iter() {
            for (offset, &value) in block.log_odds.iter().enumerate() {
                if self.log_odds.state(value) != VoxelState::Free {
                    continue;
                }
                let v = key.voxel(offset);
                let unknown_next = FACES.iter().any(|d| {
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

const FACES: [[i32; 3]; 6] = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frontiers_are_free_voxels_beside_unknown() {
        let mut map = GlobalMap::new(0.1, OccupancyParams::default(), GlobalParams::default()).expect("defaults");
        let lo = map.log_odds;
        // A free 3 x 1 x 1 bar next to an occupied voxel, all else unknown.
        for x in 0..3 {
            let v = VoxelIndex([x, 0, 0]);
            map.occupancy.get_or_insert(v.block()).log_odds[v.offset_in_block()] = lo.min;
        }
        let wall = VoxelIndex([3, 0, 0]);
        map.occupancy.get_or_insert(wall.block()).log_odds[wall.offset_in_block()] = lo.max;
        assert_eq!(map.frontiers(), vec![VoxelIndex([0, 0, 0]), VoxelIndex([1, 0, 0]), VoxelIndex([2, 0, 0])]);
        assert_eq!(map.state(wall), VoxelState::Occupied);
        assert!(map.obstacles().contains(wall));
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
