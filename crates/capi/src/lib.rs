//! The C ABI of edtmap: `include/edtmap.h` (generated from this file by
//! cbindgen; `tests/header.rs` checks that the committed header is current)
//! and the C++17 wrapper `include/edtmap.hpp` over it.
//!
//! # Conventions
//! - Every function that can fail returns an [`edtmap_status`];
//!   [`edtmap_last_error`] then gives the message, per thread (the last
//!   failed call *of the calling thread*).
//! - Handles are opaque: [`edtmap_mapper`] (a mapping pipeline) and
//!   [`edtmap_map`] (a saved map, for queries). Each `*_new`/`*_load` is
//!   paired with a `*_free`. There is no global state. The contract C
//!   callers rely on (ownership, what is undefined, threads, the error
//!   message's lifetime) opens the header: `cbindgen.toml`'s `header`.
//! - Pointers are checked: a null pointer is [`edtmap_status::EDTMAP_NULL_ARGUMENT`],
//!   a misaligned one or a length that does not fit
//!   [`edtmap_status::EDTMAP_INVALID_ARGUMENT`]. A buffer of 0 elements may
//!   be null (an empty `std::vector` has no address): an empty batch is an
//!   answer of size 0, and an empty frame goes to the mapper, which refuses
//!   it as [`edtmap_status::EDTMAP_FRAME`] (it observes nothing). Buffers
//!   are the caller's; a call never keeps a pointer after it returns.
//! - Enumerations and flags the caller passes (the `edtmap_params` fields
//!   `sensor`, `backend`, `exact`, `clear_no_return`; the `backend`
//!   argument) are taken as integers and checked: C lets them hold any
//!   value, and a Rust enum or `bool` holding one it does not have would be
//!   undefined behaviour. An out-of-range value is
//!   [`edtmap_status::EDTMAP_INVALID_ARGUMENT`], naming the field and the
//!   values it takes.
//! - No panic crosses the boundary: each entry point catches it and
//!   returns [`edtmap_status::EDTMAP_PANIC`].
//!
//! # Threads
//! Every function taking an `edtmap_mapper*` may be called from any
//! thread, concurrently with the others on the same mapper: frames are
//! integrated one at a time (a second caller waits), and queries
//! ([`edtmap_mapper_query`], [`edtmap_mapper_export_box`],
//! [`edtmap_mapper_save`]) never wait for a frame: they read the map as it
//! was after the last frame that finished. An [`edtmap_map`] is immutable:
//! any number of threads may query it. Only `*_free` must not run
//! concurrently with another call on the same handle.
#![allow(non_camel_case_types)]
#![allow(clippy::missing_safety_doc)]

use std::cell::RefCell;
use std::ffi::{c_char, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};

use edtmap::config::{CameraFields, Config, ConstructionName, LidarFields, SensorKind, SensorSection};
use edtmap::cpu::CpuBackend;
use edtmap::query;
use edtmap::sensor::Sensor;
use edtmap::sensor::{DepthData, DepthImage, Frame, LaserScan, LidarScan, Measurement, PointCloud, RangeLimits};
use edtmap::{
    BackendChoice, DynBackend, FrameStats, FrameThreads, GlobalMap, GlobalParams, IntegrationMode, MapError, Mapper,
    MapperParams, MapperSensor, PointState, SharedMapper, VolumeParams,
};
use rayon::prelude::*;

/// The outcome of a call.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum edtmap_status {
    /// It worked.
    EDTMAP_OK = 0,
    /// A required pointer (a handle, a buffer, a path) was null.
    EDTMAP_NULL_ARGUMENT = 1,
    /// An argument was out of range: a misaligned pointer, a length that
    /// does not fit, a non-finite pose, a string that is not UTF-8.
    EDTMAP_INVALID_ARGUMENT = 2,
    /// The configuration or the parameters were refused.
    EDTMAP_CONFIG = 3,
    /// The frame was refused (it does not fit the sensor, its pose is not
    /// rigid); the map is as it was.
    EDTMAP_FRAME = 4,
    /// A file could not be read or written, or is not a valid map.
    EDTMAP_IO = 5,
    /// The backend failed (no GPU adapter, a lost device); the frame was
    /// finished on the CPU and the map is whole.
    EDTMAP_BACKEND = 6,
    /// edtmap panicked (a bug): the handle should be freed.
    EDTMAP_PANIC = 7,
}

/// The sensor a mapper made by [`edtmap_mapper_new`] takes frames of: the
/// values of `edtmap_params.sensor`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum edtmap_sensor {
    /// Point clouds in the sensor frame ([`edtmap_integrate_points`]).
    EDTMAP_SENSOR_POINTS = 0,
    /// A pinhole depth camera ([`edtmap_integrate_depth`],
    /// [`edtmap_integrate_depth_u16`]).
    EDTMAP_SENSOR_DEPTH = 1,
    /// A spinning LiDAR with evenly spread rings
    /// ([`edtmap_integrate_range_image`]).
    EDTMAP_SENSOR_LIDAR = 2,
    /// A planar 2D LiDAR ([`edtmap_integrate_scan`]).
    EDTMAP_SENSOR_PLANAR = 3,
}

/// The device a mapper runs on: the values of `edtmap_params.backend` and
/// of the `backend` arguments.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum edtmap_backend {
    /// The CPU, all cores (rayon).
    EDTMAP_BACKEND_CPU = 0,
    /// A GPU through wgpu (a library built with the `gpu` feature).
    EDTMAP_BACKEND_GPU = 1,
    /// A hardware GPU if there is one, else the CPU.
    EDTMAP_BACKEND_AUTO = 2,
}

