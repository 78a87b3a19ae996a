//! `edtmap query` and `edtmap export`: answers from a saved map.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use edtmap::query::{distance_box, distances, max_query_coordinate_m, DistanceBox, MAX_QUERY_INDEX};
use edtmap::{load_map, GlobalMap, PointState, VoxelIndex, VoxelState};
use edtmap_io::files;
use edtmap_io::map_server::{write_map_server, OccupancyGrid2d};
use edtmap_io::npy::{self, ArrayLayout, ArrayOrder};

/// Arguments of `edtmap query`.
#[derive(Args, Debug)]
pub(crate) struct QueryArgs {
    /// A map saved with `edtmap run --save`.
    map: PathBuf,
    /// Points to query: a CSV file with x,y,z (metres, world frame) per line.
    ///
    /// Each line holds exactly three comma-separated finite decimal numbers
    /// (spaces around them allowed). Blank lines and lines starting with `#`
    /// are skipped, and so is a UTF-8 byte order mark and a first line that
    /// is exactly the column names `x,y,z` (any case). Anything else is an
    /// error naming the line, the field and the value, as is a coordinate
    /// farther than 2^30 voxels from the origin.
    ///
    /// A point outside the mapped area answers state `outside`, observed
    /// false and, with no obstacle within the cutoff, the cutoff distance
    /// (max_distance_m) with saturated true: free as far as the map knows,
    /// but unknown.
    #[arg(long, value_name = "FILE.csv", verbatim_doc_comment)]
    points: PathBuf,
    /// Negative distances inside obstacles.
    ///
    /// Signed distances are measured to the surface of the obstacle voxels
    /// (their faces), not between voxel centres: negative exactly when the
    /// point's voxel is occupied, with a unit gradient pointing away from
    /// the obstacle.
    #[arg(long)]
    signed: bool,
}

/// Arguments of `edtmap export`.
#[derive(Args, Debug)]
pub(crate) struct ExportArgs {
    /// A map saved with `edtmap run --save`.
    map: PathBuf,
    /// The box: xmin,ymin,zmin,xmax,ymax,zmax in metres; every voxel overlapping it is exported.
    ///
    /// Default: the mapped box that `edtmap info` prints (every allocated
    /// block of the map, whole).
    #[arg(
        long = "box",
        value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    bounds: Vec<f64>,
    /// Output: float32 distances in metres, shape (nz, ny, nx); saturated voxels hold max_distance_m.
    ///
    /// Beside it, OUT.json (the name with `.json` appended) records the
    /// world coordinate of the centre of element [0, 0, 0], the voxel size,
    /// shape, axis order, dtype and what the values mean (docs/FORMAT.md).
    ///
    /// An OUT ending in `.yaml` or `.yml` writes instead a 2D map for ROS
    /// navigation (map_server, nav2_map_server): OUT and the image OUT.pgm
    /// beside it (trinary: 0 occupied, 254 free, 205 unknown), one layer
    /// of the map at --height over the box's x and y.
    output: PathBuf,
    /// Height of the map_server map's layer, metres (OUT.yaml only).
    ///
    /// Default: the one layer a map holds when all its observed voxels lie
    /// in one z layer (a 2D LiDAR's map); a 3D map needs it.
    #[arg(long, value_name = "Z", allow_negative_numbers = true, value_parser = finite_metres)]
    height: Option<f64>,
    /// Also write each voxel's state as uint8: 0 outside, 1 unknown, 2 free, 3 occupied.
    #[arg(long, value_name = "STATES.npy")]
    states: Option<PathBuf>,
    /// Negative distances inside obstacles, measured from each voxel centre
    /// to the surface of the obstacle voxels.
    #[arg(long)]
    signed: bool,
}

/// Arguments of `edtmap info`.
#[derive(Args, Debug)]
pub(crate) struct InfoArgs {
    /// A map saved with `edtmap run --save`.
    map: PathBuf,
    /// Write the exploration frontiers (observed free voxels next to unknown ones) as x,y,z voxel centres.
    ///
    /// A voxel's six face neighbours count; in a map whose observed voxels
    /// all lie in one z layer (a 2D LiDAR's), only the four in that plane.
    #[arg(long, value_name = "OUT.csv")]
    frontiers: Option<PathBuf>,
}

