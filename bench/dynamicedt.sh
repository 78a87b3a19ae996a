#!/usr/bin/env bash
# Incremental global EDT: edtmap against DynamicEDT3D (Lau et al., the CPU
# baseline of the GIE-mapping paper) on the same sequence of occupancy
# changes, and the paper's Fig. 4 (EDT update time against the change score).
#
# Usage:
#   bench/dynamicedt.sh [--repeat N] [--recording-repeat N] [--frames N]
#                                          (both scenes and both recordings)
#   bench/dynamicedt.sh [--repeat N] [--out PREFIX] CHANGES_FILE
#
#   --repeat N    replay each whole sequence N times from empty; each frame
#                 keeps its minimum time, on both sides (default 3)
#   --recording-repeat N
#                 the same for the recordings, whose 5 and 2 frames need
#                 more runs for a stable time (default 10)
#   --frames N    default mode: replay only the first N frames of each scene
#                 (default: the scene's length, 120 and 150 frames); the
#                 recordings always run whole
#   EDTMAP_DATA=DIR  the shared recordings (default ../shared/data beside
#                 the checkout); without them only the scenes run
#   --out PREFIX  single-file mode: output prefix (default
#                 bench/out/dynamicedt/<name of CHANGES_FILE without its
#                 extension>)
#
# What it does:
#   1. Installs libdynamicedt3d-dev when missing (apt-get, when run as root;
#      otherwise it says what to install).
#   2. Compiles bench/dynamicedt/replay_dynamicedt.cpp with g++ -O3
#      -march=native into bench/out/replay_dynamicedt (rebuilt when the
#      source is newer). The EDT itself runs inside the Debian library, built
#      with Debian's own flags; these only affect the harness around it.
#   3. Default mode (no CHANGES_FILE), all with cutoff 2 m, exact
#      integration and 26-connectivity: the scenes uav_pillars and
#      ugv_corridor at their configs' voxel sizes (0.2 m and 0.1 m), and the
#      recordings 3dmatch-seq01 (configs/3dmatch.toml: 0.05 m, a 160 x 160 x
#      80 window; 5 frames) and velodyne-pair (configs/velodyne.toml: 0.2 m,
#      200 x 200 x 40; 2 frames), each in bench/out/dynamicedt/NAME/:
#      a. the example edt_changes (cargo, release; honours CARGO_TARGET_DIR)
#         runs the scene or recording through edtmap's Mapper and exports
#         changes.txt, edtmap_times.csv, edtmap_summary.json and final.edtmap;
#      b. the harness replays changes.txt into DynamicEDT3D (dynamicedt.*);
#      c. edt_changes compare scores both final fields against the exact EDT
#         of the final map and writes comparison.json, table.md and
#         fig4_time_vs_change.png.
#      Then it prints one table, a row per scene and recording, and, on a
#      full-length run, copies the uav_pillars figure to
#      docs/img/fig4_time_vs_change.png. About five minutes on 2 cores once
#      built.
#   3'. Single-file mode: runs  bench/out/replay_dynamicedt CHANGES_FILE
#      PREFIX --repeat N, which writes PREFIX.times.csv
#      (frame,set,clear,update_ms) and PREFIX.final.f32 (final distances in
#      voxels, float32, x fastest, +inf beyond max_distance_vox) and prints
#      one JSON line. The changes file format and the cutoff are described
#      at the top of the .cpp file.
#
# Exit status: that of the harness or the example (2: bad input), 1 for
# setup errors.
#
# Needs: bash, g++, cargo, python3.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
OUT="$ROOT/bench/out"
REPEAT=3
RECORDING_REPEAT=10
FRAMES=
PREFIX=
CHANGES=
SCENES=(uav_pillars ugv_corridor)
DATA=${EDTMAP_DATA:-$ROOT/../shared/data}
# Name, config and window of each recording (the window is the config's).
RECORDINGS=("3dmatch-seq01|3dmatch.toml" "velodyne-pair|velodyne.toml")
# What every run of the default mode shares (the scenes' configs already
# say 2 m and 26 neighbours; the recordings' say 1 m for 3dmatch).
COMMON=(--max-distance 2 --integration exact)

usage() { sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d' | sed 's/^# \{0,1\}//'; }

while [[ $# -gt 0 ]]; do
    case "$1" in
        --repeat) REPEAT=${2:?--repeat needs a value}; shift 2 ;;
        --recording-repeat) RECORDING_REPEAT=${2:?--recording-repeat needs a value}; shift 2 ;;
        --frames) FRAMES=${2:?--frames needs a value}; shift 2 ;;
        --out) PREFIX=${2:?--out needs a prefix}; shift 2 ;;
        -h|--help) usage; exit 0 ;;
        -*) echo "dynamicedt.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
        *) [[ -z "$CHANGES" ]] || { echo "dynamicedt.sh: one CHANGES_FILE only" >&2; exit 2; }
           CHANGES=$1; shift ;;
    esac
done