impl edtmap_sensor {
    /// Every value with its C name, in the order of their numbers from 0.
    const VALUES: [(Self, &'static str); 4] = [
        (Self::EDTMAP_SENSOR_POINTS, "EDTMAP_SENSOR_POINTS"),
        (Self::EDTMAP_SENSOR_DEPTH, "EDTMAP_SENSOR_DEPTH"),
        (Self::EDTMAP_SENSOR_LIDAR, "EDTMAP_SENSOR_LIDAR"),
        (Self::EDTMAP_SENSOR_PLANAR, "EDTMAP_SENSOR_PLANAR"),
    ];
}

impl edtmap_backend {
    /// Every value with its C name, in the order of their numbers from 0.
    const VALUES: [(Self, &'static str); 3] = [
        (Self::EDTMAP_BACKEND_CPU, "EDTMAP_BACKEND_CPU"),
        (Self::EDTMAP_BACKEND_GPU, "EDTMAP_BACKEND_GPU"),
        (Self::EDTMAP_BACKEND_AUTO, "EDTMAP_BACKEND_AUTO"),
    ];
}

/// Explicit parameters of a mapper ([`edtmap_mapper_new`]); fill them with
/// [`edtmap_params_default`] first, then set what differs. The fields are
/// the configuration file's (docs/CONFIG.md), with the same checks.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct edtmap_params {
    /// The sensor kind, an `edtmap_sensor` value (`EDTMAP_SENSOR_*`); any
    /// other number is refused with `EDTMAP_INVALID_ARGUMENT`.
    pub sensor: u32,
    /// The device, an `edtmap_backend` value (`EDTMAP_BACKEND_*`); any other
    /// number is refused likewise.
    pub backend: u32,
    /// Voxel edge, metres (`[occupancy] voxel_size_m`).
    pub voxel_size_m: f64,
    /// Local volume around the sensor, metres (`[occupancy] local_size_m`).
    pub local_size_m: [f64; 3],
    /// Cutoff of the global EDT, metres (`[global] max_distance_m`).
    pub max_distance_m: f64,
    /// Exact integration (1, the default) or the paper's wavefronts (0);
    /// any other value is refused with `EDTMAP_INVALID_ARGUMENT`.
    pub exact: u8,
    /// Shortest and longest valid return, metres.
    pub min_range_m: f32,
    /// See `min_range_m`.
    pub max_range_m: f32,
    /// Whether a beam with no return clears space up to `max_range_m` (1)
    /// or not (0); any other value is refused likewise.
    pub clear_no_return: u8,
    /// Depth camera: focal lengths and principal point, pixels.
    pub fx: f64,
    /// See `fx`.
    pub fy: f64,
    /// See `fx`.
    pub cx: f64,
    /// See `fx`.
    pub cy: f64,
    /// Depth camera: image size, pixels.
    pub width: u32,
    /// See `width`.
    pub height: u32,
    /// LiDAR: number of rings, evenly spread between the two elevations.
    pub rings: u32,
    /// LiDAR: elevation of the lowest ring, degrees.
    pub elevation_min_deg: f64,
    /// LiDAR: elevation of the highest ring, degrees.
    pub elevation_max_deg: f64,
    /// LiDAR: azimuth bins per turn.
    pub azimuth_bins: u32,
}

/// What one frame did ([`Mapper`]'s `FrameStats`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct edtmap_frame_stats {
    /// Occupancy (ray casting or projection, fusion), milliseconds.
    pub ogm_ms: f64,
    /// The window's batch EDT (wavefront mode), milliseconds.
    pub batch_edt_ms: f64,
    /// The global EDT's update, milliseconds.
    pub integrate_ms: f64,
    /// The whole frame, milliseconds.
    pub total_ms: f64,
    /// Voxels observed.
    pub voxels_updated: u64,
    /// Voxels whose state (unknown, free, occupied) changed.
    pub voxels_changed: u64,
    /// Blocks holding such a voxel.
    pub changed_blocks: u64,
    /// Voxels of the global EDT whose distance or obstacle changed.
    pub edt_voxels_changed: u64,
    /// Blocks of the map (occupancy, EDT, fixed).
    pub map_blocks: u64,
    /// Bytes of the map.
    pub map_bytes: u64,
}

/// A dense box's shape ([`edtmap_mapper_export_box`]).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct edtmap_box {
    /// Voxels along x, y, z; element (x, y, z) is at x + nx (y + ny z).
    pub dims: [u64; 3],
    /// World voxel index of element (0, 0, 0).
    pub origin: [i32; 3],
    /// Voxel edge, metres.
    pub voxel_size_m: f64,
}

/// State codes written by the queries: no block there (or not a finite
/// point).
pub const EDTMAP_STATE_OUTSIDE: u8 = 0;
/// In a mapped block, never observed.
pub const EDTMAP_STATE_UNKNOWN: u8 = 1;
/// Observed free.
pub const EDTMAP_STATE_FREE: u8 = 2;
/// Observed occupied, or a fixed obstacle.
pub const EDTMAP_STATE_OCCUPIED: u8 = 3;

/// A mapping pipeline: its mapper and the snapshot queries read.
pub struct edtmap_mapper {
    /// The mapper, shared by the handles of its sensors.
    shared: Arc<SharedMapper<DynBackend>>,
    /// The sensor this handle's frames come from (its index).
    sensor: usize,
    /// Per sensor, a planar LiDAR's range limits (its section's min and
    /// max range), shared by the handles.
    scan_ranges: Arc<Mutex<Vec<RangeLimits>>>,
    /// The threads each frame runs on (as many as cores are free), shared
    /// by the handles.
    threads: Arc<Mutex<FrameThreads>>,
}

impl edtmap_mapper {
    /// A handle for sensor `sensor` of the same mapper.
    fn for_sensor(&self, sensor: usize) -> edtmap_mapper {
        edtmap_mapper {
            shared: Arc::clone(&self.shared),
            sensor,
            scan_ranges: Arc::clone(&self.scan_ranges),
            threads: Arc::clone(&self.threads),
        }
    }

    /// This handle's sensor's scan range limits.
    fn scan_range(&self) -> Result<RangeLimits> {
        let ranges = self
            .scan_ranges
            .lock()
            .or_else(|_| fail(edtmap_status::EDTMAP_PANIC, "a thread panicked while it held the sensor list"))?;
        Ok(ranges.get(self.sensor).copied().unwrap_or(RangeLimits { min_m: 0.0, max_m: f32::MAX }))
    }
}

/// A saved map, loaded for queries.
pub struct edtmap_map {
    map: Arc<GlobalMap>,
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

/// An error: its status and message.
struct Failure(edtmap_status, String);

type Result<T> = std::result::Result<T, Failure>;

fn fail<T>(status: edtmap_status, message: impl Into<String>) -> Result<T> {
    Err(Failure(status, message.into()))
}

impl From<MapError> for Failure {
    fn from(e: MapError) -> Self {
        let status = match &e {
            MapError::Io(_) => edtmap_status::EDTMAP_IO,
            MapError::ConfigFile { .. } | MapError::Config { .. } => edtmap_status::EDTMAP_CONFIG,
            MapError::Backend(_) => edtmap_status::EDTMAP_BACKEND,
            MapError::Poisoned(_) => edtmap_status::EDTMAP_PANIC,
            _ if e.is_backend_failure() => edtmap_status::EDTMAP_BACKEND,
            _ => edtmap_status::EDTMAP_FRAME,
        };
        Failure(status, e.to_string())
    }
}

/// Runs `f`, turning its failure or panic into a status and the thread's
/// last error; `what` names the function in the message.
fn guard(what: &str, f: impl FnOnce() -> Result<()>) -> edtmap_status {
    let outcome = catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|panic| {
        let why = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Err(Failure(edtmap_status::EDTMAP_PANIC, format!("edtmap panicked (a bug; please report it): {why}")))
    });
    match outcome {
        Ok(()) => edtmap_status::EDTMAP_OK,
        Err(Failure(status, message)) => {
            let text = CString::new(format!("{what}: {message}").replace('\0', " ")).unwrap_or_default();
            LAST_ERROR.with(|e| *e.borrow_mut() = text);
            status
        }
    }
}

/// A shared reference from a handle pointer.
unsafe fn handle<'a, T>(ptr: *const T, name: &str) -> Result<&'a T> {
    // SAFETY: the caller passes a pointer it got from this library (or null).
    unsafe { ptr.as_ref() }.map_or_else(|| fail(edtmap_status::EDTMAP_NULL_ARGUMENT, format!("{name} is null")), Ok)
}

/// A slice of `len` `T` at `ptr`, checked for null (allowed when `len` is
/// 0), alignment and size.
unsafe fn slice<'a, T>(ptr: *const T, len: usize, name: &str) -> Result<&'a [T]> {
    check_ptr(ptr, len, name)?;
    if len == 0 {
        return Ok(&[]);
    }
    // SAFETY: non-null, aligned, and the caller promises `len` elements.
    Ok(unsafe { std::slice::from_raw_parts(ptr, len) })
}

/// A mutable slice of `len` `T` at `ptr`, checked likewise.
unsafe fn slice_mut<'a, T>(ptr: *mut T, len: usize, name: &str) -> Result<&'a mut [T]> {
    check_ptr(ptr, len, name)?;
    if len == 0 {
        return Ok(&mut []);
    }
    // SAFETY: as in `slice`, and the caller gives the buffer to this call.
    Ok(unsafe { std::slice::from_raw_parts_mut(ptr, len) })
}

