//! `edtmap run`: replays a built-in scene or a recording through the
//! mapping pipeline and writes `report.json` and pictures.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::sections::{self, Sections};
use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use edtmap::config::{Config, ConstructionName};
use edtmap::cpu::CpuBackend;
use edtmap::eval::{edt_errors, edt_extent, EdtErrors, OccupancyScores};
use edtmap::region::Region;
use edtmap::sensor::{Frame, Sensor};
use edtmap::stages::{Construction, OgmOptions};
use edtmap::{
    Connectivity, FrameStats, FrameThreads, IntegrationMode, LocalVolume, Mapper, MapperParams, MapperSensor,
    VoxelIndex, VoxelState,
};
use edtmap_ros::config::OnError;
use edtmap_sim::{Scene, SceneName};
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::Isometry3;
use serde_json::{json, Map};

use crate::backend::{self, BackendArg, CliMapper};
use crate::interrupt::{self, Interrupted, OnFirst};
use crate::pictures::{write_plys, write_slices, write_timing_plot, SliceHeight};
use crate::report::{median, write_report_file, FieldNames, FrameRecord};
use crate::scenes::builtin_config;
use crate::source::{check_kind, Failure, FailureKind, Source};

/// Arguments of `edtmap run`.
#[derive(Args, Debug, Clone)]
pub(crate) struct RunArgs {
    /// Built-in scene to replay: uav_pillars, ugv_corridor, room or planar.
    #[arg(long)]
    pub(crate) scene: Option<String>,
    /// Configuration file (TOML); default: the scene's own, as in configs/.
    #[arg(long)]
    pub(crate) config: Option<PathBuf>,
    /// Frames to replay (default: the config's, else the scene's or
    /// recording's length). A built-in scene's path repeats, so it runs as
    /// many frames as asked; a recording has the frames it has.
    #[arg(long)]
    pub(crate) frames: Option<usize>,
    /// Folder for report.json and the pictures.
    #[arg(long, default_value = "edtmap-out")]
    pub(crate) out: PathBuf,
    /// Score every frame: occupancy against a built-in scene's ground truth
    /// (recordings have none), the EDT against the exact EDT of the map.
    #[arg(long)]
    pub(crate) eval: bool,
    /// Override the config's [sensor] construction.
    #[arg(long, value_enum)]
    pub(crate) construction: Option<ConstructionArg>,
    /// Override the config's [occupancy] voxel_size_m (metres).
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    pub(crate) voxel_size: Option<f64>,
    /// Override the config's [global] mode: wavefront or exact.
    #[arg(long, value_enum)]
    pub(crate) integration: Option<IntegrationArg>,
    /// Override the config's [global] connectivity: 6, 18 or 26.
    #[arg(long)]
    pub(crate) connectivity: Option<u8>,
    /// A planar map ([global] planar = true): distances measured within
    /// each horizontal layer of voxels, none kept above or below the
    /// layers with obstacles. For planar LiDARs; needs the exact mode and
    /// the CPU backend.
    #[arg(long)]
    pub(crate) planar: bool,
    /// Map with these of the config's [[sensors]] only (their names, comma
    /// separated); default: every sensor.
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    pub(crate) sensors: Option<Vec<String>>,
    /// Save the final map (occupancy and global EDT) to this file.
    #[arg(long)]
    pub(crate) save: Option<PathBuf>,
    /// Start from a saved map whose obstacles stay obstacles (domain knowledge).
    #[arg(long)]
    pub(crate) prior: Option<PathBuf>,
    /// Compute backend: cpu, gpu, or auto (a hardware GPU if any, else cpu).
    #[arg(long, value_enum, default_value_t)]
    pub(crate) backend: BackendArg,
    /// Also write occupied.ply (occupied voxels) and edt.ply (the last local
    /// volume's EDT, coloured by distance).
    #[arg(long)]
    pub(crate) ply: bool,
    /// Height of the occupancy and EDT slices, metres, negative allowed
    /// (default: the config's [output] slice_height_m, else the layer of
    /// the last local volume with the most observed voxels).
    #[arg(long, value_name = "M", allow_negative_numbers = true, value_parser = finite_metres)]
    pub(crate) slice_height: Option<f64>,
    /// Replay a recording instead of a scene (needs --config): a folder of
    /// depth images (3DMatch, TUM RGB-D) or of point clouds (PCD, PLY,
    /// KITTI .bin) with their poses, a ROS 1 bag, or a ROS 2 MCAP file.
    #[arg(long, value_name = "PATH")]
    pub(crate) dataset: Option<PathBuf>,
    /// Run every frame on all of the thread pool's threads
    /// (`RAYON_NUM_THREADS`), even while other processes keep cores busy;
    /// by default a frame runs on as many threads as cores are left free.
    #[arg(long)]
    pub(crate) fixed_threads: bool,
}

/// Parses a height in metres: a finite number within a million metres.
fn finite_metres(text: &str) -> std::result::Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v.abs() <= 1e6 => Ok(v),
        Ok(v) => Err(format!("{v} is not a height: give finite metres within ±1e6")),
        Err(e) => Err(format!("{text:?} is not a number of metres: {e}")),
    }
}