/// Prints what a saved map holds.
pub(crate) fn info(args: &InfoArgs) -> Result<()> {
    let map = load_map(&args.map)?;
    let vs = map.voxel_size_m();
    outln!(
        "{}: voxel {vs} m, cutoff {} m, connectivity {}, integration {:?}{}",
        args.map.display(),
        map.params().max_distance_m,
        u8::from(map.params().connectivity),
        map.params().mode,
        if map.params().planar { ", planar (distances within each layer)" } else { "" }
    );
    outln!(
        "blocks: {} occupancy, {} EDT, {} fixed; {:.1} MB",
        map.occupancy().len(),
        map.edt().len(),
        map.fixed_obstacles().len(),
        map.bytes() as f64 / 1e6
    );
    if let Some((lo, hi)) = mapped_box_m(&map) {
        outln!("mapped box (m): {:.2},{:.2},{:.2} to {:.2},{:.2},{:.2}", lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
    }
    let (mut free, mut occupied) = (0usize, 0usize);
    for (_, b) in map.occupancy().iter() {
        for (_, v) in b.log_odds.iter_stored() {
            match map.log_odds().state(v) {
                edtmap::VoxelState::Free => free += 1,
                edtmap::VoxelState::Occupied => occupied += 1,
                edtmap::VoxelState::Unknown => {}
            }
        }
    }
    let frontiers = map.frontiers();
    outln!("voxels: {free} free, {occupied} occupied, {} exploration frontiers", frontiers.len());
    if let Some(path) = &args.frontiers {
        let mut text = String::from("x,y,z\n");
        for v in &frontiers {
            let c = v.centre(vs);
            text.push_str(&format!("{},{},{}\n", c[0], c[1], c[2]));
        }
        edtmap_io::files::write_atomic(path, text.as_bytes())?;
        outln!("wrote {}", path.display());
    }
    Ok(())
}

/// The mapped box, metres: the lowest and highest corner of the blocks
/// the occupancy layer holds; `None` for an empty map.
pub(crate) fn mapped_box_m(map: &GlobalMap) -> Option<([f64; 3], [f64; 3])> {
    let (lo, hi) = map.occupancy().key_bounds()?;
    let side = f64::from(edtmap::BLOCK_SIDE) * map.voxel_size_m();
    Some((lo.map(|b| f64::from(b) * side), hi.map(|b| f64::from(b) * side + side)))
}

/// Prints distance, gradient and state of every point as CSV.
pub(crate) fn query(args: &QueryArgs) -> Result<()> {
    let map = load_map(&args.map)?;
    let points = read_points(&args.points, map.voxel_size_m())?;
    let answers = distances(&map, &points, args.signed);
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    let mut write = || -> std::io::Result<()> {
        writeln!(out, "x,y,z,distance_m,grad_x,grad_y,grad_z,state,observed,saturated")?;
        for (p, a) in points.iter().zip(&answers) {
            let [gx, gy, gz] = a.gradient;
            writeln!(
                out,
                "{},{},{},{:.6},{gx:.6},{gy:.6},{gz:.6},{},{},{}",
                p[0],
                p[1],
                p[2],
                a.distance_m,
                state_name(a.state),
                a.observed,
                a.saturated
            )?;
        }
        out.flush()
    };
    // A closed pipe (`| head`) is not an error; a full disk is, at exit.
    if let Err(e) = write() {
        crate::output::record(e);
    }
    Ok(())
}

/// Writes a dense box of distances (and states) as `.npy`, and beside the
/// distances a JSON sidecar saying where the box lies and what it holds.
pub(crate) fn export(args: &ExportArgs) -> Result<()> {
    if !args.bounds.is_empty() && args.bounds.len() != 6 {
        bail!("--box takes six numbers: xmin,ymin,zmin,xmax,ymax,zmax");
    }
    if is_map_server(&args.output) {
        return export_map_server(args);
    }
    if args.height.is_some() {
        bail!("--height picks the layer of a map_server map: name an OUT ending in .yaml, or leave --height out for a .npy box");
    }
    let sidecar = sidecar_path(&args.output);
    let mut outputs = vec![("OUT", args.output.as_path()), ("the sidecar OUT.json", sidecar.as_path())];
    if let Some(states) = &args.states {
        outputs.push(("--states", states.as_path()));
    }
    files::check_distinct_outputs(&outputs)?;
    let map = load_map(&args.map)?;
    let (min_m, max_m) = export_box(&map, args)?;
    let (lo, hi) = query_box(args, (min_m, max_m), map.voxel_size_m());
    let dense = distance_box(&map, lo, hi, args.signed).context(if args.bounds.is_empty() {
        "the mapped box (no --box given): give a smaller --box"
    } else {
        "--box"
    })?;
    let [nx, ny, nz] = dense.dims;
    let layout = ArrayLayout::new(vec![nz, ny, nx], ArrayOrder::C).context("empty box")?;
    npy::write_distances(&args.output, &layout, &dense.distance_m)?;
    let origin = dense.origin.centre(map.voxel_size_m());
    outln!(
        "wrote {} ({nz} x {ny} x {nx} voxels; element [0, 0, 0] is world voxel {:?}, centre {origin:?} m)",
        args.output.display(),
        dense.origin.0
    );
    if let Some(path) = &args.states {
        npy::write_bytes(path, &layout, &dense.state)?;
        outln!("wrote {}", path.display());
    }
    let text = sidecar_json(&map, &dense, args, (min_m, max_m));
    files::write_atomic(&sidecar, text.as_bytes())?;
    outln!("wrote {}", sidecar.display());
    Ok(())
}

/// Whether export's `OUT` names a map_server YAML.
fn is_map_server(output: &Path) -> bool {
    output
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("yaml") || e.eq_ignore_ascii_case("yml"))
}

