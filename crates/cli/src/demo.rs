//! `edtmap demo`: the built-in demonstration.
//!
//! Until the mapping pipeline lands, the demo rasterises a pillar field
//! (the paper's UAV-Pillar world) into a 3D grid, runs the exact batch EDT
//! and draws a horizontal slice of it.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use edtmap::cpu::edt::{edt_into, ScanLayout};
use edtmap::{EdtField, Grid3};
use edtmap_io::picture::{write_slice_png, Slice, SliceStyle};
use edtmap_sim::{pillar_field, PillarField};

use crate::memory::ensure_fits;
use crate::timing::RunTimes;

/// Arguments of `edtmap demo`.
#[derive(Args, Debug)]
pub(crate) struct DemoArgs {
    /// Folder for the pictures.
    #[arg(long, default_value = "edtmap-out")]
    out: PathBuf,
    /// Grid dimensions in voxels, x y z.
    #[arg(long, num_args = 3, value_names = ["NX", "NY", "NZ"], default_values_t = [256, 256, 64])]
    dims: Vec<usize>,
    /// Voxel edge length in metres.
    #[arg(long, default_value_t = 0.1)]
    voxel_size_m: f64,
    /// Height of the pictured slice in metres.
    #[arg(long, default_value_t = 2.0)]
    slice_height_m: f64,
    /// Seed of the pillar placement.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// Runs of the EDT whose median the demo reports.
const TIMED_RUNS: usize = 5;

/// Memory per voxel: the obstacle grid, the EDT field, the slice.
const DEMO_BYTES_PER_VOXEL: u64 = 1 + 4 + 4;

pub(crate) fn run(args: &DemoArgs) -> Result<()> {
    anyhow::ensure!(
        args.voxel_size_m.is_finite() && args.voxel_size_m > 0.0,
        "--voxel-size-m must be positive, got {}",
        args.voxel_size_m
    );
    let dims = [args.dims[0], args.dims[1], args.dims[2]];
    let voxels = Grid3::<bool>::voxel_count(dims).context("--dims")? as u64;
    ensure_fits(&format!("a demo grid of {dims:?} voxels"), voxels.saturating_mul(DEMO_BYTES_PER_VOXEL))?;
    let grid = pillar_field(&PillarField::new(dims, args.seed)).context("--dims")?;
    let obstacles = grid.as_slice().iter().filter(|&&o| o).count();
    let vox = args.voxel_size_m;
    println!(
        "edtmap demo: pillar field of {} x {} x {} voxels ({:.1} x {:.1} x {:.1} m at {vox} m), {obstacles} obstacle voxels",
        dims[0], dims[1], dims[2],
        dims[0] as f64 * vox, dims[1] as f64 * vox, dims[2] as f64 * vox,
    );
    // The first run allocates the field; later ones reuse it, as a mapper
    // does from frame to frame.
    let mut field = EdtField::empty();
    let mut run = || edt_into(&grid, |&o| o, ScanLayout::default(), &mut field);
    let (first, cold) = RunTimes::measure(1, &mut run);
    first?;
    let (warm, times) = RunTimes::measure(TIMED_RUNS, &mut run);
    warm?;
    println!(
        "batch EDT with nearest obstacles (CPU, {} threads): first run {:.1} ms, then median {:.1} ms, min {:.1} ms over {} runs ({:.0} Mvoxel/s)",
        rayon::current_num_threads(),
        cold.median_ms(),
        times.median_ms(),
        times.min_ms(),
        times.runs(),
        grid.len() as f64 / times.median_ms() / 1e3,
    );
    let z = ((args.slice_height_m / vox).floor().max(0.0) as usize).min(dims[2] - 1);
    let plane = dims[0] * dims[1];
    let slice_m: Vec<f32> = (z * plane..(z + 1) * plane)
        .map(|i| field.distance_vox(i) * vox as f32)
        .collect();
    let max_m = slice_m.iter().copied().filter(|v| v.is_finite()).fold(0.0f32, f32::max);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let path = args.out.join("edt_slice.png");
    let style = SliceStyle {
        title: format!("distance to nearest obstacle z={:.2} m", (z as f64 + 0.5) * vox),
        unit: "m".into(),
        max_value: None,
    };
    write_slice_png(&path, Slice { width: dims[0], height: dims[1], values: &slice_m }, &style)?;
    println!("slice at z = {:.2} m: max distance {max_m:.2} m; wrote {}", (z as f64 + 0.5) * vox, path.display());
    Ok(())
}
