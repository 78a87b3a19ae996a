//! A backend that fails mid-frame (a GPU lost after the frame's occupancy
//! was fused): the frame returns the backend's error, the mapper finishes
//! the frame on the CPU so the map stays whole, and mapping goes on.

use edtmap::config::Config;
use edtmap::cpu::CpuBackend;
use edtmap::{
    Backend, BackendError, BatchEdt, EdtField, FixedRay, Grid3, IntegrationJob, IntegrationMode, IntegrationReport,
    MapError, Mapper, Observations, ProjectJob,
};
use edtmap_sim::{Scene, SceneName, SceneOptions};
use std::path::PathBuf;

/// The CPU, but its `fail_batch_at`-th batch EDT or its
/// `fail_integrate_at`-th integration fails as a lost device would.
struct Flaky {
    cpu: CpuBackend,
    batches: usize,
    integrations: usize,
    fail_batch_at: usize,
    fail_integrate_at: usize,
}

impl BatchEdt for Flaky {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        self.batches += 1;
        if self.batches == self.fail_batch_at {
            // What a lost device leaves: garbage, then an error.
            out.prepare(mask.dims())?.0.fill(7);
            return Err(BackendError::DeviceLost("simulated".into()));
        }
        self.cpu.batch_edt(mask, out)
    }
}

impl Backend for Flaky {
    fn name(&self) -> String {
        "flaky".into()
    }
    fn cast_rays(&mut self, rays: &[FixedRay], q: u32, obs: &Observations) -> Result<(), BackendError> {
        self.cpu.cast_rays(rays, q, obs)
    }
    fn project_volume(&mut self, job: &ProjectJob<'_>, obs: &Observations) -> Result<(), BackendError> {
        self.cpu.project_volume(job, obs)
    }
    fn integrate(&mut self, job: IntegrationJob<'_>) -> Result<IntegrationReport, BackendError> {
        self.integrations += 1;
        if self.integrations == self.fail_integrate_at {
            // The map is written only once the device is done: untouched.
            return Err(BackendError::DeviceLost("simulated".into()));
        }
        self.cpu.integrate(job)
    }
}

#[test]
fn a_backend_failure_returns_the_error_and_keeps_the_map_whole() {
    // The wavefront mode's batch EDT fails at frame 2; the exact mode's
    // integration does.
    for mode in [IntegrationMode::Wavefront, IntegrationMode::Exact] {
        let (batch, integrate) = if mode == IntegrationMode::Wavefront { (3, 0) } else { (0, 3) };
        failure_keeps_the_map_whole(
            mode,
            Flaky {
                cpu: CpuBackend::default(),
                batches: 0,
                integrations: 0,
                fail_batch_at: batch,
                fail_integrate_at: integrate,
            },
        );
    }
}

fn failure_keeps_the_map_whole(mode: IntegrationMode, flaky: Flaky) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs/uav_pillars.toml");
    let (sensor, mut params) = Config::load(&path).expect("config").mapper_params().expect("valid");
    params.global.mode = mode;
    let scene = Scene::new(SceneName::UavPillars, &SceneOptions::default()).expect("scene");
    let mut reference = Mapper::new(sensor.clone(), params.clone()).expect("cpu mapper");
    let mut mapper = Mapper::new_on(flaky, sensor.clone(), params).expect("flaky mapper");
    for i in 0..5 {
        let frame = scene.frame(&sensor, i * 3).expect("frame");
        reference.integrate_frame(&frame).expect("reference frame");
        match mapper.integrate_frame(&frame) {
            Ok(_) => assert_ne!(i, 2, "{mode:?}: frame 2 must report the failure"),
            Err(MapError::Backend(BackendError::DeviceLost(why))) => {
                assert_eq!(i, 2);
                assert_eq!(why, "simulated");
            }
            Err(e) => panic!("unexpected error {e}"),
        }
        assert!(mapper.local_edt() == reference.local_edt(), "frame {i}: local EDT");
        let (a, b) = (mapper.map(), reference.map());
        assert_eq!(a.edt().len(), b.edt().len(), "frame {i}");
        for (key, block) in b.edt().iter() {
            assert!(a.edt().get(key) == Some(block), "frame {i}: block {key:?}");
        }
    }
}

