//! `edtmap._edtmap.Recording`: the frames of any recording edtmap reads,
//! as numpy arrays, streamed by a reader thread a few frames ahead.

use std::path::PathBuf;
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::{Arc, Mutex};

use edtmap::config::Config;
use edtmap::sensor::{DepthData, Frame, Measurement, Sensor};
use edtmap_ros::config::{DatasetSection, OnError};
use edtmap_ros::recording::{Recording, RecordingFailure};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::mapper::{map_err, PyMapper};

/// Frames read ahead of the Python loop.
const READ_AHEAD: usize = 2;

/// An open recording being read.
#[pyclass(name = "Recording", module = "edtmap._edtmap", frozen)]
pub(crate) struct PyRecording {
    frames: Mutex<Receiver<(usize, Result<Frame, RecordingFailure>)>>,
    /// The configuration, with the recording's calibration applied.
    config: Config,
    /// What to do with a frame that cannot be used.
    on_error: OnError,
    /// The sensors, by name, in the config's order.
    sensors: Vec<(String, Sensor)>,
    len: usize,
    kind: &'static str,
    skipped: Mutex<Vec<String>>,
    /// The recording's one warning about poses replaced by the nearest
    /// rotation, left by the reader thread when it is done; given to
    /// Python's `warnings` once, at the end of the iteration.
    pose_warning: Arc<Mutex<Option<String>>>,
}

#[pymethods]
impl PyRecording {
    /// Opens `path` with the TOML configuration `config_path` (its
    /// `[dataset]` section says how: topics, poses, extrinsics, depth
    /// scale); reads at most `frames` frames.
    #[new]
    #[pyo3(signature = (path, config_path, frames=None))]
    fn new(py: Python<'_>, path: PathBuf, config_path: PathBuf, frames: Option<usize>) -> PyResult<Self> {
        let text = edtmap::config::read(&config_path).map_err(map_err)?;
        let origin = config_path.display().to_string();
        let mut config = Config::parse(&text, &origin).map_err(map_err)?;
        let dataset = DatasetSection::parse(&text, &origin).map_err(map_err)?;
        let recording = py.detach(|| Recording::open(&path, &mut config, &dataset, &origin)).map_err(map_err)?;
        let (sensor, _) = config.mapper_params().map_err(map_err)?;
        let sensors: Vec<(String, Sensor)> =
            config.mapper_sensors().map_err(map_err)?.into_iter().map(|(s, _)| (s.name, s.sensor)).collect();
        if sensors.len() == 1 && recording.kind() != sensor.kind() {
            return Err(PyValueError::new_err(format!(
                "{} holds {} frames but {origin}'s [sensor] is a {}",
                path.display(),
                recording.kind(),
                sensor.kind()
            )));
        }
        let len = recording.len();
        let kind = sensor.name();
        let n = frames.unwrap_or(len).min(len);
        let (tx, rx) = sync_channel(READ_AHEAD);
        let name = path.display().to_string();
        let pose_warning = Arc::new(Mutex::new(None));
        let warning_slot = Arc::clone(&pose_warning);
        std::thread::Builder::new()
            .name("edtmap-recording".into())
            .spawn(move || {
                for (_, sensor, frame) in recording.frames(n, &name) {
                    // The receiver is gone when Python dropped the recording.
                    if tx.send((sensor, frame)).is_err() {
                        return;
                    }
                }
                // Before the sender is dropped, which ends the iteration.
                if let Ok(mut slot) = warning_slot.lock() {
                    *slot = recording.pose_warning();
                }
                drop(tx);
            })
            .map_err(|e| PyRuntimeError::new_err(format!("cannot start the reader thread: {e}")))?;
        Ok(PyRecording {
            frames: Mutex::new(rx),
            config,
            on_error: dataset.on_error,
            sensors,
            len,
            kind,
            skipped: Mutex::new(Vec::new()),
            pose_warning,
        })
    }

    fn __len__(&self) -> usize {
        self.len
    }