/// Writes one layer of the map over the box's x and y as a map_server
/// pair: OUT.yaml and OUT.pgm. Fixed obstacles are occupied; unmapped
/// cells unknown.
fn export_map_server(args: &ExportArgs) -> Result<()> {
    if args.states.is_some() || args.signed {
        bail!(
            "--states and --signed are for .npy boxes: {} writes a map_server map of states only",
            args.output.display()
        );
    }
    let map = load_map(&args.map)?;
    let vs = map.voxel_size_m();
    let layer = map_server_layer(&map, args)?;
    let (min_m, max_m) = query_box(args, export_box(&map, args)?, vs);
    // A box one voxel thick around the layer's centre, so that rounding
    // cannot reach the layers beside it.
    let z = [0.25, 0.75].map(|f| (f64::from(layer) + f) * vs);
    let what = if args.bounds.is_empty() { "the mapped box (no --box given): give a smaller --box" } else { "--box" };
    let dense = distance_box(&map, [min_m[0], min_m[1], z[0]], [max_m[0], max_m[1], z[1]], false).context(what)?;
    let [width, height, _] = dense.dims;
    let states: Vec<VoxelState> = dense
        .state
        .iter()
        .map(|&s| match s {
            3 => VoxelState::Occupied,
            2 => VoxelState::Free,
            _ => VoxelState::Unknown,
        })
        .collect();
    let origin_m = [0, 1].map(|a| f64::from(dense.origin.0[a]) * vs);
    let grid = OccupancyGrid2d { width, height, states: &states, resolution_m: vs, origin_m };
    let image = write_map_server(&args.output, &grid)?;
    outln!(
        "wrote {} ({width} x {height} cells of {vs} m at z = {:.3} m, lower left corner {origin_m:?} m)",
        image.display(),
        (f64::from(layer) + 0.5) * vs
    );
    outln!("wrote {}", args.output.display());
    Ok(())
}

