#!/usr/bin/env bash
# Two sensors into one map against each sensor alone: the corridor robot's
# LiDAR and its low depth camera (configs/ugv_corridor_camera.toml), run
# with both and with each alone (`--sensors`), the three runs alternating.
# Prints, per run and sensor, the median time per frame (occupancy, EDT
# update, total) and the final map against the scene's ground truth.
#
#   bash bench/sensors.sh [--frames N] [--repeat N]
#
#   --frames N     time steps (default 150, the scene's length); each gives
#                  one frame of every sensor mapped
#   --repeat N     run each case N times (default 3)
#   EDTMAP=PATH    use a built binary instead of `cargo build --release`
#
# Reports are kept in bench/out/sensors/.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
frames=150
repeat=3
while [ $# -gt 0 ]; do
    case "$1" in
        --frames) frames="$2"; shift 2 ;;
        --repeat) repeat="$2"; shift 2 ;;
        -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
        *) echo "sensors.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
if [ -z "${EDTMAP:-}" ]; then
    (cd "$root" && cargo build --release -q -p edtmap-cli)
    target=$(cargo metadata -q --format-version 1 --no-deps --manifest-path "$root/Cargo.toml" |
             python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
    EDTMAP="$target/release/edtmap"
fi
out="$root/bench/out/sensors"
mkdir -p "$out"
config="$root/configs/ugv_corridor_camera.toml"
dirs=()
for r in $(seq 1 "$repeat"); do
    for case in lidar_top front_camera lidar_top,front_camera; do
        dir="$out/$case-$r"
        echo "sensors.sh: $case, run $r" >&2
        "$EDTMAP" run --config "$config" --frames "$frames" --eval --sensors "$case" --out "$dir" >/dev/null
        dirs+=("$dir")
    done
done
python3 - "${dirs[@]}" <<'PY'
import json, statistics, sys
print("| run | sensor | frames | occupancy ms | EDT update ms | total ms | map: true occupied / false occupied voxels |")
print("|---|---|---|---|---|---|---|")
for d in sys.argv[1:]:
    r = json.load(open(f"{d}/report.json"))
    case = d.rsplit("/", 1)[1]
    m = r.get("map_eval") or {}
    for s in r["sensors"]:
        f = [x for x in r["frames"] if x["sensor"] == s["name"]]
        med = lambda k: statistics.median(x[k] for x in f)
        print(f"| {case} | {s['name']} | {len(f)} | {med('ogm_ms'):.2f} | {med('integrate_ms'):.2f} | "
              f"{med('total_ms'):.2f} | {m.get('true_occupied_voxels')} / {m.get('false_occupied_voxels')} |")
PY
