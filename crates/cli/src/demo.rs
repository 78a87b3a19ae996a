//! `edtmap demo`: the main job with no arguments. Replays the built-in
//! `uav_pillars` scene (a drone among pillars with a 3D LiDAR) through the
//! pipeline, scores the occupancy against the scene's ground truth, and
//! writes the report and pictures under `./edtmap-out/`.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use crate::backend::BackendArg;
use crate::run::{execute, finish, RunArgs};

/// Arguments of `edtmap demo`.
#[derive(Args, Debug)]
pub(crate) struct DemoArgs {
    /// Folder for report.json and the pictures.
    #[arg(long, default_value = "edtmap-out")]
    out: PathBuf,
    /// Frames to replay (default: the whole flight).
    #[arg(long)]
    frames: Option<usize>,
    /// Compute backend: cpu, gpu, or auto (a hardware GPU if any, else cpu).
    #[arg(long, value_enum, default_value_t)]
    backend: BackendArg,
}

pub(crate) fn run(args: &DemoArgs) -> Result<()> {
    let run = RunArgs {
        scene: Some("uav_pillars".into()),
        config: None,
        frames: args.frames,
        out: args.out.clone(),
        eval: true,
        construction: None,
        voxel_size: None,
        integration: None,
        connectivity: None,
        planar: false,
        sensors: None,
        save: Some(args.out.join("map.edtmap")),
        prior: None,
        backend: args.backend,
        dataset: None,
        ply: false,
        slice_height: None,
        fixed_threads: false,
    };
    outln!(
        "edtmap demo: a drone flies among pillars with a 32-ring LiDAR; occupancy by volumetric projection, then the exact EDT of the 10 x 10 x 3 m volume around it, merged into the global EDT"
    );
    finish(&execute(&run, true)?)
}
