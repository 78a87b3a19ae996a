//! `edt_changes export`: a scene or a recording through the mapper, its
//! obstacle changes frame by frame, our EDT times, and the final map.

use crate::common::{
    median, region_json, time_stats, write_json, Error, CHANGES_FILE, MAP_FILE, SUMMARY_FILE, TIMES_FILE,
};
use crate::source;
use edtmap::config::Config;
use edtmap::eval::edt_errors;
use edtmap::region::Region;
use edtmap::sensor::{Frame, Sensor};
use edtmap::{BlockKey, Cutoff, GlobalMap, IntegrationMode, Mapper, MapperParams, VoxelIndex, BLOCK_VOXELS};
use edtmap_sim::SceneName;
use serde_json::json;
use std::collections::HashSet;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Arguments of `export`.
#[derive(Debug, Default)]
pub(crate) struct ExportArgs {
    pub(crate) scene: Option<String>,
    pub(crate) dataset: Option<PathBuf>,
    pub(crate) config: Option<PathBuf>,
    pub(crate) frames: Option<usize>,
    pub(crate) voxel_size_m: Option<f64>,
    pub(crate) max_distance_m: Option<f64>,
    pub(crate) integration: Option<IntegrationMode>,
    pub(crate) repeat: usize,
    pub(crate) out: PathBuf,
}

/// The frames, sensor and parameters of a run.
struct Setup {
    /// The scene's or the recording's name.
    name: String,
    config_origin: String,
    frames: Vec<Frame>,
    sensor: Sensor,
    params: MapperParams,
}

/// One frame's obstacle changes and EDT costs.
struct FrameChanges {
    set: Vec<VoxelIndex>,
    clear: Vec<VoxelIndex>,
    batch_edt_ms: f64,
    integrate_ms: f64,
    change_score_m: f64,
    /// Voxels of the region the integration worked on.
    region_voxels: usize,
    /// Global EDT voxels whose distance or nearest obstacle changed.
    edt_voxels_changed: usize,
}

impl FrameChanges {
    /// Our EDT update: batch EDT of the local volume + global integration.
    fn edt_ms(&self) -> f64 {
        self.batch_edt_ms + self.integrate_ms
    }
}

/// One replay of the scene: the final mapper, the frames, the obstacles.
struct Replay {
    mapper: Mapper,
    frames: Vec<FrameChanges>,
    obstacles: HashSet<VoxelIndex>,
}

/// Runs `export`.
pub(crate) fn run(args: &ExportArgs) -> Result<(), Error> {
    let setup = setup(args)?;
    std::fs::create_dir_all(&args.out).map_err(|e| format!("cannot create {}: {e}", args.out.display()))?;
    let mut best = replay(&setup)?;
    for run in 1..args.repeat {
        keep_fastest(&mut best.frames, replay(&setup)?.frames, run)?;
    }
    let map = best.mapper.map();
    let region = change_box(&best.frames, map.cutoff().reach)?;
    check_tracking(map, &region, &best.obstacles)?;
    write_changes(&args.out.join(CHANGES_FILE), &setup, map, &region, &best.frames)?;
    write_times(&args.out.join(TIMES_FILE), &best.frames)?;
    edtmap::save_map(map, &args.out.join(MAP_FILE))?;
    let errors = edt_errors(map, &region)?;
    let ms = |f: fn(&FrameChanges) -> f64| best.frames.iter().map(f).collect::<Vec<f64>>();
    let summary = json!({
        "scene": setup.name,
        "dataset": args.dataset.as_ref().map(|d| d.display().to_string()),
        "config": setup.config_origin,
        "frames": best.frames.len(),
        "repeat": args.repeat,
        "threads": rayon::current_num_threads(),
        "voxel_size_m": map.voxel_size_m(),
        "max_distance_m": map.params().max_distance_m,
        "max_dist_sq_vox": map.cutoff().max_dist_sq,
        "integration": map.params().mode,
        "connectivity": map.params().connectivity,
        "local_volume_m": setup.params.volume.size_m,
        "box": region_json(&region),
        "sets": best.frames.iter().map(|f| f.set.len()).sum::<usize>(),
        "clears": best.frames.iter().map(|f| f.clear.len()).sum::<usize>(),
        "final_obstacles": best.obstacles.len(),
        "edt_ms": time_stats(&ms(FrameChanges::edt_ms)),
        "batch_edt_ms": time_stats(&ms(|f| f.batch_edt_ms)),
        "integrate_ms": time_stats(&ms(|f| f.integrate_ms)),
        "median_region_voxels": median(&ms(|f| f.region_voxels as f64)),
        "median_edt_voxels_changed": median(&ms(|f| f.edt_voxels_changed as f64)),
        "final_error": { "rms_m": errors.rms_m, "max_m": errors.max_m, "wrong_fraction": errors.wrong_fraction, "voxels": errors.voxels },
    });
    write_json(&args.out.join(SUMMARY_FILE), &summary)?;
    println!("{}", serde_json::to_string(&summary)?);
    Ok(())
}

