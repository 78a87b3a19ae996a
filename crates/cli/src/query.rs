//! `edtmap query` and `edtmap export`: answers from a saved map.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use edtmap::cpu::query::{distance_box, distances};
use edtmap::{load_map, PointState};
use edtmap_io::npy::{self, ArrayLayout, ArrayOrder};

/// Arguments of `edtmap query`.
#[derive(Args, Debug)]
pub(crate) struct QueryArgs {
    /// A map saved with `edtmap run --save`.
    map: PathBuf,
    /// Points to query: a CSV file with x,y,z (metres, world frame) per line.
    #[arg(long, value_name = "FILE.csv")]
    points: PathBuf,
    /// Negative distances inside obstacles.
    #[arg(long)]
    signed: bool,
}

/// Arguments of `edtmap export`.
#[derive(Args, Debug)]
pub(crate) struct ExportArgs {
    /// A map saved with `edtmap run --save`.
    map: PathBuf,
    /// The box: xmin,ymin,zmin,xmax,ymax,zmax in metres; every voxel overlapping it is exported.
    #[arg(long = "box", value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX", value_delimiter = ',', allow_hyphen_values = true)]
    bounds: Vec<f64>,
    /// Output: float32 distances in metres, shape (nz, ny, nx); saturated voxels hold max_distance_m.
    output: PathBuf,
    /// Also write each voxel's state as uint8: 0 outside, 1 unknown, 2 free, 3 occupied.
    #[arg(long, value_name = "STATES.npy")]
    states: Option<PathBuf>,
    /// Negative distances inside obstacles.
    #[arg(long)]
    signed: bool,
}

/// Arguments of `edtmap info`.
#[derive(Args, Debug)]
pub(crate) struct InfoArgs {
    /// A map saved with `edtmap run --save`.
    map: PathBuf,
    /// Write the exploration frontiers (observed free voxels next to unknown ones) as x,y,z voxel centres.
    #[arg(long, value_name = "OUT.csv")]
    frontiers: Option<PathBuf>,
}

/// Prints what a saved map holds.
pub(crate) fn info(args: &InfoArgs) -> Result<()> {
    let map = load_map(&args.map)?;
    let vs = map.voxel_size_m();
    println!("{}: voxel {vs} m, cutoff {} m, connectivity {}, integration {:?}", args.map.display(), map.params.max_distance_m, u8::from(map.params.connectivity), map.params.mode);
    println!("blocks: {} occupancy, {} EDT, {} fixed; {:.1} MB", map.occupancy.len(), map.edt.len(), map.fixed.len(), map.bytes() as f64 / 1e6);
    if let Some((lo, hi)) = map.occupancy.key_bounds() {
        let side = f64::from(edtmap::BLOCK_SIDE) * vs;
        let lo: Vec<f64> = lo.iter().map(|&b| f64::from(b) * side).collect();
        let hi: Vec<f64> = hi.iter().map(|&b| f64::from(b + 1) * side).collect();
        println!("mapped box (m): {:.2},{:.2},{:.2} to {:.2},{:.2},{:.2}", lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
    }
    let (mut free, mut occupied) = (0usize, 0usize);
    for (_, b) in map.occupancy.iter() {
        for &v in &b.log_odds {
            match map.log_odds.state(v) {
                edtmap::VoxelState::Free => free += 1,
                edtmap::VoxelState::Occupied => occupied += 1,
                edtmap::VoxelState::Unknown => {}
            }
        }
    }
    let frontiers = map.frontiers();
    println!("voxels: {free} free, {occupied} occupied, {} exploration frontiers", frontiers.len());
    if let Some(path) = &args.frontiers {
        let mut text = String::from("x,y,z\n");
        for v in &frontiers {
            let c = v.centre(vs);
            text.push_str(&format!("{},{},{}\n", c[0], c[1], c[2]));
        }
        std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// Prints distance, gradient and state of every point as CSV.
pub(crate) fn query(args: &QueryArgs) -> Result<()> {
    let map = load_map(&args.map)?;
    let points = read_points(&args.points)?;
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
                p[0], p[1], p[2], a.distance_m, state_name(a.state), a.observed, a.saturated
            )?;
        }
        out.flush()
    };
    match write() {
        // A closed pipe (`| head`) is not an error.
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}

/// Writes a dense box of distances (and states) as `.npy`.
pub(crate) fn export(args: &ExportArgs) -> Result<()> {
    let b = &args.bounds;
    if b.len() != 6 {
        bail!("--box takes six numbers: xmin,ymin,zmin,xmax,ymax,zmax");
    }
    let map = load_map(&args.map)?;
    let dense = distance_box(&map, [b[0], b[1], b[2]], [b[3], b[4], b[5]], args.signed).context("--box")?;
    let [nx, ny, nz] = dense.dims;
    let layout = ArrayLayout::new(vec![nz, ny, nx], ArrayOrder::C).context("empty box")?;
    npy::write_distances(&args.output, &layout, &dense.distance_m)?;
    println!("wrote {} ({nz} x {ny} x {nx} voxels from world voxel {:?})", args.output.display(), dense.origin.0);
    if let Some(path) = &args.states {
        npy::write_bytes(path, &layout, &dense.state)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn state_name(s: PointState) -> &'static str {
    match s {
        PointState::Outside => "outside",
        PointState::Unknown => "unknown",
        PointState::Free => "free",
        PointState::Occupied => "occupied",
    }
}

/// Reads `x,y,z` lines; blank lines, `#` comments and a header line are skipped.
fn read_points(path: &Path) -> Result<Vec<[f64; 3]>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut points = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split([',', ' ', '\t']).filter(|f| !f.is_empty()).collect();
        let parsed: Result<Vec<f64>, _> = fields.iter().map(|f| f.parse::<f64>()).collect();
        match parsed {
            Ok(v) if v.len() == 3 => points.push([v[0], v[1], v[2]]),
            Err(_) if n == 0 => continue,
            _ => bail!("{}:{}: expected x,y,z (three numbers), got {line:?}", path.display(), n + 1),
        }
    }
    Ok(points)
}