/// Values of `--integration`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum IntegrationArg {
    /// The paper's raise and lower wavefronts.
    Wavefront,
    /// Exact recomputation of the region a frame can affect.
    Exact,
}

/// Values of `--construction`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ConstructionArg {
    /// Projection when the sensor model allows it, else ray casting.
    Auto,
    /// Volumetric projection.
    Projection,
    /// Ray casting.
    Raycast,
}

/// Loads the configuration the arguments name, with the CLI's sections
/// and its origin for messages.
fn load_config(args: &RunArgs) -> Result<(Config, Sections, String)> {
    let ((mut config, sections), origin) = match (&args.config, &args.scene) {
        (Some(path), _) => (sections::load(path)?, path.display().to_string()),
        (None, Some(scene)) => {
            let text = builtin_config(scene)
                .with_context(|| format!("unknown scene {scene:?}: choose one of {}", scene_names()))?;
            (
                sections::parse(text, &format!("built-in configs/{scene}.toml"))?,
                format!("configs/{scene}.toml (built in)"),
            )
        }
        (None, None) => bail!("give --scene NAME ({}) or --config FILE", scene_names()),
    };
    if let Some(c) = args.construction {
        let construction = match c {
            ConstructionArg::Auto => ConstructionName::Auto,
            ConstructionArg::Projection => ConstructionName::Projection,
            ConstructionArg::Raycast => ConstructionName::Raycast,
        };
        config.sensor.construction = construction;
        config.other_sensors.iter_mut().for_each(|s| s.construction = construction);
        config.mapper_sensors().context("--construction")?;
    }
    if let Some(v) = args.voxel_size {
        config.occupancy.voxel_size_m = v;
        config.mapper_params().context("--voxel-size")?;
    }
    if let Some(m) = args.integration {
        config.global.mode = match m {
            IntegrationArg::Wavefront => IntegrationMode::Wavefront,
            IntegrationArg::Exact => IntegrationMode::Exact,
        };
    }
    if let Some(c) = args.connectivity {
        config.global.connectivity = Connectivity::try_from(c).map_err(|e| anyhow::anyhow!("--connectivity: {e}"))?;
    }
    if args.planar {
        config.global.planar = true;
        config.mapper_params().context("--planar")?;
    }
    Ok((config, sections, origin))
}

fn scene_names() -> String {
    SceneName::ALL.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ")
}

/// What a finished run measured, for the demo's summary.
pub(crate) struct RunOutcome {
    pub(crate) frames: Vec<FrameRecord>,
    pub(crate) report_path: PathBuf,
    pub(crate) pictures: Vec<PathBuf>,
    /// The backend's name.
    pub(crate) backend: String,
    /// The signal that stopped the replay early, its outputs written.
    pub(crate) interrupted: Option<i32>,
    /// `--eval` of a scene: the final map against the ground truth.
    pub(crate) map_eval: Option<MapEval>,
}

/// The final map against a scene's ground truth at the last frame's time,
/// over the box of the map's occupancy blocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct MapEval {
    /// Voxels the map holds occupied where a solid is.
    pub(crate) true_occupied: usize,
    /// Voxels the map holds occupied where none is.
    pub(crate) false_occupied: usize,
    /// Voxels a solid meets that the map holds free or unknown.
    pub(crate) missed: usize,
}

/// Most voxels [`map_eval`] rasterises the ground truth over.
const MAP_EVAL_MAX_VOXELS: usize = 1 << 27;

/// The final map against `scene`'s ground truth at `t_s` (`None` for a map
/// with no blocks, or one whose box passes [`MAP_EVAL_MAX_VOXELS`]).
fn map_eval(scene: &Scene, mapper: &CliMapper, t_s: f64) -> Option<MapEval> {
    let (lo, hi) = mapper.map().occupancy().key_bounds()?;
    let side = edtmap::BLOCK_SIDE;
    let dims = [0, 1, 2].map(|k| ((hi[k] - lo[k] + 1) * side) as usize);
    if dims.iter().product::<usize>() > MAP_EVAL_MAX_VOXELS {
        return None;
    }
    let volume =
        LocalVolume { origin: VoxelIndex(lo.map(|k| k * side)), dims, voxel_size_m: mapper.params().voxel_size_m };
    let mut truth = Vec::new();
    scene.ground_truth(&volume, t_s, &mut truth);
    let mut eval = MapEval { true_occupied: 0, false_occupied: 0, missed: 0 };
    for (i, &solid) in truth.iter().enumerate() {
        let c = [i % dims[0], (i / dims[0]) % dims[1], i / (dims[0] * dims[1])];
        let v = VoxelIndex([0, 1, 2].map(|k| volume.origin.0[k] + c[k] as i32));
        match (mapper.state(v) == VoxelState::Occupied, solid) {
            (true, true) => eval.true_occupied += 1,
            (true, false) => eval.false_occupied += 1,
            (false, true) => eval.missed += 1,
            (false, false) => {}
        }
    }
    Some(eval)
}

