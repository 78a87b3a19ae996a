//! `edtmap edt`: exact EDT of an `.npy` grid.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use edtmap::cpu::edt::{ScanLayout, DEFAULT_TILE_LANES};
use edtmap::cpu::CpuBackend;
use edtmap::{BatchEdt, EdtField};
use edtmap_io::npy::{self, ObstacleNpy};

use crate::backend::{self, BackendArg};
use crate::interrupt::{self, OnFirst};
use crate::memory::ensure_fits;
use crate::timing::RunTimes;

/// Arguments of `edtmap edt`.
#[derive(Args, Debug)]
pub(crate) struct EdtArgs {
    /// Input grid: bool or integer dtype, 2 or 3 axes, nonzero = obstacle.
    input: PathBuf,
    /// Output: float32 distance in voxels (0 on obstacles, inf if none).
    output: PathBuf,
    /// Also write the nearest obstacle's index (int32, trailing axis of
    /// length ndim; -1 where there is none).
    #[arg(long, value_name = "IDX.npy")]
    nearest: Option<PathBuf>,
    /// Run the transform K times and print one JSON line of timings.
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(1..))]
    repeat: Option<u32>,
    /// Compute backend: cpu, gpu, or auto (a hardware GPU if any, else cpu).
    #[arg(long, value_enum, default_value_t = BackendArg::Cpu)]
    backend: BackendArg,
    /// Scan layout on the strided axes (for benchmarking).
    #[arg(long, value_enum, default_value_t = Layout::Tiled)]
    layout: Layout,
}

/// Scan layouts, see `edtmap_cpu::edt::ScanLayout`.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum Layout {
    /// Tiles of neighbouring lines, windowed minimum or lower envelope.
    Tiled,
    /// Tiles of neighbouring lines, lower envelope only.
    TiledEnvelope,
    /// One strided line at a time, lower envelope.
    PerLine,
}

/// Bytes per voxel the transform holds at its peak besides the input file's
/// elements: the obstacle mask, squared distances and nearest indices, the
/// float32 output.
const WORK_BYTES_PER_VOXEL: u64 = 1 + 4 + 4 + 4;

pub(crate) fn run(args: &EdtArgs) -> Result<()> {
    let mut outputs = vec![("OUT", args.output.as_path())];
    if let Some(nearest) = &args.nearest {
        outputs.push(("--nearest", nearest.as_path()));
    }
    edtmap_io::files::check_distinct_outputs(&outputs)?;
    for (_, path) in &outputs {
        edtmap_io::files::check_output(path)?;
    }
    let file = ObstacleNpy::open(&args.input)?;
    let layout = file.layout().clone();
    let ndim = layout.shape().len() as u64;
    let idx_bytes = if args.nearest.is_some() { 4 * ndim } else { 0 };
    let per_voxel = WORK_BYTES_PER_VOXEL + file.item_size() as u64 + idx_bytes;
    ensure_fits(
        &format!("{}: a grid of shape {:?}", args.input.display(), layout.shape()),
        per_voxel.saturating_mul(layout.len() as u64),
        "a smaller grid, or raise the budget with --max-memory",
    )?;
    // One transform has nothing to keep part-way: a signal stops at once,
    // leaving no partial output.
    let dirs: Vec<&Path> = outputs
        .iter()
        .map(|(_, p)| p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new(".")))
        .collect();
    interrupt::catch(OnFirst::Abandon, &dirs);
    let grid = file.read()?;
    let scan = match args.layout {
        Layout::Tiled => ScanLayout::default(),
        Layout::TiledEnvelope => ScanLayout::TiledEnvelope { lanes: DEFAULT_TILE_LANES },
        Layout::PerLine => ScanLayout::PerLine,
    };
    let mut backend = backend::open(args.backend, CpuBackend::with_layout(scan))?;
    // Buffers are reused across repeats, as a mapper reuses them per frame.
    let mut field = EdtField::empty();
    let (mut dist, mut idx) = (Vec::new(), Vec::new());
    let (result, times) = RunTimes::measure(args.repeat.unwrap_or(1) as usize, || {
        backend.batch_edt(&grid, &mut field)?;
        npy::distance_array(&field, &mut dist);
        if args.nearest.is_some() {
            npy::nearest_array(&layout, &field, &mut idx);
        }
        anyhow::Ok(())
    });
    result.with_context(|| format!("{}", args.input.display()))?;
    npy::write_distances(&args.output, &layout, &dist)?;
    if let Some(path) = &args.nearest {
        npy::write_nearest(path, &layout, &idx)?;
    }
    if args.repeat.is_some() {
        let line = serde_json::json!({
            "runs": times.runs(),
            "min_ms": times.min_ms(),
            "median_ms": times.median_ms(),
            "voxels": layout.len(),
            "backend": backend.name(),
        });
        outln!("{line}");
    }
    Ok(())
}