/// Null is refused unless `len` is 0: an empty buffer may have no address
/// (`std::vector::data()` of an empty vector).
fn check_ptr<T>(ptr: *const T, len: usize, name: &str) -> Result<()> {
    if ptr.is_null() {
        return match len {
            0 => Ok(()),
            _ => fail(edtmap_status::EDTMAP_NULL_ARGUMENT, format!("{name} is null")),
        };
    }
    if !(ptr as usize).is_multiple_of(std::mem::align_of::<T>()) {
        return fail(
            edtmap_status::EDTMAP_INVALID_ARGUMENT,
            format!("{name} is not aligned to {} bytes", std::mem::align_of::<T>()),
        );
    }
    if len.checked_mul(std::mem::size_of::<T>()).is_none_or(|b| b > isize::MAX as usize) {
        return fail(
            edtmap_status::EDTMAP_INVALID_ARGUMENT,
            format!("{name}: {len} elements is more than memory holds"),
        );
    }
    Ok(())
}

/// A UTF-8 path from a C string.
unsafe fn path<'a>(ptr: *const c_char, name: &str) -> Result<&'a Path> {
    // SAFETY: as the caller of `path` passes it.
    Ok(Path::new(unsafe { text(ptr, name) }?))
}

/// UTF-8 text from a C string.
unsafe fn text<'a>(ptr: *const c_char, name: &str) -> Result<&'a str> {
    if ptr.is_null() {
        return fail(edtmap_status::EDTMAP_NULL_ARGUMENT, format!("{name} is null"));
    }
    // SAFETY: the caller passes a NUL-terminated string.
    unsafe { CStr::from_ptr(ptr) }
        .to_str()
        .or_else(|_| fail(edtmap_status::EDTMAP_INVALID_ARGUMENT, format!("{name} is not UTF-8")))
}

/// Writes `value` through `out`, checked for null.
unsafe fn put<T>(out: *mut T, value: T, name: &str) -> Result<()> {
    if out.is_null() {
        return fail(edtmap_status::EDTMAP_NULL_ARGUMENT, format!("{name} is null"));
    }
    // SAFETY: non-null, and the caller passes a writable `T`.
    unsafe { out.write(value) };
    Ok(())
}

/// Refuses a null out-pointer of a constructor before anything is built
/// (a handle built and then dropped on the floor would leak).
fn check_out<T>(out: *mut *mut T) -> Result<()> {
    match out.is_null() {
        true => fail(edtmap_status::EDTMAP_NULL_ARGUMENT, "out is null"),
        false => Ok(()),
    }
}

/// The value numbered `raw` of an enumeration (`values`: its variants with
/// their C names, numbered from 0), or an error naming `field` and the
/// values it takes.
fn enum_value<T: Copy>(field: &str, raw: u32, values: &[(T, &str)]) -> Result<T> {
    match values.get(raw as usize) {
        Some((value, _)) => Ok(*value),
        None => {
            let accepted: Vec<String> =
                values.iter().enumerate().map(|(i, (_, name))| format!("{name} ({i})")).collect();
            fail(
                edtmap_status::EDTMAP_INVALID_ARGUMENT,
                format!("{field} = {raw}: must be one of {}", accepted.join(", ")),
            )
        }
    }
}

/// A flag byte: 0 is false, 1 true, anything else an error naming `field`.
fn flag(field: &str, raw: u8) -> Result<bool> {
    match raw {
        0 => Ok(false),
        1 => Ok(true),
        _ => fail(edtmap_status::EDTMAP_INVALID_ARGUMENT, format!("{field} = {raw}: must be 0 (false) or 1 (true)")),
    }
}

/// The backend `b` names ([`edtmap::open_backend`]); a planar map's is the
/// CPU.
fn open_backend(b: edtmap_backend, planar: bool) -> Result<DynBackend> {
    let choice = match b {
        edtmap_backend::EDTMAP_BACKEND_CPU => BackendChoice::Cpu,
        edtmap_backend::EDTMAP_BACKEND_GPU => BackendChoice::Gpu,
        edtmap_backend::EDTMAP_BACKEND_AUTO => BackendChoice::Auto,
    };
    match edtmap::open_backend(choice, CpuBackend::default(), planar) {
        Ok(opened) => Ok(opened.backend),
        Err(MapError::NoGpuBackend) => fail(
            edtmap_status::EDTMAP_BACKEND,
            "this build of libedtmap_c has no GPU backend; build it with the `gpu` feature (cmake -DEDTMAP_GPU=ON)",
        ),
        Err(e) => fail(edtmap_status::EDTMAP_BACKEND, e.to_string()),
    }
}

fn mapper_from(config: &Config, backend: edtmap_backend, map: Option<GlobalMap>) -> Result<Box<edtmap_mapper>> {
    let (sensor, params) = config.mapper_params()?;
    let range = |s: &edtmap::config::SensorSection| RangeLimits { min_m: s.min_range_m, max_m: s.max_range_m };
    let m = mapper_on(sensor, params, range(&config.sensor), backend, map)?;
    config.add_sensors_to(&mut *m.shared.lock()?)?;
    let mut ranges = m
        .scan_ranges
        .lock()
        .or_else(|_| fail(edtmap_status::EDTMAP_PANIC, "a thread panicked while it held the sensor list"))?;
    ranges.extend(config.other_sensors.iter().map(range));
    drop(ranges);
    Ok(m)
}

fn mapper_on(
    sensor: Sensor,
    params: MapperParams,
    scan_range: RangeLimits,
    backend: edtmap_backend,
    map: Option<GlobalMap>,
) -> Result<Box<edtmap_mapper>> {
    let backend = open_backend(backend, params.global.planar)?;
    let mapper = match map {
        Some(map) => Mapper::with_map_on(backend, sensor, params, map),
        None => Mapper::new_on(backend, sensor, params),
    }?;
    let shared = Arc::new(SharedMapper::new(mapper));
    Ok(Box::new(edtmap_mapper {
        shared,
        sensor: 0,
        scan_ranges: Arc::new(Mutex::new(vec![scan_range])),
        threads: Arc::new(Mutex::new(FrameThreads::new())),
    }))
}

/// A parameter of `edtmap_params` that is out of its range, named as the
/// struct's field (`edtmap_params.fx = 0: must be ...`).
fn param_failure(e: MapError) -> Failure {
    match e {
        MapError::Config { source: edtmap::CoreError::InvalidParam { field, value, reason }, .. } => {
            Failure(edtmap_status::EDTMAP_CONFIG, format!("edtmap_params.{field} = {value}: {reason}"))
        }
        other => other.into(),
    }
}