/// The configuration, with the overrides of the arguments, and the frames
/// of the scene or the recording.
fn setup(args: &ExportArgs) -> Result<Setup, Error> {
    if args.dataset.is_some() && (args.scene.is_some() || args.config.is_none()) {
        return Err("--dataset DIR goes with --config FILE, without --scene".into());
    }
    let (text, config_origin) = match (&args.config, &args.scene) {
        (Some(path), _) => (edtmap::config::read(path)?, path.display().to_string()),
        (None, Some(scene)) => {
            let text = builtin_config(scene).ok_or_else(|| format!("unknown scene {scene:?}: {}", scene_names()))?;
            (text.to_owned(), format!("configs/{scene}.toml"))
        }
        (None, None) => {
            return Err(
                format!("give --scene NAME ({}), --config FILE or --dataset DIR --config FILE", scene_names()).into()
            )
        }
    };
    let mut config = Config::parse(&text, &config_origin)?;
    let sections: source::Sections = edtmap::config::sections(&text, &config_origin)?;
    if let Some(v) = args.voxel_size_m {
        config.occupancy.voxel_size_m = v;
    }
    if let Some(d) = args.max_distance_m {
        config.global.max_distance_m = d;
    }
    if let Some(m) = args.integration {
        config.global.mode = m;
    }
    if let Some(dir) = &args.dataset {
        let read = source::recording(dir, &mut config, &sections.dataset, &config_origin, args.frames)?;
        let (sensor, params) = config.mapper_params()?;
        return Ok(Setup { name: read.name, config_origin, frames: read.frames, sensor, params });
    }
    let (sensor, params) = config.mapper_params()?;
    let scene = args
        .scene
        .clone()
        .or_else(|| sections.scene.as_ref().map(|s| s.name.clone()))
        .ok_or_else(|| format!("{config_origin} has no [scene]: give --scene NAME or --dataset DIR"))?;
    let made = source::scene(&scene, sections.scene.as_ref(), &sensor, args.frames)?;
    Ok(Setup { name: made.name, config_origin, frames: made.frames, sensor, params })
}

/// The shipped configuration of a built-in scene.
fn builtin_config(scene: &str) -> Option<&'static str> {
    match scene {
        "uav_pillars" => Some(include_str!("../../../../configs/uav_pillars.toml")),
        "ugv_corridor" => Some(include_str!("../../../../configs/ugv_corridor.toml")),
        "room" => Some(include_str!("../../../../configs/room.toml")),
        "planar" => Some(include_str!("../../../../configs/planar.toml")),
        _ => None,
    }
}

fn scene_names() -> String {
    SceneName::ALL.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ")
}

