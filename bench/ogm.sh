#!/usr/bin/env bash
# Per-frame occupancy (OGM) time of both constructions on every built-in
# scene, from `edtmap run` reports, as a markdown table.
#
#   bash bench/ogm.sh [--frames N]
#
# Each scene runs once with volumetric projection and once with ray casting,
# interleaved, on the scene's shipped config; the table gives the median and
# 95th percentile of the `ogm` stage (construction + fusion + read-back of
# the local volume) and the batch EDT median. Reports land in bench/out/ogm/.
set -euo pipefail
cd "$(dirname "$0")/.."
frames=""
while [ $# -gt 0 ]; do
    case "$1" in
        --frames) frames="--frames $2"; shift 2 ;;
        *) echo "usage: bash bench/ogm.sh [--frames N]" >&2; exit 2 ;;
    esac
done
cargo build --release --locked --bin edtmap >&2
out=bench/out/ogm
mkdir -p "$out"
echo "| scene | sensor | voxel (m) | local volume | construction | ogm median (ms) | ogm p95 (ms) | batch EDT median (ms) |"
echo "|---|---|---|---|---|---|---|---|"
for scene in uav_pillars ugv_corridor room planar; do
    for construction in projection raycast; do
        dir="$out/$scene-$construction"
        # shellcheck disable=SC2086
        target/release/edtmap run --scene "$scene" --construction "$construction" --out "$dir" $frames >/dev/null
        python3 - "$dir/report.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
s = r["summary"]
dims = "x".join(str(d) for d in r["local_dims"])
print(f"| {r['scene']} | {r['sensor']} | {r['voxel_size_m']} | {dims} | {r['construction']} "
      f"| {s['ogm_ms']['median']:.2f} | {s['ogm_ms']['p95']:.2f} | {s.get('batch_edt_ms', {'median': 0.0})['median']:.2f} |")
PY
    done
done
