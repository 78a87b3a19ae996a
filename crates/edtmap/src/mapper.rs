//! The mapping pipeline of paper Fig. 1, one frame at a time.

use crate::stages::{fuse_on, local_field, OccupancyStage, OgmOptions};
use crate::update::{ms_since, GlobalUpdate};
use crate::MapError;
use edtmap_core::query::{self, Distance, PointState};
use edtmap_core::sensor::{Frame, Sensor};
use edtmap_core::{
    read_states, Backend, BlockKey, EdtField, EdtParams, ExactCounts, GlobalMap, GlobalParams, Grid3, LocalVolume,
    OccupancyParams, Region, VolumeParams, VoxelIndex, VoxelState, WaveCounts,
};
use edtmap_cpu::CpuBackend;
use std::sync::OnceLock;
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
    /// Global EDT: cutoff, connectivity, mode, forbidden zones.
    pub global: GlobalParams,
    /// Most memory one frame may need, bytes; `None`: what the system has
    /// (available memory and the address-space limit). A window that needs
    /// more is refused when the mapper is made.
    pub max_memory_bytes: Option<u64>,
}

impl MapperParams {
    /// Defaults for `voxel_size_m`: GIE-mapping's 10 × 10 × 3 m volume,
    /// OctoMap's probabilities, half-voxel projection tolerances.
    pub fn for_voxel_size(voxel_size_m: f64) -> Self {
        MapperParams {
            voxel_size_m,
            volume: VolumeParams::default(),
            occupancy: OccupancyParams::default(),
            ogm: OgmOptions::default(),
            edt: EdtParams::default(),
            global: GlobalParams::default(),
            max_memory_bytes: None,
        }
    }
}

/// One of a mapper's sensors: its name, its model, and how its frames
/// become occupancy.
#[derive(Debug, Clone, PartialEq)]
pub struct MapperSensor {
    /// The name frames and reports know it by: a config's `[[sensors]]
    /// name`, or the kind's name (`depth`, `lidar`, ...) for a mapper made
    /// with one sensor.
    pub name: String,
    /// The model its frames are checked against and read with.
    pub sensor: Sensor,
    /// How its frames become occupancy.
    pub ogm: OgmOptions,
}

impl MapperSensor {
    /// Checks the model, the occupancy options and that projection, if
    /// asked for, can read this sensor's frames.
    fn validate(&self) -> Result<(), MapError> {
        let in_sensor = |source| MapError::Config { section: "sensor", source };
        if self.name.is_empty() || self.name.len() > 64 || self.name.chars().any(|c| c.is_control()) {
            return Err(in_sensor(edtmap_core::CoreError::InvalidParam {
                field: "name",
                value: format!("{:?}", self.name),
                reason: "a sensor's name must be 1 to 64 printable characters",
            }));
        }
        self.sensor.validate().map_err(in_sensor)?;
        crate::config::check_ogm(&self.ogm).map_err(in_sensor)?;
        crate::config::check_construction(&self.sensor, self.ogm.construction).map_err(in_sensor)
    }
}

/// What one call of [`Mapper::integrate_frame`] did and how long it took.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameStats {
    /// The sensor the frame came from: its index in [`Mapper::sensors`].
    pub sensor: usize,
    /// Occupancy: construction, fusion and the local read-back, ms.
    pub ogm_ms: f64,
    /// Batch EDT of the local volume, ms (wavefront mode; the exact mode
    /// computes it only when [`Mapper::local_edt`] asks).
    pub batch_edt_ms: f64,
    /// Integration into the global EDT, ms.
    pub integrate_ms: f64,
    /// Whole frame, ms.
    pub total_ms: f64,
    /// Voxels that received an observation.
    pub voxels_updated: usize,
    /// Voxels whose state changed.
    pub voxels_changed: usize,
    /// Blocks holding a voxel whose state changed, sorted.
    pub changed_blocks: Vec<BlockKey>,
    /// Blocks in which some voxel's log-odds changed.
    pub occupancy_rewritten_blocks: usize,
    /// Global EDT voxels whose distance or nearest obstacle changed.
    pub edt_voxels_changed: usize,
    /// Global EDT blocks holding such a voxel.
    pub edt_changed_blocks: usize,
    /// The paper's change score V (eq. 6): the mean over the mapped voxels
    /// of |Δ distance|, metres, distances truncated at the cutoff.
    pub change_score_m: f64,
    /// Voxels of the region the integration worked on.
    pub integrate_region_voxels: usize,
    /// Wavefront counters (frontiers A, B, C, levels).
    pub waves: WaveCounts,
    /// Exact mode's counters (obstacles added and removed; per pass,
    /// entries changed, changed at the same distance, rescanned, read).
    pub exact: ExactCounts,
    /// Blocks of the global map: occupancy, EDT and fixed obstacles.
    pub map_blocks: usize,
    /// Memory those blocks hold, bytes.
    pub map_bytes: usize,
}

