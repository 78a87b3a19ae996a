#!/usr/bin/env bash
# The exact global EDT on consecutive real depth frames: per-frame medians
# of the stage times and of the exact integration's counters (obstacle
# voxels added and removed, EDT voxels whose distance changed and those
# whose nearest obstacle alone changed, and per pass the entries changed,
# rescanned and read), on 1 and 2 threads, with the frames that ran on
# fewer threads than asked (other processes keeping cores busy).
#
#   bash bench/stream.sh [--repeat N] [--cutoff M] [--threads "1 2"]
#
#   --repeat N     run each case N times (default 1); with EDTMAP_OLD the
#                  two binaries alternate, old then new, N times
#   --cutoff M     [global] max_distance_m (default 2.0)
#   --threads L    RAYON_NUM_THREADS values (default "1 2")
#   EDTMAP=PATH    use a built binary instead of `cargo build --release`
#                  (honours CARGO_TARGET_DIR)
#   EDTMAP_OLD=PATH  a second binary, run alternately with the first in
#                  the same loop; prints each binary's medians per run and
#                  the ratio of their integration medians
#
# Recordings: ../shared/data/7scenes-kitchen-100 (100 consecutive Kinect
# frames) and ../shared/data/3dmatch-seq01 (5 frames), both with
# configs/3dmatch.toml (0.05 m voxels, 8 x 8 x 4 m window) at the cutoff
# given. Medians are over the frames after the first (the first builds the
# map from nothing). Reports are kept in bench/out/stream/.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
repeat=1
cutoff=2.0
threads="1 2"
while [ $# -gt 0 ]; do
    case "$1" in
        --repeat) repeat="$2"; shift 2 ;;
        --cutoff) cutoff="$2"; shift 2 ;;
        --threads) threads="$2"; shift 2 ;;
        -h|--help) sed -n '2,25p' "$0"; exit 0 ;;
        *) echo "stream.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
shared="$root/../shared/data"
if [ ! -d "$shared/7scenes-kitchen-100" ]; then
    echo "stream.sh: $shared/7scenes-kitchen-100 is missing (the shared recordings sit beside the checkout); nothing to measure"
    exit 0
fi
if [ -z "${EDTMAP:-}" ]; then
    (cd "$root" && cargo build --release -q -p edtmap-cli)
    target=$(cargo metadata -q --format-version 1 --no-deps --manifest-path "$root/Cargo.toml" |
             python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
    EDTMAP="$target/release/edtmap"
fi
out="$root/bench/out/stream"
mkdir -p "$out"
config="$out/3dmatch-cutoff-$cutoff.toml"
sed "s/^max_distance_m = .*/max_distance_m = $cutoff/" "$root/configs/3dmatch.toml" > "$config"
datasets=(7scenes-kitchen-100)
[ -d "$shared/3dmatch-seq01" ] && datasets+=(3dmatch-seq01)
bins=("new|$EDTMAP")
[ -n "${EDTMAP_OLD:-}" ] && bins=("old|$EDTMAP_OLD" "new|$EDTMAP")
runs=()
for data in "${datasets[@]}"; do
    for t in $threads; do
        for r in $(seq 1 "$repeat"); do
            for b in "${bins[@]}"; do
                name="${b%%|*}"
                dir="$out/$data-t$t-$name-$r"
                echo "stream.sh: $data, $t thread(s), $name, run $r" >&2
                RAYON_NUM_THREADS=$t "${b#*|}" run --config "$config" --dataset "$shared/$data" --out "$dir" >/dev/null 2>"$dir.log" ||
                    { echo "stream.sh: $name failed on $data, see $dir.log" >&2; exit 1; }
                runs+=("$data|$t|$name|$dir")
            done
        done
    done
done
python3 - "${runs[@]}" <<'EOF'
import json, statistics, sys
from collections import defaultdict
med = statistics.median
rows = defaultdict(list)
for arg in sys.argv[1:]:
    data, t, name, d = arg.split("|")
    f = json.load(open(f"{d}/report.json"))["frames"][1:]
    rows[(data, t, name)].append(f)
def m(frames, key):
    return med([x.get(key, 0) for x in frames])
times = ["ogm_ms", "integrate_ms", "total_ms"]
counts = ["obstacles_added", "obstacles_added_apart", "obstacles_removed", "edt_voxels_changed", "edt_distance_changed", "edt_nearest_only_changed",
          "g1_changed", "g1_nearest_only_changed", "g2_changed", "g2_nearest_only_changed",
          "pass_x_rescanned", "pass_y_rescanned", "pass_z_rescanned", "pass_x_visited", "pass_y_visited", "pass_z_visited"]
print("Stage times, ms, median over the frames after the first (one value per run):\n")
print("| recording | threads | binary | frames | " + " | ".join(times) + " | frames on fewer threads |")
print("|---|---|---|---|" + "---|" * len(times) + "---|")
# A frame's `threads` (absent from older builds' reports): fewer than the
# pool's while other processes kept cores busy.
fewer = lambda f, t: sum(1 for x in f if x.get("threads", int(t)) < int(t))
for (data, t, name), runs in rows.items():
    cells = [", ".join(f"{m(f, k):.2f}" for f in runs) for k in times]
    cells.append(", ".join(str(fewer(f, t)) for f in runs))
    print(f"| {data} | {t} | {name} | {len(runs[0])} | " + " | ".join(cells) + " |")
print("\nCounts per frame, median over the frames after the first (the first run of each case):\n")
print("| recording | threads | binary | " + " | ".join(f"`{k}`" for k in counts) + " |")
print("|---|---|---|" + "---|" * len(counts))
for (data, t, name), runs in rows.items():
    print(f"| {data} | {t} | {name} | " + " | ".join(f"{m(runs[0], k):.0f}" for k in counts) + " |")
if any(k[2] == "old" for k in rows):
    print("\nIntegration, old over new (median integrate_ms of each run, paired in run order):\n")
    print("| recording | threads | old ms | new ms | ratios |")
    print("|---|---|---|---|---|")
    for (data, t, name), runs in rows.items():
        if name != "new" or (data, t, "old") not in rows:
            continue
        old = [m(f, "integrate_ms") for f in rows[(data, t, "old")]]
        new = [m(f, "integrate_ms") for f in runs]
        ratios = [o / n for o, n in zip(old, new)]
        rng = lambda xs: f"{min(xs):.2f}–{max(xs):.2f}"
        print(f"| {data} | {t} | {rng(old)} | {rng(new)} | {', '.join(f'{r:.2f}' for r in ratios)} |")
EOF
