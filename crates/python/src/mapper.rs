//! `edtmap._edtmap.Mapper`: the mapping pipeline behind `edtmap.Mapper`.
//!
//! Frames are integrated under a lock, with the GIL released; queries read
//! a snapshot of the map as it was after the last frame (blocks are shared
//! copy-on-write, so taking one costs a pointer per block), so any number
//! of threads query while another integrates, each seeing a whole frame.

use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use edtmap::config::{Config, SensorSection};
use edtmap::cpu::CpuBackend;
use edtmap::query;
use edtmap::sensor::{DepthData, DepthImage, Frame, LaserScan, LidarScan, Measurement, PointCloud, RangeLimits};
use edtmap::{
    Backend, BackendChoice, FrameStats, FrameThreads, GlobalMap, MapError, Mapper, MapperSensor, PointState,
    SharedMapper, Snapshot,
};
use nalgebra::{Isometry3, Quaternion, Translation3};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;

/// Distances, gradients and state codes of a batched query.
type Answers<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<u8>>);

/// The backend a mapper runs on, chosen when it is made.
pub(crate) type DynBackend = edtmap::DynBackend;

/// Opens the backend `name` names ([`edtmap::open_backend`]): `cpu`, `gpu`
/// (an error without an adapter or the `gpu` feature) or `auto` (a
/// hardware GPU, else the CPU); a planar map's is the CPU.
fn open_backend(name: &str, planar: bool) -> PyResult<DynBackend> {
    let choice: BackendChoice = name.parse().map_err(|e: MapError| PyValueError::new_err(e.to_string()))?;
    match edtmap::open_backend(choice, CpuBackend::default(), planar) {
        Ok(opened) => Ok(opened.backend),
        Err(MapError::NoGpuBackend) => Err(PyValueError::new_err(format!(
            "backend={name:?}: this build of edtmap has no GPU backend; install it with \
             MATURIN_PEP517_ARGS=\"--features gpu\" pip install ./python"
        ))),
        Err(e @ MapError::Backend(_)) => Err(PyRuntimeError::new_err(format!("backend={name:?}: {e}"))),
        Err(e) => Err(PyValueError::new_err(format!("backend={name:?}: {e}"))),
    }
}

/// Points per parallel task of a batched query.
const QUERY_CHUNK: usize = 4096;

/// A [`MapError`] as the Python exception a caller expects: files that
/// cannot be read or written are `OSError`, a lock left poisoned by a
/// panic in another thread `RuntimeError`, everything else `ValueError`.
pub(crate) fn map_err(e: MapError) -> PyErr {
    match e {
        MapError::Io(io) => PyOSError::new_err(io.to_string()),
        e @ MapError::Poisoned(_) => PyRuntimeError::new_err(e.to_string()),
        other => PyValueError::new_err(other.to_string()),
    }
}

/// The mapper and the snapshot its queries read ([`SharedMapper`]).
#[pyclass(name = "Mapper", module = "edtmap._edtmap", frozen)]
pub(crate) struct PyMapper {
    shared: SharedMapper<DynBackend>,
    /// Per sensor, the range limits of a planar LiDAR's scans (its section's
    /// min/max range).
    scan_ranges: Mutex<Vec<RangeLimits>>,
    /// The threads each frame runs on: as many as cores are free.
    threads: Mutex<FrameThreads>,
}

impl PyMapper {
    fn new(mapper: Mapper<DynBackend>, scan_range: RangeLimits) -> Self {
        PyMapper {
            shared: SharedMapper::new(mapper),
            scan_ranges: Mutex::new(vec![scan_range]),
            threads: Mutex::new(FrameThreads::new()),
        }
    }