/// Runs every frame through a fresh mapper, recording each frame's
/// obstacle changes. Fixed obstacles (forbidden zones) are obstacles from
/// the start: they count as set in the first frame.
fn replay(setup: &Setup) -> Result<Replay, Error> {
    let mut mapper = Mapper::new(setup.sensor.clone(), setup.params.clone())?;
    let mut initial = fixed_obstacles(mapper.map());
    let mut obstacles: HashSet<VoxelIndex> = initial.iter().copied().collect();
    let mut out = Vec::with_capacity(setup.frames.len());
    for (i, frame) in setup.frames.iter().enumerate() {
        let stats = mapper.integrate_frame(frame).map_err(|e| format!("frame {i}: {e}"))?;
        let (set, clear) = obstacle_changes(mapper.map(), &stats.changed_blocks, &mut obstacles);
        initial.extend(set);
        let set = std::mem::take(&mut initial);
        out.push(FrameChanges {
            set,
            clear,
            batch_edt_ms: stats.batch_edt_ms,
            integrate_ms: stats.integrate_ms,
            change_score_m: stats.change_score_m,
            region_voxels: stats.integrate_region_voxels,
            edt_voxels_changed: stats.edt_voxels_changed,
        });
    }
    Ok(Replay { mapper, frames: out, obstacles })
}

/// The fixed obstacles of `map`.
fn fixed_obstacles(map: &GlobalMap) -> Vec<VoxelIndex> {
    let mut keys: Vec<BlockKey> = map.fixed_obstacles().iter().map(|(k, _)| k).collect();
    keys.sort();
    keys.iter()
        .flat_map(|k| (0..BLOCK_VOXELS).map(|o| k.voxel(o)))
        .filter(|&v| map.fixed_obstacles().contains(v))
        .collect()
}

/// Voxels of `blocks` that became obstacles and that stopped being
/// obstacles since `known`, which is brought up to date. Obstacles change
/// only where a voxel's state changed, so these blocks hold every change.
fn obstacle_changes(
    map: &GlobalMap,
    blocks: &[BlockKey],
    known: &mut HashSet<VoxelIndex>,
) -> (Vec<VoxelIndex>, Vec<VoxelIndex>) {
    let obstacles = map.obstacles();
    let (mut set, mut clear) = (Vec::new(), Vec::new());
    for v in blocks.iter().flat_map(|k| (0..BLOCK_VOXELS).map(|o| k.voxel(o))) {
        let now = obstacles.contains(v);
        if now && known.insert(v) {
            set.push(v);
        } else if !now && known.remove(&v) {
            clear.push(v);
        }
    }
    (set, clear)
}

/// Keeps, frame by frame, the faster of `best` and `again` (run `run`,
/// which must have seen the same changes).
fn keep_fastest(best: &mut [FrameChanges], again: Vec<FrameChanges>, run: usize) -> Result<(), Error> {
    for (i, (b, a)) in best.iter_mut().zip(again).enumerate() {
        if (a.set.len(), a.clear.len()) != (b.set.len(), b.clear.len()) {
            return Err(format!(
                "repeat {} changed other voxels than the first run at frame {i}: the mapper is not deterministic",
                run + 1
            )
            .into());
        }
        if a.edt_ms() < b.edt_ms() {
            *b = a;
        }
    }
    Ok(())
}

/// The bounding box of every voxel that was ever an obstacle, grown by the
/// cutoff's reach and one voxel.
fn change_box(frames: &[FrameChanges], reach: i32) -> Result<Region, Error> {
    let mut voxels = frames.iter().flat_map(|f| &f.set);
    let first = voxels.next().ok_or("no voxel ever became an obstacle: nothing to compare")?.0;
    let (lo, hi) = voxels.fold((first, first), |(lo, hi), v| {
        ([0, 1, 2].map(|a| lo[a].min(v.0[a])), [0, 1, 2].map(|a| hi[a].max(v.0[a])))
    });
    let tight = Region { origin: lo, dims: [0, 1, 2].map(|a| (hi[a] - lo[a] + 1) as usize) };
    Ok(tight.grown(reach + 1))
}