/// The z index of the map_server layer: `--height`, else the one layer a
/// planar map observed.
fn map_server_layer(map: &GlobalMap, args: &ExportArgs) -> Result<i32> {
    let vs = map.voxel_size_m();
    let observed = map.observed_z_range();
    if let Some(z) = args.height {
        let layer = VoxelIndex::containing([0.0, 0.0, z], vs)
            .with_context(|| format!("--height {z} m is beyond the map's voxel index range"))?;
        if let Some((lo, hi)) = observed.filter(|(lo, hi)| !(*lo..=*hi).contains(&layer.0[2])) {
            tracing::warn!("--height {z} m is outside the observed heights (z from {:.3} to {:.3} m): the map is all unknown there", f64::from(lo) * vs, f64::from(hi + 1) * vs);
        }
        return Ok(layer.0[2]);
    }
    match observed {
        Some((lo, hi)) if lo == hi => Ok(lo),
        Some((lo, hi)) => bail!(
            "{} is a 2D map and {} is 3D (observed voxels from z = {:.3} to {:.3} m): give --height Z",
            args.output.display(),
            args.map.display(),
            f64::from(lo) * vs,
            f64::from(hi + 1) * vs
        ),
        None => bail!("{} has no observed voxel, so it has no layer to draw: give --height Z", args.map.display()),
    }
}

/// Parses a height in metres: a finite number within a million metres.
pub(crate) fn finite_metres(text: &str) -> std::result::Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v.abs() <= 1e6 => Ok(v),
        Ok(v) => Err(format!("{v} is not a height: give finite metres within ±1e6")),
        Err(e) => Err(format!("{text:?} is not a number of metres: {e}")),
    }
}

/// The box to export: `--box`, else the mapped box.
fn export_box(map: &GlobalMap, args: &ExportArgs) -> Result<([f64; 3], [f64; 3])> {
    match args.bounds[..] {
        [x0, y0, z0, x1, y1, z1] => Ok(([x0, y0, z0], [x1, y1, z1])),
        _ => mapped_box_m(map).with_context(|| {
            format!("{} holds no mapped block, so there is no box to export by default: give --box", args.map.display())
        }),
    }
}

/// The box handed to the box query: `--box` as given; the mapped box,
/// whose faces lie on voxel faces, a quarter voxel inside them, so that
/// rounding cannot add a layer of voxels beyond it.
fn query_box(args: &ExportArgs, (min_m, max_m): ([f64; 3], [f64; 3]), voxel_size_m: f64) -> ([f64; 3], [f64; 3]) {
    if args.bounds.is_empty() {
        let inset = voxel_size_m / 4.0;
        (min_m.map(|m| m + inset), max_m.map(|m| m - inset))
    } else {
        (min_m, max_m)
    }
}

/// The sidecar of export's output `OUT`: `OUT.json` (`box.npy` gives
/// `box.npy.json`), which can never be `OUT` itself.
pub(crate) fn sidecar_path(output: &Path) -> PathBuf {
    let mut name = output.as_os_str().to_owned();
    name.push(".json");
    PathBuf::from(name)
}