/// What [`Mapper::clear_far`] dropped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Cleared {
    /// Occupancy blocks dropped.
    pub occupancy_blocks: usize,
    /// EDT blocks dropped.
    pub edt_blocks: usize,
    /// Memory the map held before, bytes.
    pub bytes_before: usize,
    /// Memory the map holds now, bytes.
    pub bytes_after: usize,
}

/// Builds the occupancy map and the local EDT from a stream of frames, on
/// backend `B` (the CPU by default; `edtmap_gpu::GpuBackend` for a GPU).
/// Every backend gives the same map, bit for bit.
///
/// Each frame runs the stages of [`crate::stages`] in turn: occupancy
/// (fused into the map), then the global EDT. In the exact mode (the
/// default) the global EDT is brought up to date from the obstacles the
/// frame changed, and the local volume's batch EDT is computed only when
/// [`Mapper::local_edt`] asks for it; in the wavefront mode (the paper's)
/// the batch EDT of the local volume runs every frame and is merged into
/// the global EDT. **When the backend fails** at the EDT
/// stages (a lost GPU) after the frame's occupancy was fused, the mapper
/// finishes them on a CPU backend it keeps for the purpose, so the map is
/// never half-updated, and returns the backend's error for the caller to
/// act on (switch backends, stop). That is the only fallback; backends
/// keep their own caches coherent (see `edtmap_core::Backend`).
#[derive(Debug)]
pub struct Mapper<B: Backend = CpuBackend> {
    backend: B,
    /// Finishes a frame the backend failed (made at the first failure).
    fallback: Option<CpuBackend>,
    params: MapperParams,
    /// The sensors frames come from, the first made with the mapper.
    sensors: Vec<MapperSensor>,
    map: GlobalMap,
    occupancy: OccupancyStage,
    /// The global EDT's update: exact, or the paper's wavefronts.
    global: GlobalUpdate,
    volume: Option<LocalVolume>,
    local_states: OnceLock<Grid3<VoxelState>>,
    /// Exact mode, or wavefront mode on a device: the local volume's batch
    /// EDT, once asked for.
    local: OnceLock<EdtField>,
}

impl Mapper<CpuBackend> {
    /// A mapper for `sensor` on the CPU, checking every parameter.
    pub fn new(sensor: Sensor, params: MapperParams) -> Result<Self, MapError> {
        Self::new_on(CpuBackend::default(), sensor, params)
    }

    /// A mapper on the CPU that goes on from `map` (a loaded map file,
    /// say); see [`Mapper::with_map_on`].
    pub fn with_map(sensor: Sensor, params: MapperParams, map: GlobalMap) -> Result<Self, MapError> {
        Self::with_map_on(CpuBackend::default(), sensor, params, map)
    }
}

impl<B: Backend> Mapper<B> {
    /// A mapper for `sensor` on `backend`, checking every parameter.
    pub fn new_on(backend: B, sensor: Sensor, params: MapperParams) -> Result<Self, MapError> {
        sensor.validate()?;
        params.validate()?;
        let map = GlobalMap::new(params.voxel_size_m, params.occupancy.clone(), params.global.clone())?;
        Self::with_map_on(backend, sensor, params, map)
    }

