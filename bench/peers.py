#!/usr/bin/env python3
"""Compare edtmap's exact 3D EDT with scipy and the `edt` package, side by side.

Usage (normally through the wrapper, which sets up bench/.venv):
    bash bench/peers.sh                 # full run: 128^3 and 256^3 grids
    bash bench/peers.sh --quick         # smoke run: 64^3 versions of each grid
    bash bench/peers.sh --repeat 9 --markdown docs/peers_table.md
Options: --repeat K (timed runs per method, default 5), --sizes full|small
(--quick == --sizes small), --workdir DIR (default bench/out), --edtmap PATH
(default target/release/edtmap), --seed S, --markdown FILE.

Methods, each timed on the same grids in one run (median (min) in ms):
  scipy          scipy.ndimage.distance_transform_edt(free)          (1 thread)
  scipy+indices  the same with return_indices=True                   (1 thread)
  edt.edt        edt.edt(free.astype(uint8), parallel=2)
  edtmap         `edtmap edt IN OUT --repeat K`, its own JSON median_ms
  edtmap+nearest `edtmap edt IN OUT --nearest IDX --repeat K`
Obstacles are nonzero in our grids; scipy and edt measure distance to the
nearest zero, so both are given the free-space mask (mask == 0).
Python timings use time.perf_counter() after one warm-up call; edtmap times
only the transform (no file I/O). Check column: edtmap's distances must equal
scipy's cast to float32 exactly, and every IDX entry must be an obstacle whose
distance recomputed from the index equals scipy's. Exits 1 on any mismatch.
"""
import argparse, json, os, platform, statistics, subprocess, sys, time
from importlib.metadata import version
from pathlib import Path

import numpy as np
import edt
from scipy import ndimage

REPO = Path(__file__).resolve().parent.parent


def random_grid(rng, n, frac):
    return rng.random((n, n, n)) < frac


def struct_grid(rng, n):
    """Floor, outer walls, an inner wall with a doorway, vertical pillars (axis 0 = z)."""
    s = n / 256
    a = np.zeros((n, n, n), dtype=bool)
    a[0, :, :] = True                                   # floor
    a[:, 0, :] = a[:, -1, :] = a[:, :, 0] = a[:, :, -1] = True   # outer walls
    mid = n // 2
    a[:, :, mid] = True                                 # inner wall across axis 2
    door_w, door_h = max(2, int(24 * s)), max(3, int(80 * s))
    a[1:1 + door_h, mid - door_w // 2: mid + door_w // 2, mid] = False
    yy, xx = np.mgrid[0:n, 0:n]
    foot = np.zeros((n, n), dtype=bool)
    for _ in range(max(1, round(160 * s * s))):         # ~160 pillars at 256^3
        cy, cx = rng.uniform(0, n, size=2)
        r = rng.uniform(5, 10) * max(s, 0.25)
        foot |= (yy - cy) ** 2 + (xx - cx) ** 2 <= r * r
    a |= foot[None, :, :]
    return a


def make_grids(sizes, seed):
    rng = np.random.default_rng(seed)
    ns = [64] if sizes == "small" else [128, 256]
    grids = {}
    for n in ns:
        for pct in (1, 10):
            grids[f"rand{n}_{pct}"] = random_grid(rng, n, pct / 100)
    n = ns[-1]
    grids[f"struct{n}"] = struct_grid(rng, n)
    return grids


def time_py(fn, k):
    fn()  # warm-up
    ts = []
    for _ in range(k):
        t0 = time.perf_counter()
        fn()
        ts.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(ts), min(ts)


def run_edtmap(exe, args, k, voxels):
    cmd = [str(exe), "edt", *map(str, args), "--repeat", str(k)]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"edtmap failed ({p.returncode}): {' '.join(cmd)}\n{p.stderr}")
    lines = [l for l in p.stdout.splitlines() if l.strip()]
    try:
        rec = json.loads(lines[-1])
        med, mn = float(rec["median_ms"]), float(rec["min_ms"])
    except (IndexError, ValueError, KeyError) as e:
        sys.exit(f"unexpected edtmap stdout ({e!r}) from {' '.join(cmd)}:\n{p.stdout}")
    if rec.get("runs") != k or rec.get("voxels") != voxels:
        print(f"warning: edtmap reported runs={rec.get('runs')} voxels={rec.get('voxels')},"
              f" expected {k} and {voxels}", file=sys.stderr)
    return med, mn