/// The sidecar's text (docs/FORMAT.md, "Exported boxes").
fn sidecar_json(
    map: &GlobalMap,
    dense: &DistanceBox,
    args: &ExportArgs,
    (min_m, max_m): ([f64; 3], [f64; 3]),
) -> String {
    let vs = map.voxel_size_m();
    let [nx, ny, nz] = dense.dims;
    let corner = dense.origin.0.map(|i| f64::from(i) * vs);
    let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
    let distances = if args.signed {
        "metres from each voxel centre to the surface of the obstacle voxels, negative inside them"
    } else {
        "metres from each voxel centre to the nearest obstacle voxel centre; 0 at obstacle voxels"
    };
    let json = serde_json::json!({
        "format": "edtmap export",
        "version": 1,
        "distances": name(&args.output),
        "states": args.states.as_deref().and_then(name),
        "map": args.map.display().to_string(),
        "dtype": "float32",
        "states_dtype": "uint8",
        "shape": [nz, ny, nx],
        "axis_order": ["z", "y", "x"],
        "memory_order": "C",
        "voxel_size_m": vs,
        "origin_m": dense.origin.centre(vs),
        "origin_is": "the world coordinate (metres) of the centre of element [0, 0, 0]; element [k, j, i] is centred at origin_m + voxel_size_m * [i, j, k]",
        "origin_corner_m": corner,
        "origin_voxel": dense.origin.0,
        "box_m": { "min": min_m, "max": max_m },
        "signed": args.signed,
        "distance_meaning": distances,
        "max_distance_m": map.params().max_distance_m,
        "saturated": "a voxel with no obstacle within the cutoff holds max_distance_m (signed: -max_distance_m inside an obstacle deeper than the cutoff); the true distance is at least that",
        "unknown": "unknown and outside voxels count as free: their distance is to the nearest obstacle the map knows; the states array tells them apart",
        "state_values": { "0": "outside (no mapped block)", "1": "unknown", "2": "free", "3": "occupied (or a fixed obstacle)" },
    });
    let mut text = serde_json::to_string_pretty(&json).unwrap_or_default();
    text.push('\n');
    text
}

fn state_name(s: PointState) -> &'static str {
    match s {
        PointState::Outside => "outside",
        PointState::Unknown => "unknown",
        PointState::Free => "free",
        PointState::Occupied => "occupied",
    }
}

/// Reads the points file (see `--points`): a UTF-8 byte order mark, blank
/// lines, `#` comment lines and a first line of column names are skipped;
/// every other line must be three finite numbers within the query range at
/// `voxel_size_m`. Errors name the file, the line, the field and the value.
fn read_points(path: &Path, voxel_size_m: f64) -> Result<Vec<[f64; 3]>> {
    let text = files::read_text(path)?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let limit_m = max_query_coordinate_m(voxel_size_m);
    let mut points = Vec::new();
    let mut first = true;
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if std::mem::take(&mut first) && is_header(line) {
            continue;
        }
        let point =
            parse_point(line, limit_m, voxel_size_m).map_err(|e| anyhow!("{}: line {}: {e}", path.display(), n + 1))?;
        points.push(point);
    }
    Ok(points)
}

/// Whether `line` is exactly the column names `x,y,z` (any case, spaces
/// around the names allowed).
fn is_header(line: &str) -> bool {
    let names: Vec<String> = line.split(',').map(|f| f.trim().to_ascii_lowercase()).collect();
    names == ["x", "y", "z"]
}

/// One point: three comma-separated finite numbers, each at most
/// `limit_m` in absolute value.
fn parse_point(line: &str, limit_m: f64, voxel_size_m: f64) -> Result<[f64; 3], String> {
    let fields: Vec<&str> = line.split(',').collect();
    if fields.len() != 3 {
        let found = fields.len();
        return Err(format!(
            "{line:?} has {found} comma-separated field{}, expected 3 numbers x,y,z",
            if found == 1 { "" } else { "s" }
        ));
    }
    let mut point = [0.0; 3];
    for ((slot, field), axis) in point.iter_mut().zip(&fields).zip(["x", "y", "z"]) {
        let text = field.trim();
        let value: f64 = text.parse().map_err(|_| format!("{axis} = {text:?} is not a number"))?;
        if !value.is_finite() || !is_decimal(text) {
            return Err(format!("{axis} = {text:?} is not a finite number"));
        }
        if value.abs() > limit_m {
            return Err(format!(
                "{axis} = {text:?} is beyond \u{b1}{limit_m:.0} m, the largest coordinate a query takes ({MAX_QUERY_INDEX} voxels of the map's voxel_size_m = {voxel_size_m})"
            ));
        }
        *slot = value;
    }
    Ok(point)
}

/// Whether `text`, which parses as a float, is spelled with digits (not
/// `inf` or `NaN`, which Rust's float parser also takes).
fn is_decimal(text: &str) -> bool {
    text.bytes().any(|b| b.is_ascii_digit()) && text.bytes().all(|b| b.is_ascii_digit() || b"+-.eE".contains(&b))
}