/// Runs `edtmap run` and prints its summary.
pub(crate) fn run(args: &RunArgs) -> Result<()> {
    finish(&execute(args, true)?)
}

/// Prints a run's summary; a run stopped by a signal is then an
/// [`Interrupted`] error (the program exits with 128 + the signal).
pub(crate) fn finish(outcome: &RunOutcome) -> Result<()> {
    print_summary(outcome);
    match outcome.interrupted {
        Some(signal) => {
            let n = outcome.frames.len();
            let what = format!(
                "stopped after {n} integrated frame{}; the report, pictures and map of them are written",
                if n == 1 { "" } else { "s" }
            );
            Err(Interrupted { signal, what }.into())
        }
        None => Ok(()),
    }
}

/// Replays the scene; `progress` draws a progress bar on a terminal.
///
/// The steps, in order: set up (config, input, sensor, frame count), open
/// the mapper, check the outputs, replay, write the report (first: it says
/// why a run stopped even if a later output fails), then the map and
/// pictures, and last fail if the run stopped early.
pub(crate) fn execute(args: &RunArgs, progress: bool) -> Result<RunOutcome> {
    // Made first, so that the load is known by the first frames.
    let threads = if args.fixed_threads { FrameThreads::fixed() } else { FrameThreads::new() };
    let threads = threads.with_stack_size(crate::MAIN_STACK_BYTES);
    let setup = Setup::new(args)?;
    let mut mapper = open_mapper(args, &setup)?;
    prepare_out(args)?;
    let save_dir =
        args.save.as_deref().and_then(Path::parent).map(|d| if d.as_os_str().is_empty() { Path::new(".") } else { d });
    interrupt::catch(OnFirst::Finish, &[Some(args.out.as_path()), save_dir].into_iter().flatten().collect::<Vec<_>>());
    let replayed = replay(args, &setup, &mut mapper, threads, progress)?;
    if let Some(warning) = setup.source.pose_warning() {
        tracing::warn!("{warning}");
    }
    let slice = SliceHeight::choose(args.slice_height, setup.sections.output.slice_height_m, &mapper);
    let map_eval = match (&setup.source, replayed.records.last()) {
        (Source::Scene(scene), Some(last)) if args.eval => map_eval(scene, &mapper, last.stamp_s),
        _ => None,
    };
    let mut header = report_header(args, &setup, &mapper, &slice, &replayed);
    if let Some(e) = map_eval {
        let value = json!({"true_occupied_voxels": e.true_occupied, "false_occupied_voxels": e.false_occupied, "missed_voxels": e.missed});
        header.insert("map_eval".into(), value);
    }
    let report_path = args.out.join(REPORT);
    write_report_file(&report_path, &header, &replayed.records)?;
    if replayed.records.is_empty() {
        // Nothing to picture or save: an empty map must not replace a
        // good one, and a run that mapped nothing has failed.
        bail!("{}", nothing_integrated(&replayed.skipped, replayed.stopped.as_ref(), &report_path));
    }
    let pictures = write_outputs(args, &mapper, &slice, &replayed)?;
    check_stopped(args, &setup.sections, &replayed)?;
    Ok(RunOutcome {
        frames: replayed.records,
        report_path,
        pictures,
        backend: mapper.backend().name(),
        interrupted: replayed.interrupted,
        map_eval,
    })
}

/// What a run maps and with what, settled before the mapper is built.
struct Setup {
    /// The config's `[scene]`, `[output]`, `[dataset]`.
    sections: Sections,
    /// Where the config came from, for messages and the report.
    origin: String,
    source: Source,
    /// The scene's name or the recording's path.
    name: String,
    /// Every sensor, with its mount on the robot; the first is the
    /// mapper's own (its options are `params.ogm`).
    sensors: Vec<(MapperSensor, Isometry3<f64>)>,
    params: MapperParams,
    /// Frames to replay.
    frames: usize,
}

impl Setup {
    /// Loads the config, opens the scene or recording, and checks that the
    /// sensor fits the recording and the frame count fits both.
    fn new(args: &RunArgs) -> Result<Self> {
        let (mut config, sections, origin) = load_config(args)?;
        if let Some(names) = &args.sensors {
            config.keep_sensors(names).map_err(|e| anyhow::anyhow!("--sensors {}: {origin}: {e}", names.join(",")))?;
        }
        let (source, name, default_frames) = open_source(args, &mut config, &sections, &origin)?;
        if args.eval && !matches!(source, Source::Scene(_)) {
            tracing::warn!("--eval: {name} is a recording: {RECORDING_EVAL}");
        }
        let (_, mut params) = config.mapper_params()?;
        let sensors = config.mapper_sensors()?;
        params.ogm = sensors[0].0.ogm;
        if let Some(bytes) = crate::memory::max_bytes() {
            params.max_memory_bytes = Some(bytes);
        }
        if let (Some(path), 1) = (&args.dataset, sensors.len()) {
            check_kind(&source, &sensors[0].0.sensor, path, &origin)?;
        }
        let frames = frame_count(args, &name, default_frames)?;
        Ok(Setup { sections, origin, source, name, sensors, params, frames })
    }
}

