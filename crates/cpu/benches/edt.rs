//! Criterion benchmarks of the CPU batch EDT (with nearest obstacles).
//!
//! `cargo bench -p edtmap-cpu --bench edt`: random grids at 1% and 10%
//! obstacles, a structured pillar field, and the scan layouts compared on
//! one grid (the CPU counterpart of the paper's Table I).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use edtmap_core::{EdtField, Grid3};
use edtmap_cpu::edt::{edt_into, ScanLayout};
use edtmap_sim::{pillar_field, random_grid, PillarField};
use std::time::Duration;

fn run(c: &mut Criterion, group: &str, name: &str, grid: &Grid3<bool>, layout: ScanLayout) {
    let mut g = c.benchmark_group(group);
    g.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(6));
    g.throughput(Throughput::Elements(grid.len() as u64));
    let mut field = EdtField::empty();
    g.bench_function(BenchmarkId::from_parameter(name), |b| {
        b.iter(|| edt_into(grid, |&o| o, layout, &mut field).expect("valid grid"))
    });
    g.finish();
}

fn grids(c: &mut Criterion) {
    for n in [128, 256] {
        for (pct, density) in [(1, 0.01), (10, 0.1)] {
            let grid = random_grid([n, n, n], density, 1).expect("valid dims");
            run(c, "edt", &format!("random{n}_{pct}pct"), &grid, ScanLayout::default());
        }
    }
    let grid = pillar_field(&PillarField::new([256, 256, 256], 1)).expect("valid dims");
    run(c, "edt", "pillars256", &grid, ScanLayout::default());
}

fn layouts(c: &mut Criterion) {
    let grid = random_grid([256, 256, 256], 0.01, 1).expect("valid dims");
    run(c, "edt_layout", "per_line", &grid, ScanLayout::PerLine);
    for lanes in [8, 16, 64] {
        let layout = ScanLayout::TiledEnvelope { lanes };
        run(c, "edt_layout", &format!("tiled_envelope{lanes}"), &grid, layout);
    }
    for lanes in [8, 16, 32, 64, 128] {
        run(c, "edt_layout", &format!("tiled{lanes}"), &grid, ScanLayout::Tiled { lanes });
    }
}

criterion_group!(benches, grids, layouts);
criterion_main!(benches);
