#!/usr/bin/env bash
# A long 2D laser log mapped as a 3D EDT and as a planar map (`--planar`):
# time per scan, peak memory, the map's bytes in memory and on disk, per
# mapped cell, with the two kinds of run alternated in one loop.
#
#   bash bench/planar.sh [--frames N] [--repeat N] [--voxels "0.1 0.05"]
#
#   --frames N     scans in the log (default 3000): `edtmap record --scene
#                  planar`, a drone circling a cluttered 20 x 20 m floor
#                  with a 720-beam planar LiDAR
#   --repeat N     run each case N times (default 3)
#   --voxels L     voxel sizes, metres (default "0.1 0.05")
#   EDTMAP=PATH    use a built binary instead of `cargo build --release`
#
# "Mapped cells" are the map's observed voxels (free or occupied), the
# report's `map_bytes_per_mapped_voxel`. Files and reports are kept in
# bench/out/planar/.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
frames=3000
repeat=3
voxels="0.1 0.05"
while [ $# -gt 0 ]; do
    case "$1" in
        --frames) frames="$2"; shift 2 ;;
        --repeat) repeat="$2"; shift 2 ;;
        --voxels) voxels="$2"; shift 2 ;;
        -h|--help) sed -n '2,17p' "$0"; exit 0 ;;
        *) echo "planar.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
if [ -z "${EDTMAP:-}" ]; then
    (cd "$root" && cargo build --release -q -p edtmap-cli)
    target=$(cargo metadata -q --format-version 1 --no-deps --manifest-path "$root/Cargo.toml" |
             python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
    EDTMAP="$target/release/edtmap"
fi
out="$root/bench/out/planar"
mkdir -p "$out"
log="$out/log-$frames.mcap"
[ -f "$log" ] || "$EDTMAP" record --scene planar --frames "$frames" --force "$log" >/dev/null
runs=()
for v in $voxels; do
    for r in $(seq 1 "$repeat"); do
        for kind in 3d planar; do
            dir="$out/$v-$kind-$r"
            flag=()
            [ "$kind" = planar ] && flag=(--planar)
            echo "planar.sh: $frames scans at $v m, $kind, run $r" >&2
            "$EDTMAP" run --config "${log%.mcap}.toml" --dataset "$log" --voxel-size "$v" "${flag[@]}" \
                --out "$dir" --save "$dir.edtmap" >/dev/null 2>"$dir.log" ||
                { echo "planar.sh: $kind failed at $v m, see $dir.log" >&2; exit 1; }
            runs+=("$v|$kind|$dir")
        done
    done
done
python3 - "${runs[@]}" <<'EOF'
import json, os, statistics, sys
from collections import defaultdict
med = statistics.median
rows = defaultdict(list)
for arg in sys.argv[1:]:
    v, kind, d = arg.split("|")
    r = json.load(open(f"{d}/report.json"))
    f = r["frames"][1:]
    last = r["frames"][-1]
    cells = last["map_bytes"] / last["map_bytes_per_mapped_voxel"]
    rows[(v, kind)].append({
        "integrate_ms": med(x["integrate_ms"] for x in f),
        "total_ms": med(x["total_ms"] for x in f),
        "peak_rss_mb": r["peak_rss_bytes"] / 1e6,
        "map_mb": last["map_bytes"] / 1e6,
        "file_mb": os.path.getsize(f"{d}.edtmap") / 1e6,
        "cells": cells,
    })
keys = ["integrate_ms", "total_ms", "peak_rss_mb", "map_mb", "file_mb"]
print("Per scan (median over the scans after the first) and at the end; one value per run:\n")
print("| voxel m | EDT | mapped cells | " + " | ".join(keys) + " |")
print("|---|---|---|" + "---|" * len(keys))
for (v, kind), runs in rows.items():
    print(f"| {v} | {kind} | {runs[0]['cells']:.0f} | " + " | ".join(", ".join(f"{x[k]:.2f}" for x in runs) for k in keys) + " |")
print("\n3D over planar (medians of the runs; bytes per mapped cell where both map the same cells):\n")
print("| voxel m | integrate | total | peak RSS | map bytes per cell | file bytes per cell |")
print("|---|---|---|---|---|---|")
for v in dict.fromkeys(k[0] for k in rows):
    a, b = rows.get((v, "3d")), rows.get((v, "planar"))
    if not a or not b:
        continue
    m = lambda runs, k: med(x[k] for x in runs)
    per = lambda runs, k: m(runs, k) / runs[0]["cells"]
    print(f"| {v} | {m(a, 'integrate_ms') / m(b, 'integrate_ms'):.2f} | {m(a, 'total_ms') / m(b, 'total_ms'):.2f} | "
          f"{m(a, 'peak_rss_mb') / m(b, 'peak_rss_mb'):.2f} | {per(a, 'map_mb') / per(b, 'map_mb'):.2f} | "
          f"{per(a, 'file_mb') / per(b, 'file_mb'):.2f} |")
EOF