/// The recording of `--dataset`, or else the scene of `--scene` or of the
/// config's `[scene]`; with its name and its number of frames.
fn open_source(
    args: &RunArgs,
    config: &mut Config,
    sections: &Sections,
    origin: &str,
) -> Result<(Source, String, usize)> {
    match &args.dataset {
        Some(path) => {
            let source = Source::open_recording(path, config, &sections.dataset, origin)?;
            let n = source.len().unwrap_or(0);
            Ok((source, path.display().to_string(), n))
        }
        None => {
            let name = args.scene.clone().or_else(|| sections.scene.as_ref().map(|s| s.name.clone()));
            let name =
                name.with_context(|| format!("{origin} has no [scene] section: give --scene NAME or --dataset PATH"))?;
            let (source, n) = Source::scene(&name, sections.scene.as_ref())?;
            Ok((source, name, n))
        }
    }
}

/// `--frames`, or the source's length; a recording has no more frames
/// than it holds.
fn frame_count(args: &RunArgs, name: &str, default_frames: usize) -> Result<usize> {
    let frames = args.frames.unwrap_or(default_frames);
    if frames == 0 {
        bail!("--frames must be at least 1");
    }
    if args.dataset.is_some() && frames > default_frames {
        bail!("--frames {frames}: {name} has {default_frames} frames");
    }
    Ok(frames)
}

/// The mapper on the chosen backend, with the `--prior` map added.
fn open_mapper(args: &RunArgs, setup: &Setup) -> Result<CliMapper> {
    let backend = backend::open_for(args.backend, CpuBackend::default(), setup.params.global.planar)?;
    let first = &setup.sensors[0].0;
    let mut mapper = Mapper::new_on(backend, first.sensor.clone(), setup.params.clone())?;
    mapper.rename_sensor(0, &first.name)?;
    for (sensor, _) in &setup.sensors[1..] {
        mapper.add_sensor(sensor.clone())?;
    }
    if let Some(path) = &args.prior {
        let prior = edtmap::load_map(path)?;
        mapper.add_prior(&prior).with_context(|| format!("prior map {}", path.display()))?;
    }
    Ok(mapper)
}

/// Creates `--out` and checks every output path before any frame.
fn prepare_out(args: &RunArgs) -> Result<()> {
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    check_outputs(args)
}

/// What the replay gave: a record per integrated frame, the frames
/// skipped, and the failure the run stopped at.
struct Replayed {
    records: Vec<FrameRecord>,
    /// The frames skipped, with their sensor's index.
    skipped: Vec<(usize, Failure)>,
    stopped: Option<Failure>,
    /// The signal (SIGINT, SIGTERM) that ended the replay before its last
    /// frame; the frame being integrated when it came was finished.
    interrupted: Option<i32>,
}

