//! The mapping pipeline of paper Fig. 1, one frame at a time.

use crate::MapError;
use edtmap_core::sensor::{Frame, Sensor};
use edtmap_core::{
    BlockKey, EdtField, EdtParams, Grid3, LocalVolume, LogOdds, OccupancyMap, OccupancyParams, VolumeParams, VoxelIndex,
    VoxelState,
};
use edtmap_cpu::edt::{edt_into, ScanLayout};
use edtmap_cpu::occupancy::{fuse, read_states, OccupancyStage, OgmOptions};
use std::time::Instant;

/// Everything a [`Mapper`] needs to know besides the sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct MapperParams {
    /// Voxel edge length, metres.
    pub voxel_size_m: f64,
    /// Size and placement of the local volume.
    pub volume: VolumeParams,
    /// Log-odds fusion.
    pub occupancy: OccupancyParams,
    /// How each frame's occupancy is built.
    pub ogm: OgmOptions,
    /// Batch EDT options.
    pub edt: EdtParams,
}

impl MapperParams {
    /// Defaults for `voxel_size_m`: GIE-mapping's 10 × 10 × 3 m volume,
    /// OctoMap's probabilities, half-voxel projection tolerances.
    pub fn for_voxel_size(voxel_size_m: f64) -> Self {
        MapperParams {
            voxel_size_m,
            volume: VolumeParams::default(),
            occupancy: OccupancyParams::default(),
            ogm: OgmOptions::for_voxel_size(voxel_size_m),
            edt: EdtParams::default(),
        }
    }
}

/// What one call of [`Mapper::integrate_frame`] did and how long it took.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameStats {
    /// Occupancy: construction, fusion and the local read-back, ms.
    pub ogm_ms: f64,
    /// Batch EDT of the local volume, ms.
    pub batch_edt_ms: f64,
    /// Whole frame, ms.
    pub total_ms: f64,
    /// Voxels that received an observation.
    pub voxels_updated: usize,
    /// Voxels whose state changed.
    pub voxels_changed: usize,
    /// Blocks holding a voxel whose state changed, sorted.
    pub changed_blocks: Vec<BlockKey>,
}

/// Builds the occupancy map and the local EDT from a stream of frames.
#[derive(Debug)]
pub struct Mapper {
    params: MapperParams,
    sensor: Sensor,
    log_odds: LogOdds,
    map: OccupancyMap,
    occupancy: OccupancyStage,
    volume: Option<LocalVolume>,
    local_states: Grid3<VoxelState>,
    local_edt: EdtField,
}

impl Mapper {
    /// A mapper for `sensor`, checking every parameter.
    pub fn new(sensor: Sensor, params: MapperParams) -> Result<Self, MapError> {
        sensor.validate()?;
        let log_odds = params.occupancy.log_odds()?;
        let map = OccupancyMap::new(params.voxel_size_m)?;
        // Fails early on a bad size rather than at the first frame.
        LocalVolume::centred(&params.volume, params.voxel_size_m, [0.0; 3])?;
        let local_states = Grid3::from_vec([1, 1, 1], vec![VoxelState::Unknown])?;
        let occupancy = OccupancyStage::default();
        Ok(Mapper { params, sensor, log_odds, map, occupancy, volume: None, local_states, local_edt: EdtField::empty() })
    }

    /// Adds one frame. A frame that does not fit the sensor, or has a bad
    /// pose, is an error and leaves the map as it was.
    pub fn integrate_frame(&mut self, frame: &Frame) -> Result<FrameStats, MapError> {
        let start = Instant::now();
        self.sensor.check(frame)?;
        let volume = LocalVolume::centred(&self.params.volume, self.params.voxel_size_m, frame.t_world_sensor.translation.vector.into())?;
        // §IV-A: occupancy of the local volume, fused into the global map.
        let obs = self.occupancy.observe(&self.sensor, frame, volume, &self.params.ogm)?;
        let fused = fuse(&mut self.map, obs, &self.log_odds);
        read_states(&self.map, &volume, &self.log_odds, &mut self.local_states)?;
        let ogm_ms = ms_since(start);
        // §IV-B, Alg. 1: exact batch EDT of the local volume.
        let edt_start = Instant::now();
        let unknown = self.params.edt.unknown_as_occupied;
        edt_into(&self.local_states, |s| s.is_obstacle(unknown), ScanLayout::default(), &mut self.local_edt)?;
        let batch_edt_ms = ms_since(edt_start);
        self.volume = Some(volume);
        Ok(FrameStats {
            ogm_ms,
            batch_edt_ms,
            total_ms: ms_since(start),
            voxels_updated: fused.voxels_updated,
            voxels_changed: fused.voxels_changed,
            changed_blocks: fused.changed_blocks,
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> &MapperParams {
        &self.params
    }

    /// The sensor frames are checked against.
    pub fn sensor(&self) -> &Sensor {
        &self.sensor
    }

    /// The global occupancy map.
    pub fn map(&self) -> &OccupancyMap {
        &self.map
    }

    /// The state of world voxel `v`.
    pub fn state(&self, v: VoxelIndex) -> VoxelState {
        self.log_odds.state(self.map.log_odds(v))
    }

    /// The latest local volume, once a frame has been integrated.
    pub fn local_volume(&self) -> Option<&LocalVolume> {
        self.volume.as_ref()
    }

    /// States of the latest local volume (x fastest).
    pub fn local_states(&self) -> &Grid3<VoxelState> {
        &self.local_states
    }

    /// Exact EDT of the latest local volume, in its voxel units.
    pub fn local_edt(&self) -> &EdtField {
        &self.local_edt
    }
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