/// The sensor and mapper parameters `p` stands for, checked as a
/// configuration file's are (`SensorSection::checked`,
/// `MapperParams::validate`), with the range of a planar sensor's scans.
fn params_of(p: &edtmap_params) -> Result<(Sensor, MapperParams, RangeLimits)> {
    let kind = enum_value("edtmap_params.sensor", p.sensor, &edtmap_sensor::VALUES)?;
    let exact = flag("edtmap_params.exact", p.exact)?;
    let clear_no_return = flag("edtmap_params.clear_no_return", p.clear_no_return)?;
    let (kind, lidar, camera) = match kind {
        edtmap_sensor::EDTMAP_SENSOR_POINTS => (SensorKind::Points, LidarFields::default(), CameraFields::default()),
        edtmap_sensor::EDTMAP_SENSOR_PLANAR => (SensorKind::Planar, LidarFields::default(), CameraFields::default()),
        edtmap_sensor::EDTMAP_SENSOR_DEPTH => {
            let camera = CameraFields {
                fx: Some(p.fx),
                fy: Some(p.fy),
                cx: Some(p.cx),
                cy: Some(p.cy),
                width: Some(p.width),
                height: Some(p.height),
            };
            (SensorKind::Depth, LidarFields::default(), camera)
        }
        edtmap_sensor::EDTMAP_SENSOR_LIDAR => {
            let lidar = LidarFields {
                rings: Some(p.rings as usize),
                elevation_min_deg: Some(p.elevation_min_deg),
                elevation_max_deg: Some(p.elevation_max_deg),
                ring_elevations_deg: None,
                azimuth_bins: Some(p.azimuth_bins as usize),
            };
            (SensorKind::Lidar, lidar, CameraFields::default())
        }
    };
    let section = SensorSection {
        name: None,
        sensor_in_body: None,
        topic: None,
        camera_info_topic: None,
        kind,
        construction: ConstructionName::Auto,
        clear_no_return,
        min_range_m: p.min_range_m,
        max_range_m: p.max_range_m,
        free_margin_m: None,
        planar_half_thickness_m: None,
        lidar,
        camera,
    };
    let in_sensor = |source| param_failure(MapError::Config { section: "sensor", source });
    let (sensor, ogm) = section.checked().map_err(in_sensor)?;
    let params = MapperParams {
        volume: VolumeParams { size_m: p.local_size_m, fixed_height_m: None },
        ogm,
        global: GlobalParams {
            max_distance_m: p.max_distance_m,
            mode: if exact { IntegrationMode::Exact } else { IntegrationMode::Wavefront },
            ..GlobalParams::default()
        },
        ..MapperParams::for_voxel_size(p.voxel_size_m)
    };
    params.validate().map_err(param_failure)?;
    Ok((sensor, params, RangeLimits { min_m: p.min_range_m, max_m: p.max_range_m }))
}

/// The library's version, e.g. `"0.1.0"` (static storage: never free it).
#[no_mangle]
pub extern "C" fn edtmap_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

/// The message of the calling thread's last failed call (empty if none):
/// the library's memory, never to be freed, valid until that thread's next
/// failed call or its exit.
#[no_mangle]
pub extern "C" fn edtmap_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

/// Fills `out` with the defaults: a point-cloud sensor (0.3–10 m), 0.1 m
/// voxels, a 10 × 10 × 4 m local volume, a 2 m cutoff, exact integration,
/// the CPU; a 640 × 480 camera (fx = fy = 525, centred), a 16-ring LiDAR
/// (±15°, 1800 bins) for when `sensor` is set to those.
#[no_mangle]
pub unsafe extern "C" fn edtmap_params_default(out: *mut edtmap_params) -> edtmap_status {
    guard("edtmap_params_default", || {
        let p = edtmap_params {
            sensor: edtmap_sensor::EDTMAP_SENSOR_POINTS as u32,
            backend: edtmap_backend::EDTMAP_BACKEND_CPU as u32,
            voxel_size_m: 0.1,
            local_size_m: [10.0, 10.0, 4.0],
            max_distance_m: 2.0,
            exact: 1,
            min_range_m: 0.3,
            max_range_m: 10.0,
            clear_no_return: 0,
            fx: 525.0,
            fy: 525.0,
            cx: 319.5,
            cy: 239.5,
            width: 640,
            height: 480,
            rings: 16,
            elevation_min_deg: -15.0,
            elevation_max_deg: 15.0,
            azimuth_bins: 1800,
        };
        // SAFETY: the caller passes a writable `edtmap_params`.
        unsafe { put(out, p, "out") }
    })
}

/// A mapper with the parameters `params` into `*out` (free it with
/// [`edtmap_mapper_free`]).
#[no_mangle]
pub unsafe extern "C" fn edtmap_mapper_new(
    params: *const edtmap_params,
    out: *mut *mut edtmap_mapper,
) -> edtmap_status {
    guard("edtmap_mapper_new", || {
        check_out(out)?;
        // SAFETY: the caller passes a valid `edtmap_params` or null.
        let p = unsafe { handle(params, "params") }?;
        let backend = enum_value("edtmap_params.backend", p.backend, &edtmap_backend::VALUES)?;
        let (sensor, params, scan_range) = params_of(p)?;
        let mapper = mapper_on(sensor, params, scan_range, backend, None)?;
        // SAFETY: the caller passes a writable pointer or null.
        unsafe { put(out, Box::into_raw(mapper), "out") }
    })
}

/// A mapper from the configuration file at `config_path` (the TOML of
/// `edtmap run --config`) on `backend` (an `edtmap_backend` value; any
/// other number is `EDTMAP_INVALID_ARGUMENT`) into `*out`.
#[no_mangle]
pub unsafe extern "C" fn edtmap_mapper_from_config(
    config_path: *const c_char,
    backend: u32,
    out: *mut *mut edtmap_mapper,
) -> edtmap_status {
    guard("edtmap_mapper_from_config", || {
        check_out(out)?;
        let backend = enum_value("backend", backend, &edtmap_backend::VALUES)?;
        // SAFETY: the caller passes a NUL-terminated string or null.
        let config = Config::load(unsafe { path(config_path, "config_path") }?)?;
        let mapper = mapper_from(&config, backend, None)?;
        // SAFETY: as in `edtmap_mapper_new`.
        unsafe { put(out, Box::into_raw(mapper), "out") }
    })
}

/// A mapper from the configuration file at `config_path`, continuing the
/// map saved at `map_path` (by [`edtmap_mapper_save`] or `edtmap run
/// --save`), into `*out`.
#[no_mangle]
pub unsafe extern "C" fn edtmap_mapper_resume(
    config_path: *const c_char,
    map_path: *const c_char,
    backend: u32,
    out: *mut *mut edtmap_mapper,
) -> edtmap_status {
    guard("edtmap_mapper_resume", || {
        check_out(out)?;
        let backend = enum_value("backend", backend, &edtmap_backend::VALUES)?;
        // SAFETY: as in `edtmap_mapper_from_config`.
        let config = Config::load(unsafe { path(config_path, "config_path") }?)?;
        // SAFETY: likewise.
        let map = edtmap::load_map(unsafe { path(map_path, "map_path") }?)?;
        let mapper = mapper_from(&config, backend, Some(map))?;
        // SAFETY: as in `edtmap_mapper_new`.
        unsafe { put(out, Box::into_raw(mapper), "out") }
    })
}

/// Adds a sensor to `mapper`'s map: `params`' sensor fields (`sensor`, its
/// intrinsics or rings, `min_range_m`, `max_range_m`, `construction`,
/// `clear_no_return`; the map's fields are the mapper's and are ignored
/// here), named `name` (1 to 64 characters, unlike the others' names; the
/// first sensor is named after its kind). `*out` receives a handle whose
/// frames come from that sensor, fused into the same map, and whose
/// queries read the same map; each sensor's thread may integrate through
/// its own handle. Free it with [`edtmap_mapper_free`]: the map lives
/// while any of its handles does.
#[no_mangle]
pub unsafe extern "C" fn edtmap_mapper_add_sensor(
    mapper: *mut edtmap_mapper,
    params: *const edtmap_params,
    name: *const c_char,
    out: *mut *mut edtmap_mapper,
) -> edtmap_status {
    guard("edtmap_mapper_add_sensor", || {
        check_out(out)?;
        // SAFETY: the caller passes a mapper from this library or null.
        let m = unsafe { handle(mapper, "mapper") }?;
        // SAFETY: the caller passes a valid `edtmap_params` or null.
        let p = unsafe { handle(params, "params") }?;
        // SAFETY: the caller passes a NUL-terminated string or null.
        let name = unsafe { text(name, "name") }?.to_string();
        let (sensor, params, scan_range) = params_of(p)?;
        let sensor = MapperSensor { name, sensor, ogm: params.ogm };
        let mut ranges = m
            .scan_ranges
            .lock()
            .or_else(|_| fail(edtmap_status::EDTMAP_PANIC, "a thread panicked while it held the sensor list"))?;
        let index = m.shared.lock()?.add_sensor(sensor)?;
        ranges.push(scan_range);
        drop(ranges);
        // SAFETY: the caller passes a writable pointer or null.
        unsafe { put(out, Box::into_raw(Box::new(m.for_sensor(index))), "out") }
    })
}