    fn lock(&self) -> PyResult<MutexGuard<'_, Mapper<DynBackend>>> {
        self.shared.lock().map_err(map_err)
    }

    fn map(&self) -> PyResult<Arc<Snapshot>> {
        Ok(self.shared.snapshot())
    }

    /// Integrates one frame of sensor `sensor` without the GIL, on a
    /// thread of rayon's pool (the stages' parallel loops then start at
    /// once instead of being handed over one by one) and on as many
    /// threads as cores are free ([`FrameThreads`]), and publishes the new
    /// snapshot.
    fn integrate<'py>(&self, py: Python<'py>, sensor: usize, frame: Frame) -> PyResult<Bound<'py, PyDict>> {
        let stats = py.detach(|| {
            let mut threads = self.threads.lock().unwrap_or_else(PoisonError::into_inner);
            threads.run(|| self.shared.integrate_sensor(sensor, &frame)).map_err(map_err)
        })?;
        stats_dict(py, &stats)
    }
}

impl PyMapper {
    /// Builds a mapper from a parsed configuration.
    pub(crate) fn from_parsed(config: &Config, map: Option<GlobalMap>, backend: &str) -> PyResult<PyMapper> {
        let (sensor, params) = config.mapper_params().map_err(map_err)?;
        let scan_range = RangeLimits { min_m: config.sensor.min_range_m, max_m: config.sensor.max_range_m };
        let backend = open_backend(backend, params.global.planar)?;
        let mapper = match map {
            Some(map) => Mapper::with_map_on(backend, sensor, params, map),
            None => Mapper::new_on(backend, sensor, params),
        }
        .map_err(map_err)?;
        let py_mapper = PyMapper::new(mapper, scan_range);
        config.add_sensors_to(&mut *py_mapper.lock()?).map_err(map_err)?;
        let ranges = config.other_sensors.iter().map(|s| RangeLimits { min_m: s.min_range_m, max_m: s.max_range_m });
        py_mapper.scan_ranges.lock().map_err(|_| PyRuntimeError::new_err("sensor list poisoned"))?.extend(ranges);
        Ok(py_mapper)
    }
}

/// A pose from a row-major 4×4 rigid transform (16 values) or from
/// `[x, y, z, qx, qy, qz, qw]` (7 values, a unit quaternion as ROS orders
/// it, taken bit for bit).
fn pose(values: &[f64]) -> PyResult<Isometry3<f64>> {
    let bad = |why: String| PyValueError::new_err(format!("t_world_sensor: {why}"));
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(bad(format!("holds {v}; every value must be finite")));
    }
    match values.len() {
        16 => {
            let mut m = [[0.0; 4]; 4];
            for (r, row) in m.iter_mut().enumerate() {
                row.copy_from_slice(&values[4 * r..4 * r + 4]);
            }
            edtmap::sensor::pose_from_matrix(&m).map_err(|e| bad(e.to_string()))
        }
        7 => {
            // The rule recordings' poses follow: normalised within the
            // tolerance (a unit quaternion kept bit for bit), refused beyond.
            let q = Quaternion::new(values[6], values[3], values[4], values[5]);
            let (rotation, _) =
                edtmap::sensor::rotation_from_quaternion(q).map_err(|e| bad(format!("[qx, qy, qz, qw]: {e}")))?;
            Ok(Isometry3::from_parts(Translation3::new(values[0], values[1], values[2]), rotation))
        }
        n => Err(bad(format!("has {n} values: give a 4 x 4 matrix or [x, y, z, qx, qy, qz, qw]"))),
    }
}

/// A configuration given as JSON text (the TOML file's structure), as
/// `edtmap.Mapper(...)` builds it; `origin` names it in errors.
fn config_from_json(text: &str, origin: &str) -> PyResult<Config> {
    serde_json::from_str(text).map_err(|e| PyValueError::new_err(format!("{origin}: {e}")))
}

/// A frame of `measurement` taken at `pose_values` (see [`pose`]).
fn frame(pose_values: &[f64], stamp: f64, measurement: Measurement) -> PyResult<Frame> {
    Ok(Frame { stamp_s: stamp, t_world_sensor: pose(pose_values)?, measurement })
}

