#!/usr/bin/env python3
"""Draws the benchmark pages' plots from their tables: reads the latest
table of each page under docs/benchmarks/ and writes docs/img/bench_*.png.
The tables are the source; run this after replacing one
(`pip install matplotlib`, then `python3 bench/plots.py`)."""

import re
import statistics
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PAGES = ROOT / "docs" / "benchmarks"
IMG = ROOT / "docs" / "img"


def table(page: str, first_header: str):
    """The rows of the table in `page` whose header starts with
    `first_header`, as dicts of the header's cells."""
    lines = (PAGES / page).read_text(encoding="utf-8").splitlines()
    start = next(i for i, l in enumerate(lines) if l.startswith("| " + first_header))
    cells = lambda l: [c.strip() for c in l.strip().strip("|").split("|")]
    header = cells(lines[start])
    rows = []
    for l in lines[start + 2:]:
        if not l.startswith("|"):
            break
        rows.append(dict(zip(header, cells(l))))
    return rows


def number(cell: str) -> float:
    """The cell's value: its first number, or the median of a list of runs
    (`1.80 1.81 1.81`); commas in thousands are dropped."""
    values = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?", cell.replace(",", "").split("(")[0].split("/")[0])]
    return statistics.median(values) if len(values) > 1 else values[0]


def bars(name, title, ylabel, labels, series, log=False):
    """Grouped bars: `series` is [(legend, values)], one value per label."""
    fig, ax = plt.subplots(figsize=(7.5, 3.6), dpi=100)
    width = 0.8 / len(series)
    for k, (legend, values) in enumerate(series):
        xs = [i + (k - (len(series) - 1) / 2) * width for i in range(len(labels))]
        ax.bar(xs, values, width, label=legend)
    ax.set_xticks(range(len(labels)), labels, fontsize=8)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    if log:
        ax.set_yscale("log")
    if len(series) > 1:
        ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(IMG / f"bench_{name}.png")
    plt.close(fig)
    print(f"wrote docs/img/bench_{name}.png")


def main():
    rows = table("batch-edt.md", "grid | scipy")
    cols = [("SciPy", "scipy (ms)"), ("edt.edt, 2 threads", "edt.edt parallel=2 (ms)"),
            ("edtmap", "edtmap (ms)"), ("edtmap + nearest", "edtmap +nearest (ms)")]
    bars("batch_edt", "Batch EDT (median ms, log scale)", "ms", [r["grid"] for r in rows],
         [(legend, [number(r[c]) for r in rows]) for legend, c in cols], log=True)

    rows = table("occupancy.md", "voxel (m) | OctoMap")
    bars("raycast", "Ray casting a Velodyne scan (ms)", "ms", [f"{r['voxel (m)']} m" for r in rows],
         [(c, [number(r[c]) for r in rows]) for c in ("OctoMap 1 thread", "OctoMap OpenMP (2)", "edtmap (2 threads)")])

    rows = table("global-edt.md", "scene | edtmap median")
    bars("dynamicedt", "Global EDT update per frame (median ms, log scale)", "ms", [r["scene"] for r in rows],
         [("edtmap", [number(r["edtmap median (ms)"]) for r in rows]),
          ("DynamicEDT3D", [number(r["DynamicEDT3D median (ms)"]) for r in rows])], log=True)

    rows = table("pipeline.md", "run | voxel (m) | window")
    bars("pipeline", "Pipeline per frame (median ms)", "ms", [r["run"] for r in rows],
         [("occupancy", [number(r["occupancy ms median / p95"]) for r in rows]),
          ("EDT", [number(r["EDT ms median / p95"]) for r in rows]),
          ("total", [number(r["total ms median / p95"]) for r in rows])])

    rows = table("planar.md", "voxel m | EDT | integrate")
    bars("planar", "A 2D log's map: 3D EDT against planar (MB, log scale)", "MB",
         [f"{r['voxel m']} m, {r['EDT']}" for r in rows],
         [(c, [number(r[c]) for r in rows]) for c in ("peak RSS MB", "map in memory MB", "file MB")], log=True)

    rows = [r for r in table("python.md", "grid | call") if r["grid"] != "queries"]
    calls = [("scipy", "SciPy"), ("edtmap.dte", "edtmap.distance_transform_edt"),
             ("edt.edt(p=2)", "edt.edt, 2 threads"), ("edtmap.edt", "edtmap.edt")]
    grids = list(dict.fromkeys(r["grid"] for r in rows))
    series = []
    for call, legend in calls:
        found = {r["grid"]: number(r["ms"]) for r in rows if r["call"] == call}
        if len(found) == len(grids):
            series.append((legend, [found[g] for g in grids]))
    if series:
        bars("python", "From Python: EDT of a grid (median ms, log scale)", "ms", grids, series, log=True)

    rows = table("node.md", "scene | sensor | frames mapped")
    bars("node", "edtmap node on loopback: frames mapped per second", "Hz", [r["scene"] for r in rows],
         [("rate", [number(r["rate Hz"]) for r in rows])])

    rows = table("recordings.md", "scene | source")
    bars("recordings", "A recording's replay against the simulated run (median s)", "s",
         [f"{r['scene'].split(' (')[0]}: {r['source'].split(' (')[0]}" for r in rows],
         [("median", [number(r["median s"]) for r in rows])])

    rows = table("sensors.md", "run | sensor | frames")
    bars("sensors", "Two sensors into one map: per frame (median ms)", "ms",
         [f"{r['run']}: {r['sensor']}" for r in rows],
         [("occupancy", [number(r["occupancy ms"]) for r in rows]),
          ("EDT update", [number(r["EDT update ms"]) for r in rows]),
          ("total", [number(r["total ms"]) for r in rows])])

    rows = table("capi.md", "measurement | points per call")
    bars("capi", "The C API against Rust (ns a point, log scale)", "ns",
         [f"{r['measurement']}, {r['points per call']}" for r in rows],
         [("Rust", [number(r["Rust ns/point"]) for r in rows]), ("C", [number(r["C ns/point"]) for r in rows])],
         log=True)

    rows = [r for r in table("gpu.md", "size | backend") if "not run" not in r["median (ms)"]]
    bars("gpu_batch_edt", "Batch EDT on lavapipe (a CPU Vulkan driver) and the CPU (median ms, log)", "ms",
         [f"{r['size']} {r['backend (device)'].split(':')[0].split(' (')[0]}" for r in rows],
         [("median", [number(r["median (ms)"]) for r in rows])], log=True)


if __name__ == "__main__":
    main()