/// A handle of `mapper`'s sensor named `name` (a config's `[[sensors]]`
/// entry, or one [`edtmap_mapper_add_sensor`] added) into `*out`, as that
/// function gives; `EDTMAP_INVALID_ARGUMENT` naming the sensors when there
/// is none of that name.
#[no_mangle]
pub unsafe extern "C" fn edtmap_mapper_sensor(
    mapper: *mut edtmap_mapper,
    name: *const c_char,
    out: *mut *mut edtmap_mapper,
) -> edtmap_status {
    guard("edtmap_mapper_sensor", || {
        check_out(out)?;
        // SAFETY: the caller passes a mapper from this library or null.
        let m = unsafe { handle(mapper, "mapper") }?;
        // SAFETY: the caller passes a NUL-terminated string or null.
        let name = unsafe { text(name, "name") }?;
        let names: Vec<String> = m.shared.lock()?.sensors().iter().map(|s| s.name.clone()).collect();
        let Some(index) = names.iter().position(|n| n == name) else {
            let known = names.join(", ");
            return fail(edtmap_status::EDTMAP_INVALID_ARGUMENT, format!("name = {name:?}: the sensors are {known}"));
        };
        // SAFETY: the caller passes a writable pointer or null.
        unsafe { put(out, Box::into_raw(Box::new(m.for_sensor(index))), "out") }
    })
}

/// Frees a mapper or a sensor's handle (null is allowed and does nothing).
/// No other call on it may be running or start after this one; freeing it
/// twice is undefined.
#[no_mangle]
pub unsafe extern "C" fn edtmap_mapper_free(mapper: *mut edtmap_mapper) {
    if !mapper.is_null() {
        // SAFETY: the pointer came from `Box::into_raw` in this library and
        // is freed once, as the header documents.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(mapper) })));
    }
}

/// A pose from a row-major 4 × 4 rigid transform.
unsafe fn pose(t_world_sensor: *const f64) -> Result<nalgebra::Isometry3<f64>> {
    // SAFETY: the caller passes 16 doubles or null.
    let v = unsafe { slice(t_world_sensor, 16, "t_world_sensor") }?;
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        return fail(
            edtmap_status::EDTMAP_INVALID_ARGUMENT,
            format!("t_world_sensor holds {x}; every value must be finite"),
        );
    }
    let mut m = [[0.0; 4]; 4];
    for (r, row) in m.iter_mut().enumerate() {
        row.copy_from_slice(&v[4 * r..4 * r + 4]);
    }
    edtmap::sensor::pose_from_matrix(&m)
        .or_else(|e| fail(edtmap_status::EDTMAP_INVALID_ARGUMENT, format!("t_world_sensor: {e}")))
}

/// Integrates a frame and fills `stats` when it is not null.
unsafe fn integrate(
    mapper: *const edtmap_mapper,
    t_world_sensor: *const f64,
    stamp_s: f64,
    stats: *mut edtmap_frame_stats,
    measurement: impl FnOnce(&edtmap_mapper) -> Result<Measurement>,
) -> Result<()> {
    // SAFETY: the caller passes a mapper from this library or null.
    let m = unsafe { handle(mapper, "mapper") }?;
    // SAFETY: as in `pose`.
    let t_world_sensor = unsafe { pose(t_world_sensor) }?;
    let frame = Frame { stamp_s, t_world_sensor, measurement: measurement(m)? };
    // On a thread of rayon's pool, where the stages' parallel loops start
    // at once instead of being handed over one by one, and on as many
    // threads as cores are free.
    let mut threads = m.threads.lock().unwrap_or_else(PoisonError::into_inner);
    let s: FrameStats = threads.run(|| m.shared.integrate_sensor(m.sensor, &frame))?;
    drop(threads);
    if !stats.is_null() {
        let out = edtmap_frame_stats {
            ogm_ms: s.ogm_ms,
            batch_edt_ms: s.batch_edt_ms,
            integrate_ms: s.integrate_ms,
            total_ms: s.total_ms,
            voxels_updated: s.voxels_updated as u64,
            voxels_changed: s.voxels_changed as u64,
            changed_blocks: s.changed_blocks.len() as u64,
            edt_voxels_changed: s.edt_voxels_changed as u64,
            map_blocks: s.map_blocks as u64,
            map_bytes: s.map_bytes as u64,
        };
        // SAFETY: non-null; the caller passes a writable stats struct.
        unsafe { put(stats, out, "stats") }?;
    }
    Ok(())
}

/// Integrates a point cloud: `n_points` points, `xyz` holding x, y, z of
/// each in the sensor frame (metres), seen from the pose `t_world_sensor`
/// (16 doubles, a row-major 4 × 4 rigid transform) at `stamp_s` seconds.
/// `stats` may be null. A cloud of no points (`xyz` may then be null)
/// observes nothing: the mapper refuses it with `EDTMAP_FRAME`, as it
/// refuses every empty frame, and the map is as it was.
#[no_mangle]
pub unsafe extern "C" fn edtmap_integrate_points(
    mapper: *mut edtmap_mapper,
    xyz: *const f32,
    n_points: usize,
    t_world_sensor: *const f64,
    stamp_s: f64,
    stats: *mut edtmap_frame_stats,
) -> edtmap_status {
    guard("edtmap_integrate_points", || {
        let len = n_points
            .checked_mul(3)
            .ok_or(Failure(edtmap_status::EDTMAP_INVALID_ARGUMENT, format!("n_points = {n_points} is too many")))?;
        // SAFETY: the caller passes 3 n_points floats.
        let values = unsafe { slice(xyz, len, "xyz") }?;
        let points = values.as_chunks::<3>().0.to_vec();
        // SAFETY: the pointers are checked in `integrate`.
        unsafe { integrate(mapper, t_world_sensor, stamp_s, stats, |_| Ok(Measurement::Points(PointCloud { points }))) }
    })
}

/// Integrates a depth image in metres (`width × height` floats, row by row;
/// 0 or NaN for no return). The camera is the mapper's.
#[no_mangle]
pub unsafe extern "C" fn edtmap_integrate_depth(
    mapper: *mut edtmap_mapper,
    depth_m: *const f32,
    width: u32,
    height: u32,
    t_world_sensor: *const f64,
    stamp_s: f64,
    stats: *mut edtmap_frame_stats,
) -> edtmap_status {
    guard("edtmap_integrate_depth", || {
        let n = width as usize * height as usize;
        // SAFETY: the caller passes width × height floats.
        let values = unsafe { slice(depth_m, n, "depth_m") }?.to_vec();
        let image = DepthImage { width, height, data: DepthData::Metres(values) };
        // SAFETY: as in `edtmap_integrate_points`.
        unsafe { integrate(mapper, t_world_sensor, stamp_s, stats, |_| Ok(Measurement::Depth(image))) }
    })
}

