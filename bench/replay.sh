#!/usr/bin/env bash
# Recordings against simulation: the same frames mapped from a built-in
# scene (simulated), from an MCAP file and from a ROS 1 bag written by
# `edtmap record`; the maps are compared and the wall time per run is
# reported with the replay/scene ratio, the three runs interleaved.
#
#   bash bench/replay.sh [FRAMES] [REPEATS]     (default 40 frames, 3 repeats)
#
# Builds the release CLI (honours CARGO_TARGET_DIR, default ./target).
set -euo pipefail
cd "$(dirname "$0")/.."
frames=${1:-40}
repeats=${2:-3}
cargo build --release --locked -p edtmap-cli >&2
bin=${CARGO_TARGET_DIR:-target}/release/edtmap
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
echo "# replay vs simulation, $frames frames, $repeats repeats, $(nproc) cores, $(date -u +%F)"
printf '%-8s %-6s %10s %10s %8s %s\n' scene source median_s min_s ratio map
for scene in room planar; do
  "$bin" record --scene "$scene" --frames "$frames" "$work/$scene.mcap" >/dev/null
  "$bin" record --scene "$scene" --frames "$frames" "$work/$scene.bag" >/dev/null
  declare -A times=()
  for ((k = 0; k < repeats; k++)); do
    for src in scene mcap bag; do
      start=$(date +%s.%N)
      if [ "$src" = scene ]; then
        "$bin" run --scene "$scene" --frames "$frames" --out "$work/o-$src" --save "$work/$src.edtmap" >/dev/null
      else
        "$bin" run --config "$work/$scene.toml" --dataset "$work/$scene.$src" --out "$work/o-$src" --save "$work/$src.edtmap" >/dev/null
      fi
      end=$(date +%s.%N)
      times[$src]+="$(echo "$end - $start" | bc) "
    done
  done
  base=$(echo "${times[scene]}" | tr ' ' '\n' | grep . | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
  for src in scene mcap bag; do
    sorted=$(echo "${times[$src]}" | tr ' ' '\n' | grep . | sort -g)
    median=$(echo "$sorted" | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
    min=$(echo "$sorted" | head -1)
    same=$(cmp -s "$work/scene.edtmap" "$work/$src.edtmap" && echo identical || echo DIFFERENT)
    printf '%-8s %-6s %10.3f %10.3f %8.2f %s\n' "$scene" "$src" "$median" "$min" "$(echo "$median / $base" | bc -l)" "$same"
  done
  unset times
done