/// A frame's statistics as a dict.
fn stats_dict<'py>(py: Python<'py>, s: &FrameStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("ogm_ms", s.ogm_ms)?;
    d.set_item("batch_edt_ms", s.batch_edt_ms)?;
    d.set_item("integrate_ms", s.integrate_ms)?;
    d.set_item("total_ms", s.total_ms)?;
    d.set_item("voxels_updated", s.voxels_updated)?;
    d.set_item("voxels_changed", s.voxels_changed)?;
    d.set_item("changed_blocks", s.changed_blocks.len())?;
    d.set_item("occupancy_rewritten_blocks", s.occupancy_rewritten_blocks)?;
    d.set_item("edt_voxels_changed", s.edt_voxels_changed)?;
    d.set_item("change_score_m", s.change_score_m)?;
    d.set_item("integrate_region_voxels", s.integrate_region_voxels)?;
    d.set_item("map_blocks", s.map_blocks)?;
    d.set_item("map_bytes", s.map_bytes)?;
    Ok(d)
}

/// The code of a point's state: 0 outside the mapped blocks, 1 unknown,
/// 2 free, 3 occupied (as `edtmap export`).
fn state_code(s: PointState) -> u8 {
    match s {
        PointState::Outside => 0,
        PointState::Unknown => 1,
        PointState::Free => 2,
        PointState::Occupied => 3,
    }
}

/// `points` as a slice of 3-vectors, checking the shape.
fn points3<'a>(points: &'a PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<&'a [[f64; 3]]> {
    let shape = points.shape();
    if shape[1] != 3 {
        return Err(PyValueError::new_err(format!("{name} must have shape (N, 3), not {shape:?}")));
    }
    let flat = points.as_slice().map_err(|_| PyValueError::new_err(format!("{name} must be C-contiguous")))?;
    Ok(flat.as_chunks::<3>().0)
}

/// A 2D array's values and `(rows, columns)`.
fn image<'a, T: numpy::Element>(a: &'a PyReadonlyArray2<'_, T>, name: &str) -> PyResult<(&'a [T], [usize; 2])> {
    let shape = [a.shape()[0], a.shape()[1]];
    if shape.contains(&0) {
        return Err(PyValueError::new_err(format!("{name} is empty (shape {shape:?})")));
    }
    let values = a.as_slice().map_err(|_| PyValueError::new_err(format!("{name} must be C-contiguous")))?;
    Ok((values, shape))
}

#[pymethods]
impl PyMapper {
    /// A mapper from a TOML configuration file (`[sensor]`, `[occupancy]`,
    /// `[edt]`, `[global]`, `[memory]`; other sections are ignored here).
    #[staticmethod]
    fn from_config_file(path: PathBuf, backend: &str) -> PyResult<Self> {
        let config = Config::load(&path).map_err(map_err)?;
        PyMapper::from_parsed(&config, None, backend)
    }

    /// A mapper from a configuration given as JSON text (the TOML file's
    /// structure), as `edtmap.Mapper(...)` builds it; `origin` names it in
    /// errors.
    #[staticmethod]
    fn from_config_json(text: &str, origin: &str, backend: &str) -> PyResult<Self> {
        PyMapper::from_parsed(&config_from_json(text, origin)?, None, backend)
    }