def check(name, mask, ref32, dist, idx):
    """Return a list of problems (empty = OK) for edtmap's outputs vs scipy."""
    bad = []
    for label, d in (("dist", dist[0]), ("dist(+nearest)", dist[1])):
        if d.dtype != np.float32 or d.shape != mask.shape:
            bad.append(f"{label}: dtype/shape {d.dtype}{d.shape}")
        elif not np.array_equal(d, ref32):
            diff = np.abs(d.astype(np.float64) - ref32)
            bad.append(f"{label}: {np.count_nonzero(d != ref32)} voxels differ, "
                       f"max |diff| {np.nanmax(diff):.6g}")
    if idx.dtype != np.int32 or idx.shape != mask.shape + (mask.ndim,):
        return bad + [f"idx: dtype/shape {idx.dtype}{idx.shape}"]
    if idx.min() < 0 or any(idx[..., a].max() >= n for a, n in enumerate(mask.shape)):
        return bad + ["idx: out of range"]
    if not mask[tuple(idx[..., a] for a in range(mask.ndim))].all():
        bad.append("idx: points at free voxels")
    sq = np.zeros(mask.shape, dtype=np.int64)
    for a, n in enumerate(mask.shape):
        shape = [1] * mask.ndim
        shape[a] = n
        sq += (idx[..., a].astype(np.int64) - np.arange(n).reshape(shape)) ** 2
    d_idx = np.sqrt(sq).astype(np.float32)
    if not np.array_equal(d_idx, ref32):
        bad.append(f"idx: {np.count_nonzero(d_idx != ref32)} voxels at wrong distance, "
                   f"max |diff| {np.abs(d_idx.astype(np.float64) - ref32).max():.6g}")
    for b in bad:
        print(f"  {name}: {b}", file=sys.stderr)
    return bad


def machine_line():
    model = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo")
                  if l.startswith("model name")), platform.processor() or "unknown CPU")
    nproc = subprocess.run(["nproc"], capture_output=True, text=True).stdout.strip()
    return (f"Machine: {nproc} cores (nproc), {model}; Python {platform.python_version()}, "
            f"numpy {np.__version__}, scipy {version('scipy')}, edt {version('edt')}; "
            f"load average at start {os.getloadavg()[0]:.2f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--sizes", choices=["full", "small"], default="full")
    ap.add_argument("--quick", action="store_true", help="same as --sizes small")
    ap.add_argument("--workdir", type=Path, default=REPO / "bench" / "out")
    ap.add_argument("--edtmap", type=Path, default=REPO / "target" / "release" / "edtmap")
    ap.add_argument("--seed", type=int, default=20240601)
    ap.add_argument("--markdown", type=Path, help="also write machine line + table here")
    args = ap.parse_args()
    if not args.edtmap.is_file():
        sys.exit(f"edtmap binary not found: {args.edtmap} (cargo build --release)")
    k, w = args.repeat, args.workdir
    w.mkdir(parents=True, exist_ok=True)
    head = machine_line()
    print(head, flush=True)

    fmt = lambda m: f"{m[0]:.1f} ({m[1]:.1f})"
    rows, failed = [], False
    for name, mask in make_grids("small" if args.quick else args.sizes, args.seed).items():
        print(f"{name}: {mask.shape}, {mask.mean():.2%} obstacles ...", file=sys.stderr, flush=True)
        src, out, out_n, idx_p = (w / f"{name}{s}.npy" for s in ("", "_dist", "_distn", "_idx"))
        np.save(src, mask.astype(np.uint8))
        free = mask == 0
        free_u8 = free.astype(np.uint8)
        t_sp = time_py(lambda: ndimage.distance_transform_edt(free), k)
        t_spi = time_py(lambda: ndimage.distance_transform_edt(free, return_indices=True), k)
        t_edt = time_py(lambda: edt.edt(free_u8, black_border=False, parallel=2), k)
        t_em = run_edtmap(args.edtmap, [src, out], k, mask.size)
        t_emn = run_edtmap(args.edtmap, [src, out_n, "--nearest", idx_p], k, mask.size)

        ref32 = ndimage.distance_transform_edt(free).astype(np.float32)
        e = edt.edt(free_u8, black_border=False, parallel=2)
        if np.abs(e.astype(np.float64) - ref32).max() > 1e-3:
            print(f"  note: edt.edt differs from scipy on {name}", file=sys.stderr)
        bad = check(name, mask, ref32, (np.load(out), np.load(out_n)), np.load(idx_p))
        failed |= bool(bad)
        rows.append([name, fmt(t_sp), fmt(t_spi), fmt(t_edt), fmt(t_em), fmt(t_emn),
                     f"{t_emn[0] / t_edt[0]:.2f}x", "MISMATCH" if bad else "OK"])

    cols = ["grid", "scipy (ms)", "scipy+indices (ms)", "edt.edt parallel=2 (ms)",
            "edtmap (ms)", "edtmap +nearest (ms)", "edtmap+nearest / edt.edt", "check"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    note = (f"Times: median (min) of {k} runs in ms; Python timings after one warm-up. "
            "scipy is single-threaded; ratio uses medians (<1 means edtmap is faster).")
    table = "\n".join(lines)
    print(f"\n{table}\n\n{note}")
    if args.markdown:
        args.markdown.write_text(f"{head}\n\n{table}\n\n{note}\n")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
