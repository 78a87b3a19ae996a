#!/usr/bin/env bash
# The memory budget's estimate against what a run really holds: for each
# voxel size, the mapper's estimate of one frame's peak (logged with -v)
# and the peak resident memory of the whole process (GNU time's maxrss),
# on uav_pillars (10 × 10 × 3 m window, 2 m cutoff).
#
# Usage: bench/memory.sh [VOXEL_SIZE ...]      (default: 0.2 0.1 0.05 0.04)
#        EDTMAP=target/debug/edtmap bench/memory.sh ...   (a binary already built)
#
# The estimate should stay at or above the measured peak less the
# process's base (about 20 MB: the binary, the scene, rayon's threads).
set -euo pipefail
cd "$(dirname "$0")/.."
sizes=("$@")
[ ${#sizes[@]} -gt 0 ] || sizes=(0.2 0.1 0.05 0.04)
command -v /usr/bin/time >/dev/null || { echo "needs GNU time (apt-get install time)" >&2; exit 1; }
bin=${EDTMAP:-}
if [ -z "$bin" ]; then
    cargo build --release --locked --bin edtmap >&2
    bin=target/release/edtmap
fi
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
printf '%-10s %-14s %-14s %s\n' voxel_m window estimate_MiB peak_rss_MiB
for vs in "${sizes[@]}"; do
    log="$out/log-$vs"
    /usr/bin/time -f 'maxrss_kb %M' "$bin" -v run --scene uav_pillars --frames 3 --voxel-size "$vs" --out "$out/run-$vs" >/dev/null 2>"$log"
    window=$(grep -o 'window of [0-9×]* voxels' "$log" | head -1 | awk '{print $3}')
    est=$(grep -o 'needs about [0-9.]* [KMG]iB' "$log" | head -1 | awk '{v=$3; u=$4; if (u=="KiB") v/=1024; if (u=="GiB") v*=1024; printf "%.0f", v}')
    rss=$(awk '/maxrss_kb/ {printf "%.0f", $2/1024}' "$log")
    printf '%-10s %-14s %-14s %s\n' "$vs" "$window" "$est" "$rss"
done
