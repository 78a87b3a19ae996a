//! The edtmap half of `bench/dynamicedt.sh`: our incremental global EDT
//! against DynamicEDT3D (Lau et al., the CPU baseline of the GIE-mapping
//! paper) on the same obstacle changes, and the paper's Fig. 4 (EDT update
//! time against the change score V of eq. 6).
//!
//! ```text
//! cargo run --release -p edtmap --example edt_changes -- export --scene uav_pillars --out DIR
//!     [--config FILE] [--frames N] [--voxel-size M] [--max-distance M]
//!     [--integration wavefront|exact] [--repeat N]
//! cargo run --release -p edtmap --example edt_changes -- export --dataset PATH --config FILE --out DIR
//!     [same options]
//! cargo run --release -p edtmap --example edt_changes -- compare --dir DIR --dynamicedt PREFIX
//! ```
//!
//! `export` replays a built-in scene, or a recording (as `edtmap run
//! --dataset` opens it: a folder of 3DMatch or TUM depth images or
//! PCD/PLY/KITTI clouds, a ROS bag or MCAP file),
//! through the [`edtmap::Mapper`] and,
//! after each frame, finds the voxels that became obstacles and those that
//! stopped being obstacles (only the occupancy blocks the frame changed are
//! looked at). It writes, in DIR:
//! * `changes.txt`: those changes in the format `replay_dynamicedt` reads,
//!   in a box spanning every voxel that was ever an obstacle, grown by the
//!   cutoff's reach and one voxel, so DynamicEDT3D sees every obstacle and
//!   every voxel within the cutoff of one;
//! * `edtmap_times.csv`: per frame, our EDT update cost (batch EDT of the
//!   local volume + global integration, the part comparable to DynamicEDT3D's
//!   `update()`), each part, and the change score;
//! * `edtmap_summary.json`: parameters, the box, time statistics and our
//!   final EDT error over the box against the exact EDT;
//! * `final.edtmap`: the final map, from which `compare` takes the truth.
//!
//! With `--repeat N` the whole run is repeated from an empty map N times
//! and each frame keeps its fastest run, as the DynamicEDT3D harness does.
//!
//! `compare` reads DynamicEDT3D's `PREFIX.times.csv` and `PREFIX.final.f32`,
//! scores both final fields against the exact EDT of the final map's
//! obstacles with the same definitions as [`edtmap::eval::edt_errors`],
//! writes `comparison.json`, `table.md` (a header and one row) and Fig. 4 as
//! `fig4_time_vs_change.png`, and prints the row.

#[path = "edt_changes/common.rs"]
mod common;
#[path = "edt_changes/compare.rs"]
mod compare;
#[path = "edt_changes/export.rs"]
mod export;
#[path = "edt_changes/source.rs"]
mod source;

use common::Error;
use edtmap::IntegrationMode;
use std::path::PathBuf;

const USAGE: &str = "usage:
  edt_changes export (--scene NAME [--config FILE] | --dataset DIR --config FILE) --out DIR
                     [--frames N] [--voxel-size M] [--max-distance M]
                     [--integration wavefront|exact] [--repeat N]
  edt_changes compare --dir DIR --dynamicedt PREFIX";

fn main() {
    if let Err(e) = run() {
        eprintln!("edt_changes: {e}");
        std::process::exit(2);
    }
}

fn run() -> Result<(), Error> {
    let mut args = std::env::args().skip(1);
    match args.next().as_deref() {
        Some("export") => export::run(&parse_export(args)?),
        Some("compare") => compare::run(&parse_compare(args)?),
        Some("-h" | "--help") => {
            println!("{USAGE}");
            Ok(())
        }
        _ => Err(USAGE.into()),
    }
}

fn parse_export(mut it: impl Iterator<Item = String>) -> Result<export::ExportArgs, Error> {
    let mut a = export::ExportArgs { repeat: 1, ..Default::default() };
    while let Some(flag) = it.next() {
        let value = it.next().ok_or_else(|| format!("{flag} needs a value\n{USAGE}"))?;
        match flag.as_str() {
            "--scene" => a.scene = Some(value),
            "--dataset" => a.dataset = Some(PathBuf::from(value)),
            "--config" => a.config = Some(PathBuf::from(value)),
            "--out" => a.out = PathBuf::from(value),
            "--frames" => a.frames = Some(number(&flag, &value)?),
            "--repeat" => a.repeat = number(&flag, &value)?,
            "--voxel-size" => a.voxel_size_m = Some(number(&flag, &value)?),
            "--max-distance" => a.max_distance_m = Some(number(&flag, &value)?),
            "--integration" => a.integration = Some(integration(&value)?),
            _ => return Err(format!("unknown option {flag}\n{USAGE}").into()),
        }
    }
    if a.out.as_os_str().is_empty() {
        return Err(format!("export needs --out DIR\n{USAGE}").into());
    }
    if a.repeat == 0 || a.frames == Some(0) {
        return Err("--repeat and --frames must be at least 1".into());
    }
    Ok(a)
}

fn parse_compare(mut it: impl Iterator<Item = String>) -> Result<compare::CompareArgs, Error> {
    let (mut dir, mut prefix) = (None, None);
    while let Some(flag) = it.next() {
        let value = it.next().ok_or_else(|| format!("{flag} needs a value\n{USAGE}"))?;
        match flag.as_str() {
            "--dir" => dir = Some(PathBuf::from(value)),
            "--dynamicedt" => prefix = Some(value),
            _ => return Err(format!("unknown option {flag}\n{USAGE}").into()),
        }
    }
    match (dir, prefix) {
        (Some(dir), Some(dynamicedt_prefix)) => Ok(compare::CompareArgs { dir, dynamicedt_prefix }),
        _ => Err(format!("compare needs --dir DIR and --dynamicedt PREFIX\n{USAGE}").into()),
    }
}

fn number<T: std::str::FromStr>(flag: &str, value: &str) -> Result<T, Error>
where
    T::Err: std::fmt::Display,
{
    value.parse().map_err(|e| format!("{flag} {value:?}: {e}").into())
}

fn integration(value: &str) -> Result<IntegrationMode, Error> {
    match value {
        "wavefront" => Ok(IntegrationMode::Wavefront),
        "exact" => Ok(IntegrationMode::Exact),
        _ => Err(format!("--integration {value:?}: choose wavefront or exact").into()),
    }
}
