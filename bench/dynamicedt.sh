#!/usr/bin/env bash
# Incremental global EDT: DynamicEDT3D (Lau et al., the CPU baseline of the
# GIE-mapping paper) replaying a sequence of occupancy changes, so that
# edtmap's incremental EDT can be compared with it on the same changes.
#
# Usage:
#   bench/dynamicedt.sh [--repeat N] [--out PREFIX] CHANGES_FILE
#
#   --repeat N    replay the whole sequence N times from empty; each frame
#                 keeps its minimum time (default 3)
#   --out PREFIX  output prefix (default bench/out/dynamicedt/<name of
#                 CHANGES_FILE without its extension>)
#
# What it does:
#   1. Installs libdynamicedt3d-dev when missing (apt-get, when run as root;
#      otherwise it says what to install).
#   2. Compiles bench/dynamicedt/replay_dynamicedt.cpp with g++ -O3
#      -march=native into bench/out/replay_dynamicedt (rebuilt when the
#      source is newer). The EDT itself runs inside the Debian library, built
#      with Debian's own flags; these only affect the harness around it.
#   3. Runs  bench/out/replay_dynamicedt CHANGES_FILE PREFIX --repeat N,
#      which writes PREFIX.times.csv (frame,set,clear,update_ms) and
#      PREFIX.final.f32 (final distances in voxels, float32, x fastest, +inf
#      beyond max_distance_vox) and prints one JSON line. The changes file
#      format and the cutoff are described at the top of the .cpp file.
#
# Exit status: that of the harness (2: bad changes file), 1 for setup errors.
#
# Needs: bash, g++.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
OUT="$ROOT/bench/out"
REPEAT=3
PREFIX=
CHANGES=

usage() { sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d' | sed 's/^# \{0,1\}//'; }

while [[ $# -gt 0 ]]; do
    case "$1" in
        --repeat) REPEAT=${2:?--repeat needs a value}; shift 2 ;;
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

# ---------------------------------------------------------------------------
# edtmap side: TO BE ADDED. An edtmap example will export changes files from
# built-in scenes (and its own per-frame times and final field); it goes
# here, before step 3, and a comparison of times and field errors after it.
# Until then the script replays one given CHANGES_FILE.
# ---------------------------------------------------------------------------

# 3. DynamicEDT3D on the changes.
[[ -n "$CHANGES" ]] || { echo "dynamicedt.sh: no CHANGES_FILE given (see --help)" >&2; exit 2; }
[[ -f "$CHANGES" ]] || { echo "dynamicedt.sh: no such file: $CHANGES" >&2; exit 2; }
if [[ -z "$PREFIX" ]]; then
    name=$(basename "$CHANGES")
    PREFIX="$OUT/dynamicedt/${name%.*}"
fi
mkdir -p "$(dirname "$PREFIX")"
"$BIN" "$CHANGES" "$PREFIX" --repeat "$REPEAT"