/// Integrates a 16-bit depth image (`width × height` values, row by row;
/// 0 for no return), each value times `metres_per_unit` metres (0.001
/// for millimetres).
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn edtmap_integrate_depth_u16(
    mapper: *mut edtmap_mapper,
    depth: *const u16,
    width: u32,
    height: u32,
    metres_per_unit: f32,
    t_world_sensor: *const f64,
    stamp_s: f64,
    stats: *mut edtmap_frame_stats,
) -> edtmap_status {
    guard("edtmap_integrate_depth_u16", || {
        if !(metres_per_unit.is_finite() && metres_per_unit > 0.0) {
            return fail(
                edtmap_status::EDTMAP_INVALID_ARGUMENT,
                format!("metres_per_unit = {metres_per_unit}; it must be a positive number"),
            );
        }
        let n = width as usize * height as usize;
        // SAFETY: the caller passes width × height values.
        let values = unsafe { slice(depth, n, "depth") }?.to_vec();
        let image = DepthImage { width, height, data: DepthData::U16 { values, metres_per_unit } };
        // SAFETY: as in `edtmap_integrate_points`.
        unsafe { integrate(mapper, t_world_sensor, stamp_s, stats, |_| Ok(Measurement::Depth(image))) }
    })
}

/// Integrates a planar scan: `n` ranges (metres; NaN, infinity or out of
/// the mapper's range for no return), beam i at `angle_min_rad + i ·
/// angle_increment_rad` in the sensor's x-y plane.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn edtmap_integrate_scan(
    mapper: *mut edtmap_mapper,
    ranges: *const f32,
    n: usize,
    angle_min_rad: f64,
    angle_increment_rad: f64,
    t_world_sensor: *const f64,
    stamp_s: f64,
    stats: *mut edtmap_frame_stats,
) -> edtmap_status {
    guard("edtmap_integrate_scan", || {
        // SAFETY: the caller passes n floats.
        let ranges = unsafe { slice(ranges, n, "ranges") }?.to_vec();
        // SAFETY: as in `edtmap_integrate_points`.
        unsafe {
            integrate(mapper, t_world_sensor, stamp_s, stats, |m| {
                let range = m.scan_range()?;
                Ok(Measurement::Scan(LaserScan { angle_min_rad, angle_increment_rad, ranges, range }))
            })
        }
    })
}

/// Integrates a spinning LiDAR's range image: `n` = rings × azimuth bins
/// ranges (metres), ring by ring from the lowest, bins from azimuth −π.
#[no_mangle]
pub unsafe extern "C" fn edtmap_integrate_range_image(
    mapper: *mut edtmap_mapper,
    ranges: *const f32,
    n: usize,
    t_world_sensor: *const f64,
    stamp_s: f64,
    stats: *mut edtmap_frame_stats,
) -> edtmap_status {
    guard("edtmap_integrate_range_image", || {
        // SAFETY: the caller passes n floats.
        let ranges = unsafe { slice(ranges, n, "ranges") }?.to_vec();
        // SAFETY: as in `edtmap_integrate_points`.
        unsafe { integrate(mapper, t_world_sensor, stamp_s, stats, |_| Ok(Measurement::Lidar(LidarScan { ranges }))) }
    })
}

/// Most points per parallel task of a batched query; a small batch is
/// split into about four tasks per thread, at least 64 points each.
const QUERY_CHUNK: usize = 4096;

fn state_code(s: PointState) -> u8 {
    match s {
        PointState::Outside => EDTMAP_STATE_OUTSIDE,
        PointState::Unknown => EDTMAP_STATE_UNKNOWN,
        PointState::Free => EDTMAP_STATE_FREE,
        PointState::Occupied => EDTMAP_STATE_OCCUPIED,
    }
}

/// Distances (and gradients and states where those buffers are not null)
/// of `n` points of `map`, in parallel.
#[allow(clippy::too_many_arguments)]
unsafe fn query_into(
    map: &GlobalMap,
    points: *const f64,
    n: usize,
    signed: bool,
    distances: *mut f64,
    gradients: *mut f64,
    states: *mut u8,
) -> Result<()> {
    let len3 =
        n.checked_mul(3).ok_or(Failure(edtmap_status::EDTMAP_INVALID_ARGUMENT, format!("n = {n} is too many")))?;
    // SAFETY: the caller passes 3 n doubles.
    let pts = unsafe { slice(points, len3, "points") }?.as_chunks::<3>().0;
    // SAFETY: the caller passes n doubles to write.
    let dist = unsafe { slice_mut(distances, n, "distances") }?;
    let mut grad = if gradients.is_null() {
        None
    } else {
        // SAFETY: non-null; the caller passes 3 n doubles to write.
        Some(unsafe { slice_mut(gradients, len3, "gradients") }?)
    };
    let mut state = if states.is_null() {
        None
    } else {
        // SAFETY: non-null; the caller passes n bytes to write.
        Some(unsafe { slice_mut(states, n, "states") }?)
    };
    let chunk = n.div_ceil(rayon::current_num_threads()).clamp(64, QUERY_CHUNK);
    let grad_chunks = grad.as_mut().map(|g| g.par_chunks_mut(3 * chunk));
    let state_chunks = state.as_mut().map(|s| s.par_chunks_mut(chunk));
    let answer =
        |(pts, dist): (&[[f64; 3]], &mut [f64]), mut grad: Option<&mut [f64]>, mut state: Option<&mut [u8]>| {
            for (i, p) in pts.iter().enumerate() {
                let d = query::distance(map, *p, signed);
                dist[i] = d.distance_m;
                if let Some(g) = grad.as_deref_mut() {
                    g[3 * i..3 * i + 3].copy_from_slice(&d.gradient);
                }
                if let Some(s) = state.as_deref_mut() {
                    s[i] = state_code(d.state);
                }
            }
        };
    let base = pts.par_chunks(chunk).zip(dist.par_chunks_mut(chunk));
    match (grad_chunks, state_chunks) {
        (Some(g), Some(s)) => base.zip(g).zip(s).for_each(|((b, g), s)| answer(b, Some(g), Some(s))),
        (Some(g), None) => base.zip(g).for_each(|(b, g)| answer(b, Some(g), None)),
        (None, Some(s)) => base.zip(s).for_each(|(b, s)| answer(b, None, Some(s))),
        (None, None) => base.for_each(|b| answer(b, None, None)),
    }
    Ok(())
}

/// Distances (metres) to the nearest obstacle at `n` world points (`points`:
/// x, y, z of each), interpolated between voxel centres, into `distances`
/// (n doubles); their gradients into `gradients` (3 n doubles) and their
/// states (`EDTMAP_STATE_*`) into `states` (n bytes) unless those are null.
/// `signed`: negative inside obstacles. Saturated at the cutoff; NaN for a
/// point that is not finite. Reads the map as of the last finished frame.
/// `n` = 0 writes nothing and succeeds; the buffers may then be null.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn edtmap_mapper_query(
    mapper: *const edtmap_mapper,
    points: *const f64,
    n: usize,
    signed: bool,
    distances: *mut f64,
    gradients: *mut f64,
    states: *mut u8,
) -> edtmap_status {
    guard("edtmap_mapper_query", || {
        // SAFETY: a mapper from this library or null.
        let map = unsafe { handle(mapper, "mapper") }?.shared.snapshot();
        // SAFETY: the buffers as documented.
        unsafe { query_into(&map, points, n, signed, distances, gradients, states) }
    })
}

/// [`edtmap_mapper_query`] on a loaded map.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn edtmap_map_query(
    map: *const edtmap_map,
    points: *const f64,
    n: usize,
    signed: bool,
    distances: *mut f64,
    gradients: *mut f64,
    states: *mut u8,
) -> edtmap_status {
    guard("edtmap_map_query", || {
        // SAFETY: a map from this library or null.
        let m = unsafe { handle(map, "map") }?;
        // SAFETY: the buffers as documented.
        unsafe { query_into(&m.map, points, n, signed, distances, gradients, states) }
    })
}