    /// A mapper on `backend` that goes on from `map` (a loaded map file,
    /// say); the map's voxel size, probabilities and global parameters
    /// replace those of `params`.
    pub fn with_map_on(
        mut backend: B,
        sensor: Sensor,
        mut params: MapperParams,
        map: GlobalMap,
    ) -> Result<Self, MapError> {
        sensor.validate()?;
        // A device fuses the observations it makes where it made them.
        backend.set_deferred_observations(true);
        params.voxel_size_m = map.voxel_size_m();
        params.occupancy = map.occupancy_params().clone();
        params.global = map.params().clone();
        params.validate()?;
        if params.global.planar && !backend.integrates_planar() {
            let what = format!("a planar map ([global] planar = true) on the {} backend; use the CPU", backend.name());
            return Err(edtmap_core::CoreError::Unsupported(what).into());
        }
        // Fails early on a bad size, or one past the memory budget, rather
        // than at the first frame.
        crate::budget::check(&params)?;
        let global = GlobalUpdate::new(&params.global, params.voxel_size_m, params.edt.unknown_as_occupied)?;
        let first = MapperSensor { name: sensor.name().into(), sensor, ogm: params.ogm };
        let mut mapper = Mapper {
            backend,
            fallback: None,
            sensors: vec![first],
            map,
            occupancy: OccupancyStage::default(),
            global,
            volume: None,
            local_states: OnceLock::new(),
            local: OnceLock::new(),
            params,
        };
        mapper.lay_down_fixed()?;
        Ok(mapper)
    }

    /// Brings the fixed obstacles (forbidden zones, priors) into the global
    /// EDT at once, rather than when a window first passes over them.
    fn lay_down_fixed(&mut self) -> Result<(), MapError> {
        let Some(keys) = self.map.fixed_obstacles().key_bounds() else { return Ok(()) };
        self.global.recompute(&mut self.backend, &mut self.map, &Region::of_blocks(keys))?;
        Ok(())
    }

    /// Adds a sensor whose frames [`Self::integrate_sensor_frame`] takes,
    /// fused into the same map; returns its index. Its name must differ
    /// from the others'.
    pub fn add_sensor(&mut self, sensor: MapperSensor) -> Result<usize, MapError> {
        self.check_new_sensor(&sensor, None)?;
        self.sensors.push(sensor);
        Ok(self.sensors.len() - 1)
    }

    /// Checks `sensor`, and that no sensor but `replacing` has its name.
    fn check_new_sensor(&self, sensor: &MapperSensor, replacing: Option<usize>) -> Result<(), MapError> {
        sensor.validate()?;
        if self.sensors.iter().enumerate().any(|(i, s)| Some(i) != replacing && s.name == sensor.name) {
            return Err(MapError::Config {
                section: "sensor",
                source: edtmap_core::CoreError::InvalidParam {
                    field: "name",
                    value: format!("{:?}", sensor.name),
                    reason: "another sensor of this mapper has that name",
                },
            });
        }
        Ok(())
    }

    /// Renames sensor `index` (the first sensor is named after its kind
    /// until renamed).
    pub fn rename_sensor(&mut self, index: usize, name: &str) -> Result<(), MapError> {
        let Some(s) = self.sensors.get(index) else { return Err(no_sensor(index, self.sensors.len())) };
        let renamed = MapperSensor { name: name.into(), ..s.clone() };
        self.check_new_sensor(&renamed, Some(index))?;
        self.sensors[index] = renamed;
        Ok(())
    }

    /// Replaces sensor `index`'s model and options (a camera's intrinsics
    /// learnt from its camera info), keeping its name; the map is kept, and
    /// frames integrated so far stay as they were mapped.
    pub fn replace_sensor(&mut self, index: usize, sensor: MapperSensor) -> Result<(), MapError> {
        let Some(s) = self.sensors.get(index) else { return Err(no_sensor(index, self.sensors.len())) };
        let replaced = MapperSensor { name: s.name.clone(), ..sensor };
        self.check_new_sensor(&replaced, Some(index))?;
        self.sensors[index] = replaced;
        Ok(())
    }

    /// The sensors, in the order they were added.
    pub fn sensors(&self) -> &[MapperSensor] {
        &self.sensors
    }