/// A backend whose device is lost in the occupancy stage (ray casting).
struct LostInRaycast(CpuBackend);

impl BatchEdt for LostInRaycast {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        self.0.batch_edt(mask, out)
    }
}

impl Backend for LostInRaycast {
    fn name(&self) -> String {
        "lost-in-raycast".into()
    }
    fn cast_rays(&mut self, _: &[FixedRay], _: u32, _: &Observations) -> Result<(), BackendError> {
        Err(BackendError::DeviceLost("lost while casting rays".into()))
    }
    fn project_volume(&mut self, job: &ProjectJob<'_>, obs: &Observations) -> Result<(), BackendError> {
        self.0.project_volume(job, obs)
    }
    fn integrate(&mut self, job: IntegrationJob<'_>) -> Result<IntegrationReport, BackendError> {
        self.0.integrate(job)
    }
}

#[test]
fn a_device_lost_in_the_occupancy_stage_is_a_backend_failure() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs/uav_pillars.toml");
    let mut config = Config::load(&path).expect("config");
    config.sensor.construction = edtmap::config::ConstructionName::Raycast;
    let (sensor, params) = config.mapper_params().expect("valid");
    let scene = Scene::new(SceneName::UavPillars, &SceneOptions::default()).expect("scene");
    let mut mapper = Mapper::new_on(LostInRaycast(CpuBackend::default()), sensor.clone(), params).expect("mapper");
    let err = mapper.integrate_frame(&scene.frame(&sensor, 0).expect("frame")).expect_err("the device is lost");
    assert!(err.is_backend_failure(), "{err:?}");
    assert!(matches!(err, MapError::Backend(BackendError::DeviceLost(_))), "{err:?}");
}

/// A backend whose device is lost while fusing a frame's observations.
struct LostInFusion(CpuBackend, usize);

impl BatchEdt for LostInFusion {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        self.0.batch_edt(mask, out)
    }
}

impl Backend for LostInFusion {
    fn name(&self) -> String {
        "lost-in-fusion".into()
    }
    fn cast_rays(&mut self, rays: &[FixedRay], q: u32, obs: &Observations) -> Result<(), BackendError> {
        self.0.cast_rays(rays, q, obs)
    }
    fn project_volume(&mut self, job: &ProjectJob<'_>, obs: &Observations) -> Result<(), BackendError> {
        self.0.project_volume(job, obs)
    }
    fn fuse(
        &mut self,
        map: &mut edtmap::OccupancyMap,
        obs: &Observations,
        lo: &edtmap::LogOdds,
    ) -> Result<edtmap::FuseReport, BackendError> {
        // The first frames fuse; then the device is gone.
        self.1 += 1;
        if self.1 > 2 {
            return Err(BackendError::DeviceLost("lost while fusing".into()));
        }
        self.0.fuse(map, obs, lo)
    }
    fn integrate(&mut self, job: IntegrationJob<'_>) -> Result<IntegrationReport, BackendError> {
        self.0.integrate(job)
    }
}

#[test]
fn a_device_lost_in_the_fusion_leaves_the_map_as_it_was() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs/uav_pillars.toml");
    let (sensor, params) = Config::load(&path).expect("config").mapper_params().expect("valid");
    let scene = Scene::new(SceneName::UavPillars, &SceneOptions::default()).expect("scene");
    let mut mapper = Mapper::new_on(LostInFusion(CpuBackend::default(), 0), sensor.clone(), params).expect("mapper");
    for i in 0..2 {
        mapper.integrate_frame(&scene.frame(&sensor, i).expect("frame")).expect("fused");
    }
    let blocks = |m: &edtmap::GlobalMap| {
        let mut b: Vec<(edtmap::BlockKey, Vec<u32>)> =
            m.occupancy().iter().map(|(k, b)| (k, b.log_odds.iter().map(|l| l.to_bits()).collect())).collect();
        b.sort_by_key(|e| e.0);
        b
    };
    let before = blocks(mapper.map());
    let err = mapper.integrate_frame(&scene.frame(&sensor, 5).expect("frame")).expect_err("the device is lost");
    assert!(matches!(err, MapError::Backend(BackendError::DeviceLost(_))), "{err:?}");
    assert!(blocks(mapper.map()) == before, "the failed frame changed the occupancy");
}
