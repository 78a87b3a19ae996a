#!/usr/bin/env bash
# Ray-casting throughput on a real LiDAR scan: edtmap against OctoMap's
# OcTree::insertPointCloud, side by side, at 0.1 m and 0.2 m voxels.
#
# Usage:
#   bench/raycast.sh [--quick] [--repeat N] [--max-range R] [--pcd FILE]
#                    [--voxels "0.1 0.2"] [--no-omp]
#
#   --quick        3 repeats instead of 7
#   --repeat N     repeats per tool and voxel size (default 7)
#   --max-range R  maximum range in metres, the same for both tools (default 30)
#   --pcd FILE     the scan (default ../shared/data/velodyne-pair/251370668.pcd,
#                  relative to the repository root)
#   --voxels LIST  voxel sizes in metres (default "0.1 0.2")
#   --no-omp       skip the OpenMP build of the OctoMap harness
#
# What it does:
#   1. Installs liboctomap-dev when missing (apt-get, when run as root;
#      otherwise it says what to install).
#   2. Compiles bench/octomap/raycast_octomap.cpp with g++ -O3 -march=native
#      into bench/out/: raycast_octomap (one thread, as the Debian library
#      is built) and raycast_octomap_omp (-fopenmp: OctoMap's own OpenMP
#      loop in computeUpdate, OMP_NUM_THREADS or all cores).
#   3. Builds the edtmap example raycast_pcd (release), then for each voxel
#      size runs, one after the other so that all see the same machine load:
#        bench/out/raycast_octomap     PCD V R N
#        bench/out/raycast_octomap_omp PCD V R N
#        cargo run --release -q -p edtmap --example raycast_pcd -- PCD \
#            --voxel-size V --max-range R --repeat N
#      Each prints one JSON line (median_ms, min_ms, points, ...); all lines
#      are kept in bench/out/raycast-<time>.jsonl.
#   4. Prints a markdown table: voxel size, max range, OctoMap median ms (one
#      thread and OpenMP), edtmap median ms, and the speed-up OctoMap/edtmap
#      against the faster of the two OctoMap builds.
#
# Both sides insert the same points from the origin with the same maximum
# range; points beyond it clear space up to it. Each repeat starts from an
# empty map (a fresh OcTree; a fresh edtmap map) and only the insertion is
# timed. The OctoMap harness drops non-finite points and points at (0,0,0),
# the scanner's "no return" marker. Honours CARGO_TARGET_DIR.
#
# Needs: bash, g++, python3 (stdlib json only), cargo.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
OUT="$ROOT/bench/out"
PCD="$ROOT/../shared/data/velodyne-pair/251370668.pcd"
REPEAT=7
MAX_RANGE=30
VOXELS="0.1 0.2"
OMP=1

usage() { sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d' | sed 's/^# \{0,1\}//'; }

while [[ $# -gt 0 ]]; do
    case "$1" in
        --quick) REPEAT=3; shift ;;
        --repeat) REPEAT=${2:?--repeat needs a value}; shift 2 ;;
        --max-range) MAX_RANGE=${2:?--max-range needs a value}; shift 2 ;;
        --pcd) PCD=${2:?--pcd needs a file}; shift 2 ;;
        --voxels) VOXELS=${2:?--voxels needs a list}; shift 2 ;;
        --no-omp) OMP=0; shift ;;
        -h|--help) usage; exit 0 ;;
        *) echo "raycast.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
done

[[ -f "$PCD" ]] || { echo "raycast.sh: no such scan: $PCD (use --pcd FILE)" >&2; exit 1; }
PCD=$(cd "$(dirname "$PCD")" && pwd)/$(basename "$PCD")
mkdir -p "$OUT"

# 1. OctoMap.
if ! dpkg -s liboctomap-dev >/dev/null 2>&1; then
    if [[ $(id -u) -eq 0 ]]; then
        echo "raycast.sh: installing liboctomap-dev" >&2
        apt-get install -y -q liboctomap-dev >&2 || { apt-get update -q >&2 && apt-get install -y -q liboctomap-dev >&2; }
    else
        echo "raycast.sh: liboctomap-dev is missing; install it (sudo apt-get install liboctomap-dev)" >&2
        exit 1
    fi
fi

# 2. The harness, rebuilt when its source is newer than the binary.
SRC="$ROOT/bench/octomap/raycast_octomap.cpp"
build() { # build OUTPUT [extra flags]
    local bin=$1; shift
    if [[ ! -x "$bin" || "$SRC" -nt "$bin" ]]; then
        echo "raycast.sh: compiling $(basename "$bin")" >&2
        g++ -O3 -march=native -std=c++17 "$@" -o "$bin" "$SRC" -loctomap -loctomath
    fi
}
build "$OUT/raycast_octomap"
[[ $OMP -eq 1 ]] && build "$OUT/raycast_octomap_omp" -fopenmp
THREADS=${OMP_NUM_THREADS:-$(nproc)}