/// The body of the two `export_box` functions.
#[allow(clippy::too_many_arguments)]
unsafe fn export_box(
    map: &GlobalMap,
    min_m: *const f64,
    max_m: *const f64,
    signed: bool,
    distances: *mut f32,
    states: *mut u8,
    capacity: usize,
    info: *mut edtmap_box,
) -> Result<()> {
    // SAFETY: the caller passes 3 doubles each.
    let (lo, hi) = unsafe { (slice(min_m, 3, "min_m")?, slice(max_m, 3, "max_m")?) };
    let dense = query::distance_box(map, [lo[0], lo[1], lo[2]], [hi[0], hi[1], hi[2]], signed)
        .or_else(|e| fail(edtmap_status::EDTMAP_INVALID_ARGUMENT, e.to_string()))?;
    let n = dense.distance_m.len();
    let shape =
        edtmap_box { dims: dense.dims.map(|d| d as u64), origin: dense.origin.0, voxel_size_m: map.voxel_size_m() };
    // SAFETY: the caller passes a writable `edtmap_box` or null.
    unsafe { put(info, shape, "info") }?;
    if distances.is_null() && states.is_null() {
        return Ok(());
    }
    if capacity < n {
        return fail(
            edtmap_status::EDTMAP_INVALID_ARGUMENT,
            format!("capacity {capacity} is less than the box's {n} voxels"),
        );
    }
    // SAFETY: the caller passes `capacity` elements each.
    unsafe { slice_mut(distances, n, "distances") }?.copy_from_slice(&dense.distance_m);
    // SAFETY: likewise.
    unsafe { slice_mut(states, n, "states") }?.copy_from_slice(&dense.state);
    Ok(())
}

/// [`edtmap_map_export_box`] on the mapper's map as of the last finished
/// frame.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn edtmap_mapper_export_box(
    mapper: *const edtmap_mapper,
    min_m: *const f64,
    max_m: *const f64,
    signed: bool,
    distances: *mut f32,
    states: *mut u8,
    capacity: usize,
    info: *mut edtmap_box,
) -> edtmap_status {
    guard("edtmap_mapper_export_box", || {
        // SAFETY: a mapper from this library or null.
        let map = unsafe { handle(mapper, "mapper") }?.shared.snapshot();
        // SAFETY: the buffers as documented.
        unsafe { export_box(&map, min_m, max_m, signed, distances, states, capacity, info) }
    })
}

/// A dense box of `map` from `min_m` to `max_m` (world metres): its shape
/// into `info`, and, unless `distances` and `states` are both null, the
/// distances (metres) and states (`EDTMAP_STATE_*`) of its voxel centres,
/// x fastest, into them (`capacity` elements each, at least the box's).
/// Call with null buffers first to learn the size.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn edtmap_map_export_box(
    map: *const edtmap_map,
    min_m: *const f64,
    max_m: *const f64,
    signed: bool,
    distances: *mut f32,
    states: *mut u8,
    capacity: usize,
    info: *mut edtmap_box,
) -> edtmap_status {
    guard("edtmap_map_export_box", || {
        // SAFETY: a map from this library or null.
        let m = unsafe { handle(map, "map") }?;
        // SAFETY: the buffers as documented.
        unsafe { export_box(&m.map, min_m, max_m, signed, distances, states, capacity, info) }
    })
}

/// Saves the mapper's map (as of the last finished frame) to `path`,
/// atomically (a temporary file renamed into place).
#[no_mangle]
pub unsafe extern "C" fn edtmap_mapper_save(mapper: *const edtmap_mapper, path_: *const c_char) -> edtmap_status {
    guard("edtmap_mapper_save", || {
        // SAFETY: a mapper from this library or null.
        let map = unsafe { handle(mapper, "mapper") }?.shared.snapshot();
        // SAFETY: a NUL-terminated string or null.
        edtmap::save_map(&map, unsafe { path(path_, "path") }?)?;
        Ok(())
    })
}

/// Loads the map saved at `path` (by [`edtmap_mapper_save`] or `edtmap run
/// --save`) into `*out`, for queries; free it with [`edtmap_map_free`].
#[no_mangle]
pub unsafe extern "C" fn edtmap_map_load(path_: *const c_char, out: *mut *mut edtmap_map) -> edtmap_status {
    guard("edtmap_map_load", || {
        check_out(out)?;
        // SAFETY: a NUL-terminated string or null.
        let map = edtmap::load_map(unsafe { path(path_, "path") }?)?;
        // SAFETY: a writable pointer or null.
        unsafe { put(out, Box::into_raw(Box::new(edtmap_map { map: Arc::new(map) })), "out") }
    })
}

/// Frees a loaded map (null is allowed and does nothing). No other call on
/// it may be running or start after this one; freeing it twice is
/// undefined.
#[no_mangle]
pub unsafe extern "C" fn edtmap_map_free(map: *mut edtmap_map) {
    if !map.is_null() {
        // SAFETY: from `Box::into_raw` in this library, freed once.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(map) })));
    }
}

/// The voxel edge of a loaded map, metres (0 for a null map).
#[no_mangle]
pub unsafe extern "C" fn edtmap_map_voxel_size(map: *const edtmap_map) -> f64 {
    // SAFETY: a map from this library or null.
    unsafe { map.as_ref() }.map_or(0.0, |m| m.map.voxel_size_m())
}