    /// A mapper that goes on from the map file `path`, for the sensor and
    /// parameters of `config_json` (the map's voxel size, probabilities and
    /// global EDT parameters win).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf, config_json: &str, origin: &str, backend: &str) -> PyResult<Self> {
        let mut config = config_from_json(config_json, origin)?;
        let map = py.detach(|| edtmap::load_map(&path)).map_err(map_err)?;
        // The map's voxel size wins; the occupancy options follow it.
        config.occupancy.voxel_size_m = map.voxel_size_m();
        PyMapper::from_parsed(&config, Some(map), backend)
    }

    /// Integrates a depth image in metres (float32, H × W).
    #[pyo3(signature = (depth, pose_values, stamp, sensor = 0))]
    fn integrate_depth_m<'py>(
        &self,
        py: Python<'py>,
        depth: PyReadonlyArray2<'py, f32>,
        pose_values: Vec<f64>,
        stamp: f64,
        sensor: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (values, [h, w]) = image(&depth, "depth")?;
        let data = DepthData::Metres(values.to_vec());
        self.depth_frame(py, data, [w, h], &pose_values, stamp, sensor)
    }

    /// Integrates a raw 16-bit depth image (H × W), `scale` metres per unit.
    #[pyo3(signature = (depth, scale, pose_values, stamp, sensor = 0))]
    fn integrate_depth_u16<'py>(
        &self,
        py: Python<'py>,
        depth: PyReadonlyArray2<'py, u16>,
        scale: f32,
        pose_values: Vec<f64>,
        stamp: f64,
        sensor: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        if !(scale.is_finite() && scale > 0.0) {
            return Err(PyValueError::new_err(format!("depth_scale must be finite and positive, got {scale}")));
        }
        let (values, [h, w]) = image(&depth, "depth")?;
        let data = DepthData::U16 { values: values.to_vec(), metres_per_unit: scale };
        self.depth_frame(py, data, [w, h], &pose_values, stamp, sensor)
    }

    /// Integrates a point cloud (N × 3 float32, sensor frame).
    #[pyo3(signature = (points, pose_values, stamp, sensor = 0))]
    fn integrate_points<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        pose_values: Vec<f64>,
        stamp: f64,
        sensor: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let shape = points.shape();
        if shape[1] != 3 || shape[0] == 0 {
            return Err(PyValueError::new_err(format!("points must have shape (N, 3) with N > 0, not {shape:?}")));
        }
        let flat = points.as_slice().map_err(|_| PyValueError::new_err("points must be C-contiguous"))?;
        let cloud = PointCloud { points: flat.as_chunks::<3>().0.to_vec() };
        self.integrate(py, sensor, frame(&pose_values, stamp, Measurement::Points(cloud))?)
    }

    /// Integrates a planar scan (ranges in metres, float32); the range
    /// limits are `[sensor]`'s unless given.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (ranges, angle_min, angle_increment, pose_values, stamp, range_limits = None, sensor = 0))]
    fn integrate_scan<'py>(
        &self,
        py: Python<'py>,
        ranges: PyReadonlyArray1<'py, f32>,
        angle_min: f64,
        angle_increment: f64,
        pose_values: Vec<f64>,
        stamp: f64,
        range_limits: Option<(f32, f32)>,
        sensor: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let ranges = ranges.as_slice().map_err(|_| PyValueError::new_err("ranges must be contiguous"))?.to_vec();
        let own = self.scan_ranges.lock().ok().and_then(|r| r.get(sensor).copied());
        let range = match (range_limits, own) {
            (Some((min_m, max_m)), _) => RangeLimits { min_m, max_m },
            (None, Some(range)) => range,
            (None, None) => {
                return Err(PyValueError::new_err(format!("sensor {sensor}: the mapper has no such sensor")))
            }
        };
        let scan = LaserScan { angle_min_rad: angle_min, angle_increment_rad: angle_increment, ranges, range };
        self.integrate(py, sensor, frame(&pose_values, stamp, Measurement::Scan(scan))?)
    }

    /// Integrates a spinning LiDAR's range image (rings × azimuth bins).
    #[pyo3(signature = (ranges, pose_values, stamp, sensor = 0))]
    fn integrate_range_image<'py>(
        &self,
        py: Python<'py>,
        ranges: PyReadonlyArray2<'py, f32>,
        pose_values: Vec<f64>,
        stamp: f64,
        sensor: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (values, _) = image(&ranges, "ranges")?;
        let scan = LidarScan { ranges: values.to_vec() };
        self.integrate(py, sensor, frame(&pose_values, stamp, Measurement::Lidar(scan))?)
    }

    /// Distances (metres), gradients and state codes of N points, in
    /// parallel without the GIL.
    fn distance<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
        signed: bool,
    ) -> PyResult<Answers<'py>> {
        let pts = points3(&points, "points")?;
        let map = self.map()?;
        let n = pts.len();
        let (mut dist, mut grad, mut state) = (vec![0.0f64; n], vec![0.0f64; 3 * n], vec![0u8; n]);
        py.detach(|| {
            dist.par_chunks_mut(QUERY_CHUNK)
                .zip(grad.par_chunks_mut(3 * QUERY_CHUNK))
                .zip(state.par_chunks_mut(QUERY_CHUNK))
                .zip(pts.par_chunks(QUERY_CHUNK))
                .for_each(|(((dist, grad), state), pts)| {
                    for (i, p) in pts.iter().enumerate() {
                        let d = query::distance(&map, *p, signed);
                        dist[i] = d.distance_m;
                        grad[3 * i..3 * i + 3].copy_from_slice(&d.gradient);
                        state[i] = state_code(d.state);
                    }
                });
        });
        let grad = PyArray1::from_vec(py, grad).reshape([n, 3])?;
        Ok((PyArray1::from_vec(py, dist), grad, PyArray1::from_vec(py, state)))
    }

    /// State codes of N points.
    fn state<'py>(&self, py: Python<'py>, points: PyReadonlyArray2<'py, f64>) -> PyResult<Bound<'py, PyArray1<u8>>> {
        let pts = points3(&points, "points")?;
        let map = self.map()?;
        let state: Vec<u8> = py.detach(|| pts.par_iter().map(|&p| state_code(query::point_state(&map, p))).collect());
        Ok(PyArray1::from_vec(py, state))
    }

    /// The dense box `[min_m, max_m)`: distances (float32, metres) and
    /// state codes, each of shape `(nz, ny, nx)` in C order, and the world
    /// index of element `[0, 0, 0]`.
    #[allow(clippy::type_complexity)]
    fn export_box<'py>(
        &self,
        py: Python<'py>,
        min_m: [f64; 3],
        max_m: [f64; 3],
        signed: bool,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, [i32; 3])> {
        let map = self.map()?;
        let dense = py
            .detach(|| query::distance_box(&map, min_m, max_m, signed))
            .map_err(|e| PyValueError::new_err(format!("export_box: {e}")))?;
        let [nx, ny, nz] = dense.dims;
        let dist = PyArray1::from_vec(py, dense.distance_m).reshape([nz, ny, nx])?.into_any();
        let state = PyArray1::from_vec(py, dense.state).reshape([nz, ny, nx])?.into_any();
        Ok((dist, state, dense.origin.0))
    }

    /// The local volume's exact EDT (squared distances in voxels, shape
    /// `(nz, ny, nx)`, C order, `u32::MAX` without obstacle), its state
    /// codes, and the world index of its element `[0, 0, 0]`; `None`
    /// before the first frame.
    #[allow(clippy::type_complexity)]
    fn local_edt<'py>(&self, py: Python<'py>) -> PyResult<Option<(Bound<'py, PyAny>, Bound<'py, PyAny>, [i32; 3])>> {
        let local = py.detach(|| -> PyResult<_> {
            let mapper = self.lock()?;
            let Some(volume) = mapper.local_volume().copied() else { return Ok(None) };
            let edt = mapper.local_edt().dist_sq_vox().to_vec();
            // The codes of `state_code`: 1 unknown, 2 free, 3 occupied.
            let states: Vec<u8> = mapper.local_states().as_slice().iter().map(|s| *s as u8 + 1).collect();
            Ok(Some((edt, states, volume.dims, volume.origin.0)))
        })?;
        let Some((dist_sq, states, dims, origin)) = local else { return Ok(None) };
        let [nx, ny, nz] = dims;
        let d = PyArray1::from_vec(py, dist_sq).reshape([nz, ny, nx])?.into_any();
        let s = PyArray1::from_vec(py, states).reshape([nz, ny, nx])?.into_any();
        Ok(Some((d, s, origin)))
    }

    /// Frontier voxels (observed free beside unknown), as world indices.
    fn frontiers<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<i32>>> {
        let map = self.map()?;
        let cells: Vec<i32> = py.detach(|| map.frontiers().into_iter().flat_map(|v| v.0).collect());
        let n = cells.len() / 3;
        PyArray1::from_vec(py, cells).reshape([n, 3])
    }

    /// Writes the whole map to `path` (atomically).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let map = self.map()?;
        py.detach(|| edtmap::save_map(&map, &path)).map_err(map_err)
    }

    /// Voxel edge length, metres.
    #[getter]
    fn voxel_size_m(&self) -> PyResult<f64> {
        Ok(self.map()?.voxel_size_m())
    }

    /// Distance cutoff of the global EDT, metres.
    #[getter]
    fn max_distance_m(&self) -> PyResult<f64> {
        Ok(self.map()?.params().max_distance_m)
    }

    /// What the mapper runs on: `cpu (N threads)` or the GPU's name.
    #[getter]
    fn backend(&self) -> PyResult<String> {
        Ok(self.lock()?.backend().name())
    }

    /// The sensor kind: `depth`, `lidar`, `points` or `planar`.
    #[getter]
    fn sensor_kind(&self) -> PyResult<&'static str> {
        Ok(self.lock()?.sensor().name())
    }

    /// The sensors, in the order they were added: `(name, kind)` pairs.
    #[getter]
    fn sensors(&self) -> PyResult<Vec<(String, &'static str)>> {
        Ok(self.lock()?.sensors().iter().map(|s| (s.name.clone(), s.sensor.name())).collect())
    }

    /// Adds a sensor, its `[sensor]` table given as JSON text, named
    /// `name`; returns its index. `origin` names it in errors.
    fn add_sensor(&self, name: &str, section_json: &str, origin: &str) -> PyResult<usize> {
        let mut section: SensorSection =
            serde_json::from_str(section_json).map_err(|e| PyValueError::new_err(format!("{origin}: {e}")))?;
        section.name = Some(name.to_string());
        let in_origin = |e: edtmap::CoreError| PyValueError::new_err(format!("{origin}: {e}"));
        let (sensor, ogm) = section.checked().map_err(in_origin)?;
        let mut ranges = self.scan_ranges.lock().map_err(|_| PyRuntimeError::new_err("sensor list poisoned"))?;
        let index = self.lock()?.add_sensor(MapperSensor { name: name.to_string(), sensor, ogm }).map_err(map_err)?;
        ranges.push(RangeLimits { min_m: section.min_range_m, max_m: section.max_range_m });
        Ok(index)
    }

    /// Blocks of the global map (occupancy, EDT, fixed obstacles).
    #[getter]
    fn map_blocks(&self) -> PyResult<usize> {
        let map = self.map()?;
        Ok(map.occupancy().len() + map.edt().len() + map.fixed_obstacles().len())
    }
}

impl PyMapper {
    fn depth_frame<'py>(
        &self,
        py: Python<'py>,
        data: DepthData,
        [width, height]: [usize; 2],
        pose_values: &[f64],
        stamp: f64,
        sensor: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let too_big = |n: usize| {
            u32::try_from(n).map_err(|_| PyValueError::new_err(format!("depth image side {n} is too large")))
        };
        let image = DepthImage { width: too_big(width)?, height: too_big(height)?, data };
        self.integrate(py, sensor, frame(pose_values, stamp, Measurement::Depth(image))?)
    }
}
