#!/usr/bin/env python3
"""The edtmap Python package against SciPy and the `edt` package, in one run.

Usage (through the wrapper, which builds and installs the package into
bench/.venv-python): bash bench/python.sh [--repeat K] [--sizes 128,256]
[--points N] [--labels 500,3000] [--label-size 160] [--memory 384]
[--markdown FILE]

Transforms, on seeded n^3 grids with 1 % obstacles (zeros for SciPy's and
edt's convention), each call timed whole (argument conversion and output
arrays included), median (min) of K runs after a warm-up:
  scipy             scipy.ndimage.distance_transform_edt(grid)        (1 thread)
  edtmap.dte        edtmap.distance_transform_edt(grid)                (all cores)
  scipy+indices     the same with return_indices=True
  edtmap.dte+ind    the same with return_indices=True
  edt.edt(p=2)      edt.edt(grid, parallel=2)
  edtmap.edt        edtmap.edt(grid)                                    (parallel=0: all cores)
Each edtmap result is checked against its peer (exactly). Then many
labels: edt.edt and edtmap.edt of a --label-size^3 grid of L labels
(seeded cells of a coarse grid, 5 % background), ratio to edt.edt measured
in the same run. Then the peak memory above the input of each call on a
--memory^3 uint8 grid, each in a fresh interpreter (the peak resident
memory, VmHWM of /proc/self/status, after the call less before it; not
getrusage's ru_maxrss, which a child inherits from the parent it was forked
from; 0 skips). Then the query
throughput of Mapper.distance() (distance, gradient, state) for N points
spread over a mapped scene. Exits 1 on a mismatch.
"""
import argparse
from importlib.metadata import version
import os
import platform
import statistics
import subprocess
import sys
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


def label_grid(n, labels, seed):
    """n^3 labels 1..labels in blocks of a coarse grid, 5 % background."""
    rng = np.random.default_rng(seed)
    cells = max(round(labels ** (1 / 3)) + 1, 2)
    coarse = rng.integers(1, labels + 1, size=(cells,) * 3).astype(np.uint32)
    index = np.arange(n) * cells // n
    grid = coarse[np.ix_(index, index, index)]
    grid[rng.random(grid.shape) < 0.05] = 0
    return grid


# One call measured in a fresh interpreter: peak resident memory after the
# call less the peak before it, when the input is resident.
MEMORY_CHILD = """
import sys
import numpy as np
import edt, edtmap
from scipy import ndimage
n = int(sys.argv[1])
grid = np.ones((n, n, n), dtype=np.uint8)
rng = np.random.default_rng(n)
grid.reshape(-1)[rng.integers(0, grid.size, size=grid.size // 100)] = 0
small = np.ascontiguousarray(grid[:16, :16, :16])
calls = {
    "scipy.dte": lambda g: ndimage.distance_transform_edt(g),
    "edtmap.dte": lambda g: edtmap.distance_transform_edt(g),
    "scipy.dte+ind": lambda g: ndimage.distance_transform_edt(g, return_indices=True),
    "edtmap.dte+ind": lambda g: edtmap.distance_transform_edt(g, return_indices=True),
    "edt.edt": lambda g: edt.edt(g, parallel=2),
    "edtmap.edt": lambda g: edtmap.edt(g),
    "edtmap.obstacle_distance": lambda g: edtmap.obstacle_distance(g),
}
def peak_kib():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))
call = calls[sys.argv[2]]
call(small)
before = peak_kib()
out = call(grid)
print((peak_kib() - before) / 1024)
"""
MEMORY_CALLS = ["scipy.dte", "edtmap.dte", "scipy.dte+ind", "edtmap.dte+ind", "edt.edt", "edtmap.edt",
                "edtmap.obstacle_distance"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--sizes", default="128,256")
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--labels", default="500,3000")
    ap.add_argument("--label-size", type=int, default=160)
    ap.add_argument("--memory", type=int, default=384)
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

    n = args.label_size
    for count in [int(s) for s in args.labels.split(",") if s]:
        grid = label_grid(n, count, count)
        ok &= bool(np.array_equal(edt.edt(grid, parallel=2), edtmap.edt(grid)))
        theirs = timed(lambda: edt.edt(grid, parallel=2), args.repeat)
        ours = timed(lambda: edtmap.edt(grid), args.repeat)
        labels = len(np.unique(grid)) - 1
        for name, (med, lo) in [("edt.edt(p=2)", theirs), ("edtmap.edt", ours)]:
            ratio = f"{med / theirs[0]:.2f} of edt.edt(p=2)" if name == "edtmap.edt" else ""
            rows.append((f"{n}³, {labels} labels", name, f"{med:.1f} ({lo:.1f})", ratio))
            print(f"{n}^3 {labels} labels {name:14s} {med:9.1f} ms (min {lo:.1f}) {ratio}", flush=True)

    if args.memory:
        for name in MEMORY_CALLS:
            done = subprocess.run([sys.executable, "-c", MEMORY_CHILD, str(args.memory), name],
                                  capture_output=True, text=True)
            if done.returncode != 0:
                print(done.stderr)
                raise SystemExit(f"{name}: the memory run failed")
            mib = float(done.stdout.strip())
            rows.append((f"{args.memory}³ uint8", f"{name}, peak memory above the input", f"{mib:.0f} MiB", ""))
            print(f"{args.memory}^3 {name:26s} peak above the input {mib:7.0f} MiB", flush=True)

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
        lines = [f"Measured by `bash bench/python.sh` ({info}); median (min) of the runs, ms "
                 "(peak memory in MiB).", "", "| grid | call | ms | ratio |", "|---|---|---|---|"]
        lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
        Path(args.markdown).write_text("\n".join(lines) + "\n")
    if not ok:
        print("MISMATCH: an edtmap result differs from its peer")
        raise SystemExit(1)


if __name__ == "__main__":
    main()