# 3. The edtmap example.
EDTMAP=1
if [[ ! -f "$ROOT/crates/edtmap/examples/raycast_pcd.rs" ]]; then
    EDTMAP=0
    echo "raycast.sh: the edtmap example crates/edtmap/examples/raycast_pcd.rs is missing; only OctoMap is measured" >&2
else
    echo "raycast.sh: building the edtmap example raycast_pcd (release)" >&2
    (cd "$ROOT" && cargo build --release -q -p edtmap --example raycast_pcd) || {
        EDTMAP=2
        echo "raycast.sh: building the edtmap example raycast_pcd failed; only OctoMap is measured" >&2
    }
fi

LOG="$OUT/raycast-$(date +%Y%m%d-%H%M%S).jsonl"
: >"$LOG"
run() { # run LABEL COMMAND...: appends its JSON line to $LOG, echoes it to stderr
    local label=$1; shift
    local line
    if ! line=$("$@" | tail -n 1) || [[ "$line" != \{* ]]; then
        echo "raycast.sh: $label failed" >&2
        line="{\"tool\":\"$label\",\"failed\":true}"
    fi
    echo "$line" >&2
    python3 -c 'import json,sys; d=json.loads(sys.argv[1]); d["run"]=sys.argv[2]; print(json.dumps(d))' "$line" "$label" >>"$LOG"
}

for V in $VOXELS; do
    echo "raycast.sh: voxel ${V} m, max range ${MAX_RANGE} m, ${REPEAT} repeats" >&2
    run "octomap:$V" "$OUT/raycast_octomap" "$PCD" "$V" "$MAX_RANGE" "$REPEAT"
    if [[ $OMP -eq 1 ]]; then
        OMP_NUM_THREADS=$THREADS run "octomap_omp:$V" "$OUT/raycast_octomap_omp" "$PCD" "$V" "$MAX_RANGE" "$REPEAT"
    fi
    if [[ $EDTMAP -eq 1 ]]; then
        (cd "$ROOT" && run "edtmap:$V" cargo run --release -q -p edtmap --example raycast_pcd -- \
            "$PCD" --voxel-size "$V" --max-range "$MAX_RANGE" --repeat "$REPEAT")
    fi
done

# 4. The table.
python3 - "$LOG" "$VOXELS" "$MAX_RANGE" "$REPEAT" "$EDTMAP" "$OMP" "$THREADS" "$PCD" <<'EOF'
import json, os, sys

log, voxels, max_range, repeat, edtmap, omp, threads, pcd = sys.argv[1:9]
runs = {}
with open(log) as f:
    for line in f:
        d = json.loads(line)
        runs[d["run"]] = d

def ms(d):
    return d.get("median_ms") if d and not d.get("failed") else None

def fmt(x, spec=".1f"):
    return format(x, spec) if x is not None else "n/a"

try:
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
except OSError:
    load = "?"
print(f"\nScan {os.path.basename(pcd)}, {repeat} repeats, {os.cpu_count()} cores, load average {load} (after the runs)")
print()
head = ["voxel (m)", "max range (m)", "points", "OctoMap 1 thread (ms)"]
if omp == "1":
    head.append(f"OctoMap OpenMP {threads} thr. (ms)")
head += ["edtmap (ms)", "speed-up", "occupied: OctoMap / edtmap"]
print("| " + " | ".join(head) + " |")
print("|" + "|".join("---:" for _ in head) + "|")
for v in voxels.split():
    o1 = runs.get(f"octomap:{v}")
    om = runs.get(f"octomap_omp:{v}")
    e = runs.get(f"edtmap:{v}")
    best = min((x for x in (ms(o1), ms(om)) if x is not None), default=None)
    row = [v, max_range, str((o1 or {}).get("points", "?")), fmt(ms(o1))]
    if omp == "1":
        row.append(fmt(ms(om)))
    if edtmap == "1":
        em = ms(e)
        row.append(fmt(em, ".2f"))
        row.append(f"{best / em:.1f}x" if best is not None and em else "n/a")
        row.append(f"{(o1 or {}).get('occupied_voxels', '?')} / {(e or {}).get('occupied_voxels', '?')}")
    else:
        row += ["missing", "n/a", f"{(o1 or {}).get('occupied_voxels', '?')} / -"]
    print("| " + " | ".join(row) + " |")
print()
print("Medians over the repeats; speed-up = the faster OctoMap median / edtmap median.")
if edtmap == "0":
    print("The edtmap example crates/edtmap/examples/raycast_pcd.rs is missing: only OctoMap was measured.")
elif edtmap == "2":
    print("The edtmap example raycast_pcd failed to build (see above): only OctoMap was measured.")
print(f"JSON lines: {log}")
EOF