    /// Adds one frame of the first sensor ([`Self::integrate_sensor_frame`]).
    pub fn integrate_frame(&mut self, frame: &Frame) -> Result<FrameStats, MapError> {
        self.integrate_sensor_frame(0, frame)
    }

    /// Adds one frame of sensor `index` (see [`Self::sensors`]): its
    /// occupancy fused into the one map, then the global EDT brought up to
    /// date, as for a mapper with that sensor alone. A frame that does not
    /// fit the sensor, or has a bad pose, is an error and leaves the map as
    /// it was.
    pub fn integrate_sensor_frame(&mut self, index: usize, frame: &Frame) -> Result<FrameStats, MapError> {
        let start = Instant::now();
        let Some(entry) = self.sensors.get(index) else { return Err(no_sensor(index, self.sensors.len())) };
        entry.sensor.check(frame)?;
        let volume = LocalVolume::centred(
            &self.params.volume,
            self.params.voxel_size_m,
            frame.t_world_sensor.translation.vector.into(),
        )?;
        // §IV-A: occupancy of the local volume, fused into the global map.
        let obs = self.occupancy.observe(&mut self.backend, &entry.sensor, frame, volume, &entry.ogm)?;
        let fused = fuse_on(&mut self.backend, &mut self.map, obs)?;
        let ogm_ms = ms_since(start);
        self.local = OnceLock::new();
        self.local_states = OnceLock::new();
        // §IV-B and §IV-C: the global EDT brought up to date from the
        // obstacles the frame changed (exact), or the window's batch EDT
        // (Alg. 1) merged into it by wavefronts (Alg. 2 and 3).
        let updated = match self.global.run(&mut self.backend, &mut self.map, &volume, &fused.changed_blocks) {
            Ok(updated) => updated,
            Err(e) => return Err(self.recover(&volume, &fused.changed_blocks, e)),
        };
        let (batch_edt_ms, integrate_ms, merged) = (updated.batch_edt_ms, updated.integrate_ms, updated.report);
        self.volume = Some(volume);
        let mapped_voxels = (self.map.occupancy().len() * edtmap_core::BLOCK_VOXELS).max(1);
        Ok(FrameStats {
            sensor: index,
            ogm_ms,
            batch_edt_ms,
            integrate_ms,
            total_ms: ms_since(start),
            voxels_updated: fused.voxels_updated,
            voxels_changed: fused.voxels_changed,
            changed_blocks: fused.changed_blocks,
            occupancy_rewritten_blocks: fused.rewritten_blocks,
            edt_voxels_changed: merged.voxels_changed,
            edt_changed_blocks: merged.changed_blocks.len(),
            change_score_m: merged.change_sum_vox * self.params.voxel_size_m / mapped_voxels as f64,
            integrate_region_voxels: merged.region_voxels,
            waves: merged.waves,
            exact: merged.exact,
            map_blocks: self.map.occupancy().len() + self.map.edt().len() + self.map.fixed_obstacles().len(),
            map_bytes: self.map.bytes(),
        })
    }

    /// After the backend failed (a lost GPU, say) with the frame's
    /// occupancy already fused: finishes the frame's EDT stages on the CPU
    /// fallback, so the map stays whole, and returns the backend's error
    /// for the caller to act on (switch backends, stop).
    fn recover(&mut self, volume: &LocalVolume, changed: &[BlockKey], failure: MapError) -> MapError {
        if !failure.is_backend_failure() {
            return failure;
        }
        let mut cpu = self.fallback.take().unwrap_or_default();
        let finished = self.global.run(&mut cpu, &mut self.map, volume, changed);
        self.fallback = Some(cpu);
        match finished {
            Ok(_) => {
                self.volume = Some(*volume);
                failure
            }
            Err(e) => e,
        }
    }

    /// Whether [`Self::clear_far`] with these arguments would drop a block.
    pub fn would_clear(&self, centre_m: [f64; 3], radius_m: f64) -> bool {
        let side = f64::from(edtmap_core::BLOCK_SIDE) * self.params.voxel_size_m;
        self.map.occupancy().iter().any(|(k, _)| block_distance(k, side, centre_m) > radius_m)
    }

