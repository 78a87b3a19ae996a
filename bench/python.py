#!/usr/bin/env python3
"""The edtmap Python package against SciPy and the `edt` package, in one run.

Usage (through the wrapper, which builds and installs the package into
bench/.venv-python): bash bench/python.sh [--repeat K] [--sizes 128,256]
[--points N] [--markdown FILE]

Transforms, on seeded n^3 grids with 1 % obstacles (zeros for SciPy's and
edt's convention), each call timed whole (argument conversion and output
arrays included), median (min) of K runs after a warm-up:
  scipy             scipy.ndimage.distance_transform_edt(grid)        (1 thread)
  edtmap.dte        edtmap.distance_transform_edt(grid)                (all cores)
  scipy+indices     the same with return_indices=True
  edtmap.dte+ind    the same with return_indices=True
  edt.edt(p=2)      edt.edt(grid, parallel=2)
  edtmap.edt        edtmap.edt(grid)                                    (parallel=0: all cores)
Each edtmap result is checked against its peer (exactly). Then the query
throughput of Mapper.distance() (distance, gradient, state) for N points
spread over a mapped scene. Exits 1 on a mismatch.
"""
import argparse
from importlib.metadata import version
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np
import edt
import scipy
from scipy import ndimage

import edtmap


def timed(fn, repeat):
    fn()
    runs = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        runs.append((time.perf_counter() - t) * 1e3)
    return statistics.median(runs), min(runs)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--sizes", default="128,256")
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--markdown")
    args = ap.parse_args()
    rows, ok = [], True
    for n in [int(s) for s in args.sizes.split(",")]:
        grid = (np.random.default_rng(n).random((n, n, n)) >= 0.01).astype(np.uint8)
        want_d = ndimage.distance_transform_edt(grid)
        got_d = edtmap.distance_transform_edt(grid)
        ok &= bool(np.array_equal(want_d, got_d))
        ok &= bool(np.array_equal(edt.edt(grid, parallel=2), edtmap.edt(grid)))
        results = {}
        for name, fn in [
            ("scipy", lambda: ndimage.distance_transform_edt(grid)),
            ("edtmap.dte", lambda: edtmap.distance_transform_edt(grid)),
            ("scipy+indices", lambda: ndimage.distance_transform_edt(grid, return_indices=True)),
            ("edtmap.dte+ind", lambda: edtmap.distance_transform_edt(grid, return_indices=True)),
            ("edt.edt(p=2)", lambda: edt.edt(grid, parallel=2)),
            ("edtmap.edt", lambda: edtmap.edt(grid)),
        ]:
            repeat = 1 if name.startswith("scipy") and n >= 256 else args.repeat
            results[name] = timed(fn, repeat)
        for name, (med, lo) in results.items():
            peer = {"edtmap.dte": "scipy", "edtmap.dte+ind": "scipy+indices", "edtmap.edt": "edt.edt(p=2)"}.get(name)
            ratio = f"{med / results[peer][0]:.2f} of {peer}" if peer else ""
            rows.append((f"{n}³", name, f"{med:.1f} ({lo:.1f})", ratio))
            print(f"{n}^3 {name:16s} {med:9.1f} ms (min {lo:.1f}) {ratio}", flush=True)

    # Query throughput on a mapped scene: a wall-and-pillars point cloud.
    rng = np.random.default_rng(1)
    mapper = edtmap.Mapper(edtmap.PointSensor(0.1, 30.0), 0.1, max_distance_m=2.0)
    cloud = np.concatenate([
        np.stack([np.full(20000, 6.0), rng.uniform(-5, 5, 20000), rng.uniform(-1.4, 1.4, 20000)], 1),
        np.stack([rng.uniform(-5, 5, 20000), np.full(20000, 4.0), rng.uniform(-1.4, 1.4, 20000)], 1),
    ])
    for x in (-4.0, 0.0, 4.0):
        pose = np.eye(4)
        pose[:3, 3] = [x, 0.0, 1.5]
        mapper.integrate_points(cloud - pose[:3, 3], pose)
    points = rng.uniform([-5, -5, 0.2], [6, 4, 2.8], size=(args.points, 3))
    med, lo = timed(lambda: mapper.distance(points), args.repeat)
    rate = args.points / (med / 1e3)
    print(f"Mapper.distance: {args.points} points in {med:.1f} ms (min {lo:.1f}): {rate / 1e6:.1f} M points/s")
    rows.append(("queries", f"Mapper.distance, {args.points} points", f"{med:.1f} ({lo:.1f})",
                 f"{rate / 1e6:.1f} M points/s"))
    info = (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
            f"{platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, edt {version('edt')}")
    print(info)
    if args.markdown:
        lines = [f"Measured by `bash bench/python.sh` ({info}); median (min) of the runs, ms.", "",
                 "| grid | call | ms | ratio |", "|---|---|---|---|"]
        lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
        Path(args.markdown).write_text("\n".join(lines) + "\n")
    if not ok:
        print("MISMATCH: an edtmap result differs from its peer")
        raise SystemExit(1)


if __name__ == "__main__":
    main()