# 1. DynamicEDT3D.
if ! dpkg -s libdynamicedt3d-dev >/dev/null 2>&1; then
    if [[ $(id -u) -eq 0 ]]; then
        echo "dynamicedt.sh: installing libdynamicedt3d-dev" >&2
        apt-get install -y -q libdynamicedt3d-dev >&2 || { apt-get update -q >&2 && apt-get install -y -q libdynamicedt3d-dev >&2; }
    else
        echo "dynamicedt.sh: libdynamicedt3d-dev is missing; install it (sudo apt-get install libdynamicedt3d-dev)" >&2
        exit 1
    fi
fi

# 2. The harness, rebuilt when its source is newer than the binary.
SRC="$ROOT/bench/dynamicedt/replay_dynamicedt.cpp"
BIN="$OUT/replay_dynamicedt"
mkdir -p "$OUT"
if [[ ! -x "$BIN" || "$SRC" -nt "$BIN" ]]; then
    echo "dynamicedt.sh: compiling $(basename "$BIN")" >&2
    g++ -O3 -march=native -std=c++17 -o "$BIN" "$SRC" -ldynamicedt3d
fi

# 3. Default mode: edtmap exports each scene's and recording's changes,
#    DynamicEDT3D replays them, edtmap compares.
# Built once and run from the binary, so every step runs the same code.
edt_changes() { "$EXE" "$@"; }


if [[ -z "$CHANGES" ]]; then
    [[ -z "$PREFIX" ]] || { echo "dynamicedt.sh: --out goes with a CHANGES_FILE" >&2; exit 2; }
    echo "dynamicedt.sh: building the edt_changes example" >&2
    cargo build --release -q --manifest-path "$ROOT/Cargo.toml" -p edtmap --example edt_changes
    target=$(cargo metadata -q --format-version 1 --no-deps --manifest-path "$ROOT/Cargo.toml" |
             python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
    EXE="$target/release/examples/edt_changes"
    tables=()
    # One case: NAME REPEAT EXPORT_ARGS...
    compare_case() {
        local name=$1 repeat=$2 dir="$OUT/dynamicedt/$1"
        shift 2
        mkdir -p "$dir"
        echo "dynamicedt.sh: $name: edtmap" >&2
        edt_changes export "$@" "${COMMON[@]}" --out "$dir" --repeat "$repeat" >"$dir/export.json"
        echo "dynamicedt.sh: $name: DynamicEDT3D" >&2
        "$BIN" "$dir/changes.txt" "$dir/dynamicedt" --repeat "$repeat" >"$dir/dynamicedt.json"
        edt_changes compare --dir "$dir" --dynamicedt "$dir/dynamicedt" >/dev/null
        tables+=("$dir/table.md")
    }
    for scene in "${SCENES[@]}"; do
        compare_case "$scene" "$REPEAT" --scene "$scene" ${FRAMES:+--frames "$FRAMES"}
    done
    recordings=0
    for r in "${RECORDINGS[@]}"; do
        name=${r%%|*}
        if [[ -d "$DATA/$name" ]]; then
            compare_case "$name" "$RECORDING_REPEAT" --dataset "$DATA/$name" --config "$ROOT/configs/${r#*|}"
            recordings=$((recordings + 1))
        else
            echo "dynamicedt.sh: $DATA/$name is missing: skipping it (set EDTMAP_DATA)" >&2
        fi
    done
    echo
    head -n 2 "${tables[0]}"
    for t in "${tables[@]}"; do tail -n 1 "$t"; done
    echo
    echo "(times: ms per frame, each frame the minimum of $REPEAT runs (scenes${FRAMES:+, first $FRAMES frames})" \
         "or $RECORDING_REPEAT runs (recordings, every frame); cutoff 2 m, exact integration, 26 neighbours;" \
         "edtmap: batch EDT + global integration, $(nproc) cores; DynamicEDT3D: update(), one thread;" \
         "ratio: DynamicEDT3D / edtmap; details in bench/out/dynamicedt/NAME/comparison.json)"
    [[ $recordings -eq ${#RECORDINGS[@]} ]] || echo "(only $recordings of the ${#RECORDINGS[@]} recordings: $DATA lacks the others)"
    fig="$OUT/dynamicedt/uav_pillars/fig4_time_vs_change.png"
    if [[ -z "$FRAMES" ]]; then
        cp "$fig" "$ROOT/docs/img/fig4_time_vs_change.png"
        echo "copied $fig to docs/img/fig4_time_vs_change.png"
    else
        echo "(--frames $FRAMES: docs/img/fig4_time_vs_change.png left as it was; see $fig)"
    fi
    exit 0
fi

# 3'. Single-file mode: DynamicEDT3D on the given changes.
[[ -z "$FRAMES" ]] || { echo "dynamicedt.sh: --frames goes with the default mode (no CHANGES_FILE)" >&2; exit 2; }
[[ -f "$CHANGES" ]] || { echo "dynamicedt.sh: no such file: $CHANGES" >&2; exit 2; }
if [[ -z "$PREFIX" ]]; then
    name=$(basename "$CHANGES")
    PREFIX="$OUT/dynamicedt/${name%.*}"
fi
mkdir -p "$(dirname "$PREFIX")"
"$BIN" "$CHANGES" "$PREFIX" --repeat "$REPEAT"