    /// Forgets the map farther than `radius_m` from `centre_m` (world,
    /// metres), as a long-running node bounds its memory (nvblox's map
    /// clearing): occupancy blocks whose centre is farther are dropped, the
    /// obstacles they held vanish from the global EDT exactly, and EDT
    /// blocks too far from every remaining obstacle to hold a distance
    /// within the cutoff are dropped. Fixed obstacles stay. The EDT stays
    /// the exact EDT of the obstacles kept. Exact mode only (the wavefront
    /// mode's merge would need the window's batch EDT).
    pub fn clear_far(&mut self, centre_m: [f64; 3], radius_m: f64) -> Result<Cleared, MapError> {
        let invalid = |reason| {
            MapError::Core(edtmap_core::CoreError::InvalidParam {
                field: "map_clearing_radius_m",
                value: radius_m.to_string(),
                reason,
            })
        };
        if !(radius_m.is_finite() && radius_m > 0.0 && centre_m.iter().all(|c| c.is_finite())) {
            return Err(invalid("must be a positive number of metres, around a finite centre"));
        }
        if !self.global.is_exact() {
            return Err(invalid("needs [global] mode = \"exact\""));
        }
        let bytes_before = self.map.bytes();
        let vs = self.params.voxel_size_m;
        let side = f64::from(edtmap_core::BLOCK_SIDE) * vs;
        let dist = |k: BlockKey| block_distance(k, side, centre_m);
        let gone = self.map.occupancy_mut().remove_where(|k| dist(k) > radius_m);
        if gone.is_empty() {
            return Ok(Cleared { bytes_before, bytes_after: bytes_before, ..Cleared::default() });
        }
        // The obstacles of the dropped blocks vanish: the exact update over them.
        self.global.apply_changes(&mut self.backend, &mut self.map, &gone)?;
        // Every obstacle left lies in a block within the radius, or is fixed:
        // EDT blocks beyond the radius by more than the cutoff and a block
        // diagonal hold no distance within the cutoff.
        let margin = self.params.global.max_distance_m + 2.0 * side * 3f64.sqrt();
        let fixed: Vec<BlockKey> = self.map.fixed_obstacles().iter().map(|(k, _)| k).collect();
        let near_fixed = |k: BlockKey| {
            fixed
                .iter()
                .any(|f| (0..3).map(|a| (f64::from(f.0[a] - k.0[a]) * side).powi(2)).sum::<f64>().sqrt() <= margin)
        };
        let edt_gone = self.map.edt_mut().remove_where(|k| dist(k) > radius_m + margin && !near_fixed(k));
        self.local = OnceLock::new();
        self.local_states = OnceLock::new();
        Ok(Cleared {
            occupancy_blocks: gone.len(),
            edt_blocks: edt_gone.len(),
            bytes_before,
            bytes_after: self.map.bytes(),
        })
    }

    /// The backend the stages run on.
    pub fn backend(&self) -> &B {
        &self.backend
    }

    /// The parameters in use.
    pub fn params(&self) -> &MapperParams {
        &self.params
    }

    /// The first sensor, which [`Self::integrate_frame`] checks frames
    /// against.
    pub fn sensor(&self) -> &Sensor {
        &self.sensors[0].sensor
    }

    /// The global map: occupancy, EDT, fixed obstacles.
    pub fn map(&self) -> &GlobalMap {
        &self.map
    }

    /// Gives the global map up (to save it, say).
    pub fn into_map(self) -> GlobalMap {
        self.map
    }

    /// Gives the backend up (to map something else on the same device).
    pub fn into_backend(mut self) -> B {
        self.backend.set_deferred_observations(false);
        self.backend
    }

    /// The state of world voxel `v`.
    pub fn state(&self, v: VoxelIndex) -> VoxelState {
        self.map.state(v)
    }