/// The cutoff of a loaded map's distances, metres (0 for a null map).
#[no_mangle]
pub unsafe extern "C" fn edtmap_map_max_distance(map: *const edtmap_map) -> f64 {
    // SAFETY: a map from this library or null.
    unsafe { map.as_ref() }.map_or(0.0, |m| m.map.params().max_distance_m)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two sensors' handles of one mapper fuse into one map, the map the
    /// same frames make through single-sensor mappers handing it on.
    #[test]
    fn sensor_handles_fuse_into_one_map() {
        let mut defaults = std::mem::MaybeUninit::<edtmap_params>::uninit();
        // SAFETY: a valid out-pointer to an `edtmap_params`.
        assert_eq!(unsafe { edtmap_params_default(defaults.as_mut_ptr()) }, edtmap_status::EDTMAP_OK);
        // SAFETY: `edtmap_params_default` filled it.
        let points_params = unsafe { defaults.assume_init() };
        let mut scan_params = points_params;
        scan_params.sensor = edtmap_sensor::EDTMAP_SENSOR_PLANAR as u32;
        let wall: Vec<f32> = (0..40).flat_map(|i| [2.05, -1.0 + 0.05 * i as f32, 0.05]).collect();
        let ranges: Vec<f32> = (0..360).map(|i| 1.5 + 0.3 * ((i as f32) * 0.05).sin()).collect();
        let pose: [f64; 16] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.5, 0.0, 0.0, 0.0, 1.0];
        let inc = std::f64::consts::TAU / 360.0;
        let (mut first, mut scan) = (std::ptr::null_mut(), std::ptr::null_mut());
        let name = CString::new("scan").expect("name");
        let dir = tempfile::tempdir().expect("tempdir");
        let path = CString::new(dir.path().join("both.edtmap").to_str().expect("utf-8")).expect("path");
        // SAFETY: valid pointers and lengths throughout; each handle freed once.
        unsafe {
            assert_eq!(edtmap_mapper_new(&points_params, &mut first), edtmap_status::EDTMAP_OK);
            assert_eq!(
                edtmap_mapper_add_sensor(first, &scan_params, name.as_ptr(), &mut scan),
                edtmap_status::EDTMAP_OK
            );
            let again = CString::new("points").expect("name");
            let mut same = std::ptr::null_mut();
            assert_eq!(edtmap_mapper_sensor(first, again.as_ptr(), &mut same), edtmap_status::EDTMAP_OK);
            let null = std::ptr::null_mut();
            assert_eq!(
                edtmap_integrate_points(same, wall.as_ptr(), 40, pose.as_ptr(), 0.0, null),
                edtmap_status::EDTMAP_OK
            );
            assert_eq!(
                edtmap_integrate_scan(scan, ranges.as_ptr(), 360, 0.0, inc, pose.as_ptr(), 0.1, null),
                edtmap_status::EDTMAP_OK
            );
            edtmap_mapper_free(same);
            edtmap_mapper_free(first);
            // The map lives while a handle does.
            assert_eq!(edtmap_mapper_save(scan, path.as_ptr()), edtmap_status::EDTMAP_OK);
            edtmap_mapper_free(scan);
        }
        let params = |p: &edtmap_params| params_of(p).unwrap_or_else(|Failure(_, m)| panic!("{m}"));
        let ((points, pp, _), (planar, sp, scan_range)) = (params(&points_params), params(&scan_params));
        let t = nalgebra::Isometry3::translation(0.0, 0.0, 0.5);
        let cloud = Measurement::Points(PointCloud { points: wall.as_chunks::<3>().0.to_vec() });
        let mut one = Mapper::new(points, pp).expect("mapper");
        one.integrate_frame(&Frame { stamp_s: 0.0, t_world_sensor: t, measurement: cloud }).expect("frame");
        let mut two = Mapper::with_map(planar, sp, one.into_map()).expect("mapper");
        let scan = LaserScan { angle_min_rad: 0.0, angle_increment_rad: inc, ranges, range: scan_range };
        two.integrate_frame(&Frame { stamp_s: 0.1, t_world_sensor: t, measurement: Measurement::Scan(scan) })
            .expect("frame");
        let oracle = dir.path().join("oracle.edtmap");
        edtmap::save_map(two.map(), &oracle).expect("save");
        let both = std::fs::read(dir.path().join("both.edtmap")).expect("read");
        assert!(both == std::fs::read(&oracle).expect("read"), "the two handles' map differs");

        // A config's [[sensors]] are the mapper's, each with its handle.
        let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/ugv_corridor_camera.toml");
        let config = CString::new(config.to_str().expect("utf-8")).expect("path");
        let (mut mapper, mut camera) = (std::ptr::null_mut(), std::ptr::null_mut());
        let (known, unknown) = (CString::new("front_camera").expect("name"), CString::new("sonar").expect("name"));
        // SAFETY: valid pointers; each handle freed once.
        unsafe {
            let cpu = edtmap_backend::EDTMAP_BACKEND_CPU as u32;
            assert_eq!(edtmap_mapper_from_config(config.as_ptr(), cpu, &mut mapper), edtmap_status::EDTMAP_OK);
            assert_eq!(edtmap_mapper_sensor(mapper, known.as_ptr(), &mut camera), edtmap_status::EDTMAP_OK);
            let mut none = std::ptr::null_mut();
            let status = edtmap_mapper_sensor(mapper, unknown.as_ptr(), &mut none);
            assert_eq!(status, edtmap_status::EDTMAP_INVALID_ARGUMENT);
            let message = CStr::from_ptr(edtmap_last_error()).to_string_lossy().into_owned();
            assert!(message.contains("lidar_top, front_camera"), "{message}");
            assert_eq!((*camera).sensor, 1);
            edtmap_mapper_free(camera);
            edtmap_mapper_free(mapper);
        }
    }

    /// `enum_value` finds a variant by its position: the tables must list
    /// the variants in the order of their numbers, from 0.
    #[test]
    fn value_tables_follow_the_discriminants() {
        for (i, (v, _)) in edtmap_sensor::VALUES.iter().enumerate() {
            assert_eq!(*v as usize, i);
        }
        for (i, (v, _)) in edtmap_backend::VALUES.iter().enumerate() {
            assert_eq!(*v as usize, i);
        }
    }

    #[test]
    fn out_of_range_values_name_the_field_and_the_values() {
        let Err(Failure(status, message)) = enum_value("edtmap_params.sensor", 42, &edtmap_sensor::VALUES) else {
            panic!("42 is no sensor")
        };
        assert_eq!(status, edtmap_status::EDTMAP_INVALID_ARGUMENT);
        assert!(
            message.contains("edtmap_params.sensor = 42") && message.contains("EDTMAP_SENSOR_PLANAR (3)"),
            "{message}"
        );
        let Err(Failure(_, message)) = flag("edtmap_params.exact", 0x7f) else { panic!("0x7f is no flag") };
        assert!(
            message.contains("edtmap_params.exact = 127") && message.contains("0 (false) or 1 (true)"),
            "{message}"
        );
        assert!(flag("f", 1).is_ok_and(|b| b) && flag("f", 0).is_ok_and(|b| !b));
    }

    /// The struct's numbers are checked as a configuration file's are, and
    /// a value out of range is named as the struct's field.
    #[test]
    fn parameters_out_of_range_name_the_struct_field() {
        let mut defaults = std::mem::MaybeUninit::<edtmap_params>::uninit();
        // SAFETY: a valid out-pointer to an `edtmap_params`.
        assert_eq!(unsafe { edtmap_params_default(defaults.as_mut_ptr()) }, edtmap_status::EDTMAP_OK);
        // SAFETY: `edtmap_params_default` filled it.
        let p = unsafe { defaults.assume_init() };
        let (sensor, params, _) = params_of(&p).unwrap_or_else(|Failure(_, m)| panic!("{m}"));
        assert!(matches!(sensor, Sensor::Points(_)));
        assert_eq!((params.voxel_size_m, params.global.max_distance_m), (p.voxel_size_m, p.max_distance_m));
        let refused = |edit: &dyn Fn(&mut edtmap_params)| {
            let mut q = p;
            edit(&mut q);
            match params_of(&q) {
                Err(Failure(status, message)) => (status, message),
                Ok(_) => panic!("accepted"),
            }
        };
        type Edit<'a> = &'a dyn Fn(&mut edtmap_params);
        let cases: [(Edit<'_>, &str); 6] = [
            (&|q| q.voxel_size_m = f64::NAN, "edtmap_params.voxel_size_m = NaN: must be finite"),
            (&|q| q.voxel_size_m = 20.0, "edtmap_params.voxel_size_m = 20.0: must be finite, in [1e-4, 10] metres"),
            (&|q| q.local_size_m[2] = 0.0, "edtmap_params.local_size_m = [10.0, 10.0, 0.0]"),
            (&|q| q.max_distance_m = -1.0, "edtmap_params.max_distance_m = -1.0"),
            (
                &|q| {
                    q.sensor = edtmap_sensor::EDTMAP_SENSOR_DEPTH as u32;
                    q.fx = 0.5;
                },
                "edtmap_params.fx = 0.5: must be finite, in [1, 1e6] pixels",
            ),
            (
                &|q| {
                    q.sensor = edtmap_sensor::EDTMAP_SENSOR_LIDAR as u32;
                    q.elevation_max_deg = 90.0;
                },
                "edtmap_params.elevation_max_deg = 90.0: must be finite, in (-90, 90) degrees",
            ),
        ];
        for (edit, want) in cases {
            let (status, message) = refused(edit);
            assert_eq!(status, edtmap_status::EDTMAP_CONFIG, "{message}");
            assert!(message.starts_with(want), "{message:?} should start with {want:?}");
        }
    }
}