    /// The sensor kind: `depth`, `lidar`, `points` or `planar`.
    #[getter]
    fn kind(&self) -> &'static str {
        self.kind
    }

    /// Messages of the frames skipped so far (`[dataset] on_error = "skip"`).
    #[getter]
    fn skipped(&self) -> PyResult<Vec<String>> {
        Ok(self.skipped.lock().map_err(|_| PyRuntimeError::new_err("poisoned"))?.clone())
    }

    /// A mapper for this recording: the configuration with the recording's
    /// calibration applied, as `edtmap run --dataset` makes it.
    #[pyo3(signature = (backend="cpu"))]
    fn mapper(&self, backend: &str) -> PyResult<PyMapper> {
        PyMapper::from_parsed(&self.config, None, backend)
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    /// The next frame as a dict, skipping or raising on a bad frame as
    /// `[dataset] on_error` says; the end of the recording (or damage that
    /// ends it, under `skip`) stops the iteration.
    fn __next__<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        loop {
            let next = py.detach(|| self.frames.lock().map(|rx| rx.recv().ok()).map_err(|_| ()));
            let next = next.map_err(|()| PyRuntimeError::new_err("a reader of this recording panicked"))?;
            match next {
                None => {
                    let warning = self.pose_warning.lock().ok().and_then(|mut w| w.take());
                    if let Some(text) = warning {
                        PyErr::warn(
                            py,
                            &py.get_type::<PyUserWarning>(),
                            &std::ffi::CString::new(text).unwrap_or_default(),
                            1,
                        )?;
                    }
                    return Ok(None);
                }
                Some((s, Ok(frame))) => {
                    let (name, sensor) = &self.sensors[s.min(self.sensors.len() - 1)];
                    let d = frame_dict(py, &frame, sensor)?;
                    d.set_item("sensor", name)?;
                    return Ok(Some(d));
                }
                Some((_, Err(failure))) => {
                    if self.on_error == OnError::Stop {
                        return Err(PyValueError::new_err(failure.message));
                    }
                    self.skipped.lock().map_err(|_| PyRuntimeError::new_err("poisoned"))?.push(failure.message);
                    if failure.damage {
                        return Ok(None);
                    }
                }
            }
        }
    }
}

/// A frame as a dict of numpy arrays (see `edtmap.read_recording`).
fn frame_dict<'py>(py: Python<'py>, frame: &Frame, sensor: &Sensor) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("stamp", frame.stamp_s)?;
    let t = &frame.t_world_sensor;
    let q = t.rotation.quaternion();
    let v = t.translation.vector;
    d.set_item("pose", PyArray1::from_vec(py, vec![v.x, v.y, v.z, q.i, q.j, q.k, q.w]))?;
    let m: Vec<f64> = t.to_homogeneous().transpose().as_slice().to_vec();
    d.set_item("t_world_sensor", PyArray1::from_vec(py, m).reshape([4, 4])?)?;
    match &frame.measurement {
        Measurement::Depth(image) => {
            d.set_item("kind", "depth")?;
            let shape = [image.height as usize, image.width as usize];
            match &image.data {
                DepthData::Metres(values) => d.set_item("depth", PyArray1::from_slice(py, values).reshape(shape)?)?,
                DepthData::U16 { values, metres_per_unit } => {
                    d.set_item("depth", PyArray1::from_slice(py, values).reshape(shape)?)?;
                    d.set_item("depth_scale", *metres_per_unit)?;
                }
            }
        }
        Measurement::Lidar(scan) => {
            d.set_item("kind", "lidar")?;
            let (rings, bins) = match sensor {
                Sensor::Lidar(l) => (l.ring_elevations_rad.len(), l.azimuth_bins),
                _ => (1, scan.ranges.len()),
            };
            d.set_item("ranges", PyArray1::from_slice(py, &scan.ranges).reshape([rings, bins])?)?;
        }
        Measurement::Points(cloud) => {
            d.set_item("kind", "points")?;
            let flat: Vec<f32> = cloud.points.iter().flatten().copied().collect();
            d.set_item("points", PyArray1::from_vec(py, flat).reshape([cloud.points.len(), 3])?)?;
        }
        Measurement::Scan(scan) => {
            d.set_item("kind", "planar")?;
            d.set_item("ranges", PyArray1::from_slice(py, &scan.ranges))?;
            d.set_item("angle_min", scan.angle_min_rad)?;
            d.set_item("angle_increment", scan.angle_increment_rad)?;
            d.set_item("range_limits", (scan.range.min_m, scan.range.max_m))?;
        }
    }
    Ok(d)
}