    /// Makes every occupied voxel of `prior` (a map built before, say) a
    /// fixed obstacle of this map, with its fixed obstacles; returns how
    /// many voxels were added. The global EDT takes them in at once.
    pub fn add_prior(&mut self, prior: &GlobalMap) -> Result<usize, MapError> {
        if (prior.voxel_size_m() - self.map.voxel_size_m()).abs() > 1e-9 * self.map.voxel_size_m() {
            return Err(MapError::Core(edtmap_core::CoreError::InvalidParam {
                field: "prior map voxel_size_m",
                value: prior.voxel_size_m().to_string(),
                reason: "must equal the mapper's voxel size",
            }));
        }
        let mut added = 0;
        for (key, block) in prior.occupancy().iter() {
            for (offset, value) in block.log_odds.iter().enumerate() {
                let v = key.voxel(offset);
                if prior.log_odds().state(value) == VoxelState::Occupied || prior.fixed_obstacles().contains(v) {
                    self.map.fixed_obstacles_mut().insert(v);
                    added += 1;
                }
            }
        }
        self.lay_down_fixed()?;
        Ok(added)
    }

    /// Distance to the nearest obstacle at world point `p` (metres), with
    /// its gradient, interpolated between voxel centres.
    pub fn distance(&self, p: [f64; 3]) -> Distance {
        query::distance(&self.map, p, false)
    }

    /// Signed distance at world point `p` (metres) to the surface of the
    /// obstacle voxels, with a unit gradient: negative exactly when `p`'s
    /// voxel is an obstacle (see [`crate::query`]).
    pub fn signed_distance(&self, p: [f64; 3]) -> Distance {
        query::distance(&self.map, p, true)
    }

    /// [`Self::distance`] of many points, in parallel.
    pub fn distances(&self, points: &[[f64; 3]]) -> Vec<Distance> {
        query::distances(&self.map, points, false)
    }

    /// State of the voxel holding world point `p`.
    pub fn state_at(&self, p: [f64; 3]) -> PointState {
        query::point_state(&self.map, p)
    }

    /// Exploration frontiers: observed free voxels next to unknown ones.
    pub fn frontiers(&self) -> Vec<VoxelIndex> {
        self.map.frontiers()
    }

    /// The latest local volume, once a frame has been integrated.
    pub fn local_volume(&self) -> Option<&LocalVolume> {
        self.volume.as_ref()
    }

    /// States of the latest local volume (x fastest), read from the map at
    /// the first call after a frame (no stage needs them; empty before the
    /// first frame).
    pub fn local_states(&self) -> &Grid3<VoxelState> {
        self.local_states.get_or_init(|| {
            let mut states = Grid3::default();
            if let Some(volume) = &self.volume {
                // Only a grid of the wrong size fails, and this one is sized here.
                let _ = read_states(self.map.occupancy(), volume, self.map.log_odds(), &mut states);
            }
            states
        })
    }

    /// Exact EDT of the latest local volume, in its voxel units: the
    /// high-rate local distance field of the paper, for local planners.
    /// The wavefront mode computes it every frame; the exact mode at the
    /// first call after a frame, on the CPU (every backend gives the same
    /// field), empty before the first frame.
    pub fn local_edt(&self) -> &EdtField {
        if let Some(field) = self.global.local_field() {
            return field;
        }
        self.local.get_or_init(|| {
            let Some(volume) = &self.volume else { return EdtField::empty() };
            // The window was checked when the mapper was made.
            local_field(&mut CpuBackend::default(), &self.map, volume, self.params.edt.unknown_as_occupied)
                .unwrap_or_else(|_| EdtField::empty())
        })
    }
}

/// Distance from block `k`'s centre (blocks of `side` metres) to `p`.
fn block_distance(k: BlockKey, side: f64, p: [f64; 3]) -> f64 {
    (0..3).map(|a| ((f64::from(k.0[a]) + 0.5) * side - p[a]).powi(2)).sum::<f64>().sqrt()
}

/// The error for a sensor index a mapper does not have.
fn no_sensor(index: usize, sensors: usize) -> MapError {
    MapError::Core(edtmap_core::CoreError::BadMeasurement(format!(
        "a frame of sensor {index}, and the mapper has {sensors} sensor(s) (indices 0 to {})",
        sensors - 1
    )))
}