/// Integrates the frames one by one, skipping or stopping at a frame that
/// fails as `[dataset] on_error` says (a scene's failure always stops).
fn replay(
    args: &RunArgs,
    setup: &Setup,
    mapper: &mut CliMapper,
    mut threads: FrameThreads,
    progress: bool,
) -> Result<Replayed> {
    // A scene's time step gives a frame of each sensor; a recording's
    // frame count is its sensor messages'.
    let per_step = if matches!(setup.source, Source::Scene(_)) { setup.sensors.len() } else { 1 };
    let bar = progress_bar(setup.frames * per_step, progress);
    // Grows with the frames that come: --frames may be far more than a
    // recording or a soak run delivers.
    let mut out = Replayed { records: Vec::new(), skipped: Vec::new(), stopped: None, interrupted: None };
    let mut truth = (Vec::new(), Vec::new());
    let mut frames = setup.source.frames(&setup.sensors, setup.frames, &setup.name);
    let batch = batch_stage(setup, mapper);
    let sensor_names: Vec<Arc<str>> = mapper.sensors().iter().map(|s| Arc::from(s.name.as_str())).collect();
    let (mut names, mut pairs) = (FieldNames::default(), Vec::new());
    loop {
        if let Some(signal) = interrupt::requested() {
            out.interrupted = Some(signal);
            break;
        }
        let Some((i, s, item)) = frames.next() else { break };
        let counted = mapper.backend().device_counters();
        let done = item.and_then(|frame| threads.run(|| integrate(mapper, s, frame, i, &setup.name)));
        let (frame, stats) = match done {
            Ok(done) => done,
            Err(failure) => {
                bar.inc(1);
                if stops_the_run(&failure, setup) {
                    out.stopped = Some(failure);
                    break;
                }
                tracing::warn!("skipped: {}", failure.message);
                out.skipped.push((s, failure));
                continue;
            }
        };
        tracing::debug!("frame {i} at {:.3} s: {:.2} ms", frame.stamp_s, stats.total_ms);
        let mut rec = frame_record(i, &frame, &stats, batch);
        rec.sensor = Arc::clone(&sensor_names[s]);
        pairs.clear();
        pairs.extend(global_fields(&stats, mapper.map().occupancy().len()));
        pairs.push(("sensor_bytes", frame.measurement.bytes() as f64));
        pairs.push(("threads", threads.threads() as f64));
        if let (Some(before), Some(now)) = (counted, mapper.backend().device_counters()) {
            pairs.extend(device_fields(now.since(before)));
        }
        if args.eval {
            evaluate(&mut rec, &mut pairs, setup, &setup.sensors[s].0.sensor, &frame, mapper, &mut truth)?;
        }
        rec.fields = names.fields(&pairs);
        out.records.push(rec);
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(out)
}

/// Integrates frame `i` of `name`; a failure says whether the backend
/// failed (fatal) or the frame was refused.
fn integrate(
    mapper: &mut CliMapper,
    sensor: usize,
    frame: Frame,
    i: usize,
    name: &str,
) -> std::result::Result<(Frame, FrameStats), Failure> {
    match mapper.integrate_sensor_frame(sensor, &frame) {
        Ok(stats) => Ok((frame, stats)),
        Err(e) => {
            let kind = if e.is_backend_failure() { FailureKind::Fatal } else { FailureKind::Frame };
            let of = match mapper.sensors() {
                [_] => String::new(),
                all => all.get(sensor).map_or_else(String::new, |s| format!(" of sensor {:?}", s.name)),
            };
            Err(Failure {
                index: i,
                message: format!("frame {i}{of} (stamp {:.6} s) of {name}: {e:#}", frame.stamp_s),
                kind,
            })
        }
    }
}

/// Whether the window's batch EDT runs as a stage of its own: in wavefront
/// mode, where the backend does not keep it inside the integration.
fn batch_stage(setup: &Setup, mapper: &CliMapper) -> bool {
    setup.params.global.mode == IntegrationMode::Wavefront && !mapper.backend().batch_stays_on_device()
}

/// `report.json`'s `stages`: what each timed stage of a frame is, as the
/// integration mode and backend run them.
fn stages(setup: &Setup, mapper: &CliMapper) -> serde_json::Value {
    let ogm = "occupancy: ray casting or projection of the frame into the local window, fused into the map's log-odds (paper §IV-A)";
    match setup.params.global.mode {
        IntegrationMode::Exact => json!({
            "ogm_ms": ogm,
            "integrate_ms": "the exact global EDT brought up to date over the region the frame's obstacle changes can reach (exact mode has no separate batch EDT of the window)",
        }),
        IntegrationMode::Wavefront if batch_stage(setup, mapper) => json!({
            "ogm_ms": ogm,
            "batch_edt_ms": "the exact batch EDT of the local window (paper §IV-B)",
            "integrate_ms": "the window's EDT merged into the global EDT by raise and lower wavefronts (paper §IV-C)",
        }),
        IntegrationMode::Wavefront => json!({
            "ogm_ms": ogm,
            "integrate_ms": "the window's batch EDT and its merge into the global EDT by wavefronts, both on the device",
        }),
    }
}

/// Whether `failure` ends the run rather than skipping its frame.
fn stops_the_run(failure: &Failure, setup: &Setup) -> bool {
    failure.kind != FailureKind::Frame
        || setup.sections.dataset.on_error == OnError::Stop
        || matches!(setup.source, Source::Scene(_))
}

/// The report's record of frame `index`, its named fields still to come;
/// `batch`: whether the window's batch EDT is a stage of its own.
fn frame_record(index: usize, frame: &Frame, stats: &FrameStats, batch: bool) -> FrameRecord {
    FrameRecord {
        index,
        stamp_s: frame.stamp_s,
        ogm_ms: stats.ogm_ms,
        batch_edt_ms: batch.then_some(stats.batch_edt_ms),
        integrate_ms: stats.integrate_ms,
        total_ms: stats.total_ms,
        voxels_updated: stats.voxels_updated,
        voxels_changed: stats.voxels_changed,
        changed_blocks: stats.changed_blocks.len(),
        ..Default::default()
    }
}

/// `--eval`: occupancy scores against a scene's ground truth, and the EDT
/// errors, added to `fields`. Recordings have no ground truth: only the
/// EDT is checked.
fn evaluate(
    rec: &mut FrameRecord,
    fields: &mut Vec<(&'static str, f64)>,
    setup: &Setup,
    sensor: &Sensor,
    frame: &Frame,
    mapper: &CliMapper,
    truth: &mut (Vec<bool>, Vec<bool>),
) -> Result<()> {
    if let Source::Scene(scene) = &setup.source {
        let scores = score(scene, sensor, frame, mapper, truth);
        (rec.precision, rec.recall, rec.strict_recall) = (scores.precision(), scores.recall(), scores.strict_recall());
    }
    fields.extend(edt_error_fields(mapper)?);
    Ok(())
}

/// `report.json`'s header: what ran, on what, and how it ended.
fn report_header(
    args: &RunArgs,
    setup: &Setup,
    mapper: &CliMapper,
    slice: &SliceHeight,
    replayed: &Replayed,
) -> Map<String, serde_json::Value> {
    let (sensor, params) = (&setup.sensors[0].0.sensor, &setup.params);
    let mut header = Map::new();
    header.insert("edtmap_version".into(), json!(env!("CARGO_PKG_VERSION")));
    header.insert("scene".into(), json!(setup.name));
    header.insert("config".into(), json!(setup.origin));
    header.insert("backend".into(), json!(mapper.backend().name()));
    header.insert("threads".into(), json!(rayon::current_num_threads()));
    header.insert("sensor".into(), json!(sensor.kind()));
    header.insert("construction".into(), json!(construction_of(sensor, &setup.params.ogm)));
    header.insert("voxel_size_m".into(), json!(params.voxel_size_m));
    header.insert("local_dims".into(), json!(mapper.local_volume().map(|v| v.dims)));
    header.insert("map_blocks".into(), json!(mapper.map().occupancy().len()));
    let peak = crate::memory::peak_rss_bytes();
    let window_voxels = mapper.local_volume().map(|v| v.len()).filter(|&n| n > 0);
    header.insert("peak_rss_bytes".into(), json!(peak));
    header
        .insert("peak_bytes_per_window_voxel".into(), json!(peak.zip(window_voxels).map(|(b, n)| b as f64 / n as f64)));
    header.insert("integration".into(), json!(params.global.mode));
    header.insert("connectivity".into(), json!(params.global.connectivity));
    header.insert("max_distance_m".into(), json!(params.global.max_distance_m));
    header.insert("slice".into(), slice.to_json());
    header.insert("stages".into(), stages(setup, mapper));
    if args.eval {
        header.insert("eval".into(), eval_note(&setup.source));
    }
    let sensors: Vec<_> = mapper
        .sensors()
        .iter()
        .enumerate()
        .map(|(i, s)| {
            json!({
                "name": s.name,
                "kind": s.sensor.kind(),
                "construction": construction_of(&s.sensor, &s.ogm),
                "frames_integrated": replayed.records.iter().filter(|r| *r.sensor == *s.name).count(),
                "frames_skipped": replayed.skipped.iter().filter(|(k, _)| *k == i).count(),
            })
        })
        .collect();
    header.insert("sensors".into(), json!(sensors));
    let failure = |(s, f): &(usize, Failure)| json!({"index": f.index, "sensor": mapper.sensors().get(*s).map(|m| m.name.as_str()), "reason": f.message});
    header.insert("skipped".into(), json!(replayed.skipped.iter().map(failure).collect::<Vec<_>>()));
    let stopped = |f: &Failure| json!({"index": f.index, "reason": f.message});
    header.insert("stopped".into(), json!(replayed.stopped.as_ref().map(stopped)));
    let interrupted = |&s: &i32| json!({"signal": if s == libc::SIGTERM { "SIGTERM" } else { "SIGINT" }, "frames": replayed.records.len()});
    header.insert("interrupted".into(), json!(replayed.interrupted.as_ref().map(interrupted)));
    header
}

/// The map (`--save`), the slices, the clouds (`--ply`) and the timing
/// chart; a failure after an early stop says so.
fn write_outputs(args: &RunArgs, mapper: &CliMapper, slice: &SliceHeight, replayed: &Replayed) -> Result<Vec<PathBuf>> {
    let outputs = (|| -> Result<Vec<PathBuf>> {
        if let Some(path) = &args.save {
            edtmap::save_map(mapper.map(), path)?;
        }
        let mut pictures = write_slices(mapper, slice.z_m, &args.out)?;
        pictures.extend(crate::pictures::write_map_views(mapper.map(), slice.z_m, None, &args.out)?);
        if args.ply {
            pictures.extend(write_plys(mapper, &args.out)?);
        }
        pictures.push(write_timing_plot(&replayed.records, &mapper.backend().name(), &args.out)?);
        Ok(pictures)
    })();
    match (outputs, &replayed.stopped) {
        (Ok(p), _) => Ok(p),
        (Err(e), None) => Err(e),
        (Err(e), Some(failure)) => Err(e.context(format!("after the run stopped early: {}", failure.message))),
    }
}

/// A run that stopped early fails, its outputs written; only damage that
/// ends a recording under `on_error = "skip"` is a warning.
fn check_stopped(args: &RunArgs, sections: &Sections, replayed: &Replayed) -> Result<()> {
    let Some(failure) = &replayed.stopped else { return Ok(()) };
    let n = replayed.records.len();
    let plural = if n == 1 { "frame before it is" } else { "frames before it are" };
    let kept = format!("the {n} {plural} integrated and written to {}", args.out.display());
    if failure.kind == FailureKind::Damage && sections.dataset.on_error == OnError::Skip {
        tracing::warn!("stopped early: {}; {kept}", failure.message);
        Ok(())
    } else {
        bail!("{}; {kept}", failure.message);
    }
}

/// The run's report in `--out`.
const REPORT: &str = "report.json";

/// Refuses, before any frame, outputs that would replace one another or
/// write through a link.
fn check_outputs(args: &RunArgs) -> Result<()> {
    let names = std::iter::once(REPORT).chain(crate::pictures::OUT_PICTURES);
    let outs: Vec<(String, PathBuf)> = names.map(|n| (format!("--out's {n}"), args.out.join(n))).collect();
    let mut named: Vec<(&str, &Path)> = outs.iter().map(|(n, p)| (n.as_str(), p.as_path())).collect();
    if let Some(save) = &args.save {
        named.push(("--save", save));
    }
    edtmap_io::files::check_distinct_outputs(&named)?;
    for (_, path) in &named {
        edtmap_io::files::check_output(path)?;
    }
    Ok(())
}

/// Why a run integrated no frame, from its skipped and stopping frames.
fn nothing_integrated(skipped: &[(usize, Failure)], stopped: Option<&Failure>, report: &Path) -> String {
    let mut text = String::from("no frame was integrated");
    if let Some(f) = stopped {
        text.push_str(&format!(": the run stopped at the first usable frame: {}", f.message));
    }
    if let Some((_, first)) = skipped.first() {
        text.push_str(&format!("; {} frames were skipped, the first because {}", skipped.len(), first.message));
    }
    text.push_str(&format!(" (every reason is in {}; no map or picture was written)", report.display()));
    text
}

/// What `--eval` cannot do on a recording.
const RECORDING_EVAL: &str = "no occupancy score (precision, recall): it needs a built-in scene's ground truth; the EDT error against the exact EDT of the map is still computed";

/// `report.json`'s `eval`: what `--eval` scored.
fn eval_note(source: &Source) -> serde_json::Value {
    match source {
        Source::Scene(_) => json!({ "occupancy": true, "edt_errors": true }),
        _ => json!({ "occupancy": false, "edt_errors": true, "note": format!("a recording: {RECORDING_EVAL}") }),
    }
}

/// How a sensor's frames become occupancy, as the report names it.
fn construction_of(sensor: &Sensor, ogm: &OgmOptions) -> &'static str {
    match ogm.construction {
        Construction::RayCasting => "raycast",
        Construction::Projection => "projection",
        Construction::Auto if sensor.supports_projection() => "projection",
        Construction::Auto => "raycast",
    }
}

/// The global EDT's per-frame fields of the report; the map's bytes per
/// mapped voxel count every layer's bytes over the voxels of the
/// `occupancy_blocks` (what `bench/pipeline.sh` reports).
fn global_fields(s: &FrameStats, occupancy_blocks: usize) -> Vec<(&'static str, f64)> {
    let mapped_voxels = (occupancy_blocks * edtmap::BLOCK_VOXELS).max(1);
    vec![
        ("occupancy_rewritten_blocks", s.occupancy_rewritten_blocks as f64),
        ("edt_voxels_changed", s.edt_voxels_changed as f64),
        ("edt_changed_blocks", s.edt_changed_blocks as f64),
        ("change_score_m", s.change_score_m),
        ("map_blocks", s.map_blocks as f64),
        ("map_bytes", s.map_bytes as f64),
        ("map_bytes_per_mapped_voxel", s.map_bytes as f64 / mapped_voxels as f64),
        ("raised", s.waves.raised as f64),
        ("kept_outside", s.waves.kept_outside as f64),
        ("wave_seeds", s.waves.seeds as f64),
        ("wave_levels", s.waves.levels as f64),
        ("obstacles_added", s.exact.obstacles_added as f64),
        ("obstacles_added_apart", s.exact.obstacles_added_apart as f64),
        ("obstacles_removed", s.exact.obstacles_removed as f64),
        ("edt_distance_changed", (s.exact.changed[2] - s.exact.nearest_only[2]) as f64),
        ("edt_nearest_only_changed", s.exact.nearest_only[2] as f64),
        ("g1_changed", s.exact.changed[0] as f64),
        ("g1_nearest_only_changed", s.exact.nearest_only[0] as f64),
        ("g2_changed", s.exact.changed[1] as f64),
        ("g2_nearest_only_changed", s.exact.nearest_only[1] as f64),
        ("pass_x_rescanned", s.exact.rescanned[0] as f64),
        ("pass_y_rescanned", s.exact.rescanned[1] as f64),
        ("pass_z_rescanned", s.exact.rescanned[2] as f64),
        ("pass_x_visited", s.exact.visited[0] as f64),
        ("pass_y_visited", s.exact.visited[1] as f64),
        ("pass_z_visited", s.exact.visited[2] as f64),
    ]
}

/// A device backend's traffic and work during one frame (GPU runs).
fn device_fields(c: edtmap::DeviceCounters) -> [(&'static str, f64); 9] {
    [
        ("gpu_uploaded_bytes", c.uploaded_bytes as f64),
        ("gpu_downloaded_bytes", c.downloaded_bytes as f64),
        ("gpu_dispatches", c.dispatches as f64),
        ("gpu_submissions", c.submissions as f64),
        ("gpu_memory_bytes", c.memory_bytes as f64),
        ("gpu_ogm_device_ms", c.occupancy_ns as f64 * 1e-6),
        ("gpu_batch_edt_device_ms", c.batch_edt_ns as f64 * 1e-6),
        ("gpu_integrate_device_ms", c.integrate_ns as f64 * 1e-6),
        ("gpu_wait_ms", c.wait_ns as f64 * 1e-6),
    ]
}

/// Errors of the local window and of the whole global EDT against the
/// exact EDT of the mapper's own obstacles.
fn edt_error_fields(mapper: &CliMapper) -> Result<Vec<(&'static str, f64)>> {
    let map = mapper.map();
    let mut out = Vec::new();
    let regions = [
        ("local", mapper.local_volume().map(|v| Region { origin: v.origin.0, dims: v.dims })),
        ("global", edt_extent(map)),
    ];
    for (name, region) in regions {
        let e = match region {
            Some(r) => edt_errors(map, &r)?,
            None => EdtErrors::default(),
        };
        let keys: [&'static str; 3] = if name == "local" {
            ["local_rms_m", "local_max_m", "local_wrong_fraction"]
        } else {
            ["global_rms_m", "global_max_m", "global_wrong_fraction"]
        };
        out.extend(keys.into_iter().zip([e.rms_m, e.max_m, e.wrong_fraction]));
    }
    Ok(out)
}

/// Occupancy scores of the mapper's local volume against the scene.
fn score(
    scene: &Scene,
    sensor: &Sensor,
    frame: &Frame,
    mapper: &CliMapper,
    buffers: &mut (Vec<bool>, Vec<bool>),
) -> OccupancyScores {
    match mapper.local_volume() {
        Some(volume) => {
            scene.ground_truth(volume, frame.stamp_s, &mut buffers.0);
            scene.seen_surface(sensor, frame, volume, &mut buffers.1);
            OccupancyScores::compare(mapper.local_states().as_slice(), &buffers.0, &buffers.1)
        }
        None => OccupancyScores::default(),
    }
}

fn progress_bar(frames: usize, show: bool) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    // Draws on stderr only when it is a terminal.
    let bar = ProgressBar::new(frames as u64);
    if let Ok(style) = ProgressStyle::with_template("{bar:40} {pos}/{len} frames  {per_sec}  ETA {eta}") {
        bar.set_style(style);
    }
    bar
}

/// Prints the per-stage medians and what was written.
pub(crate) fn print_summary(outcome: &RunOutcome) {
    let f = &outcome.frames;
    // The same median as report.json's summary.
    let median =
        |g: fn(&FrameRecord) -> Option<f64>| median(&f.iter().filter_map(g).collect::<Vec<_>>()).unwrap_or(f64::NAN);
    // Only the stages that ran: exact mode has no batch EDT of its own.
    let stages = match f.iter().all(|r| r.batch_edt_ms.is_some()) {
        true => format!(
            "batch EDT median {:.2} ms, integration median {:.2} ms",
            median(|r| r.batch_edt_ms),
            median(|r| Some(r.integrate_ms))
        ),
        false => format!("EDT update median {:.2} ms", median(|r| Some(r.integrate_ms))),
    };
    outln!(
        "{} frames on {}: occupancy median {:.2} ms, {stages}, total median {:.2} ms per frame",
        f.len(),
        outcome.backend,
        median(|r| Some(r.ogm_ms)),
        median(|r| Some(r.total_ms))
    );
    let mean = |g: fn(&FrameRecord) -> Option<f64>| {
        let v: Vec<f64> = f.iter().filter_map(g).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    if let (Some(p), Some(r), Some(rs)) = (mean(|r| r.precision), mean(|r| r.recall), mean(|r| r.strict_recall)) {
        outln!("occupancy vs ground truth (mean over frames): precision {p:.3}, recall of the seen surface {r:.3} (strict recall {rs:.3})");
    }
    let field_mean = |key: &str| {
        let v: Vec<f64> = f.iter().filter_map(|r| r.field(key)).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    if let (Some(l), Some(g), Some(gm)) =
        (field_mean("local_rms_m"), field_mean("global_rms_m"), field_mean("global_max_m"))
    {
        outln!("EDT vs exact EDT of the map (mean over frames): local RMS {l:.5} m, global RMS {g:.5} m, global max {gm:.4} m");
    }
    if let Some(e) = outcome.map_eval {
        outln!(
            "final map vs ground truth: {} voxels occupied where a solid is, {} where none is; {} voxels of solids not occupied",
            e.true_occupied,
            e.false_occupied,
            e.missed
        );
    }
    outln!("wrote {}", outcome.report_path.display());
    for p in &outcome.pictures {
        outln!("wrote {}", p.display());
    }
}