/// Checks that the tracked obstacles are exactly those of `map` in `region`.
fn check_tracking(map: &GlobalMap, region: &Region, tracked: &HashSet<VoxelIndex>) -> Result<(), Error> {
    let obstacles = map.obstacles();
    let mut row = vec![false; region.dims[0]];
    let mut count = 0;
    for z in 0..region.dims[2] {
        for y in 0..region.dims[1] {
            obstacles.fill_row(region.world([0, y, z]), &mut row);
            count += row.iter().filter(|&&o| o).count();
        }
    }
    let stale = tracked.iter().filter(|&&v| !obstacles.contains(v)).count();
    if count != tracked.len() || stale > 0 {
        return Err(format!(
            "change tracking is off: {count} obstacles in the box, {} tracked, {stale} of them stale",
            tracked.len()
        )
        .into());
    }
    Ok(())
}

/// The cutoff as `max_distance_vox` for the harness, which keeps squared
/// distances up to floor(D²) exact: D = √(max_dist_sq + ½) when the cutoff
/// is not a whole number of voxels, so both sides cut at the same distance.
fn cutoff_vox_text(cutoff: Cutoff) -> String {
    let root = f64::from(cutoff.max_dist_sq).sqrt().round() as u32;
    if root * root == cutoff.max_dist_sq {
        root.to_string()
    } else {
        format!("{:.9}", (f64::from(cutoff.max_dist_sq) + 0.5).sqrt())
    }
}

/// Writes the changes in `replay_dynamicedt`'s format, box-local.
fn write_changes(
    path: &Path,
    setup: &Setup,
    map: &GlobalMap,
    region: &Region,
    frames: &[FrameChanges],
) -> Result<(), Error> {
    let file = std::fs::File::create(path).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    let mut w = BufWriter::new(file);
    writeln!(w, "edtmap-changes 1")?;
    writeln!(w, "# edt_changes export: {}, {}, {} frames", setup.name, setup.config_origin, frames.len())?;
    writeln!(
        w,
        "# edtmap cutoff: max_distance_m {} = squared distance <= {} voxels^2",
        map.params().max_distance_m,
        map.cutoff().max_dist_sq
    )?;
    writeln!(w, "voxel_size_m {}", map.voxel_size_m())?;
    writeln!(w, "max_distance_vox {}", cutoff_vox_text(map.cutoff()))?;
    let [ox, oy, oz] = region.origin;
    let [nx, ny, nz] = region.dims;
    writeln!(w, "box {ox} {oy} {oz} {nx} {ny} {nz}")?;
    writeln!(w, "frames {}", frames.len())?;
    for (k, f) in frames.iter().enumerate() {
        writeln!(w, "frame {k} set {} clear {}", f.set.len(), f.clear.len())?;
        for v in f.set.iter().chain(&f.clear) {
            let [x, y, z] = region.local(*v).ok_or("a changed voxel lies outside the box")?;
            writeln!(w, "{x} {y} {z}")?;
        }
    }
    w.flush().map_err(|e| format!("cannot write {}: {e}", path.display()).into())
}

/// Writes our per-frame times and change scores.
fn write_times(path: &Path, frames: &[FrameChanges]) -> Result<(), Error> {
    let mut text = String::from(
        "frame,set,clear,batch_edt_ms,integrate_ms,edt_ms,change_score_m,region_voxels,edt_voxels_changed\n",
    );
    for (k, f) in frames.iter().enumerate() {
        let (set, clear) = (f.set.len(), f.clear.len());
        text += &format!(
            "{k},{set},{clear},{:.6},{:.6},{:.6},{:.9},{},{}\n",
            f.batch_edt_ms,
            f.integrate_ms,
            f.edt_ms(),
            f.change_score_m,
            f.region_voxels,
            f.edt_voxels_changed
        );
    }
    std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()).into())
}
