#!/usr/bin/env bash
# Per-frame cost of the whole pipeline on every built-in scene and on the
# two shared recordings: median and p95 of occupancy, EDT (batch EDT plus
# global integration) and total, and the global map's bytes per mapped
# voxel, from each run's report.json. Prints a Markdown table and writes
# it (with the date, commit and machine) to target/bench/pipeline.md; the
# page docs/benchmarks/pipeline.md is updated from it by hand.
#
#   bash bench/pipeline.sh [--frames N] [--backend cpu|gpu] [--no-append]
#
#   --frames N    replay N frames of each scene (default: the scene's own
#                 length); recordings always replay all their frames
#   --no-append   accepted for older command lines; nothing is appended
#   EDTMAP=PATH   use a built binary instead of `cargo build --release`
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
frames=""
backend=cpu
while [ $# -gt 0 ]; do
    case "$1" in
        --frames) frames="$2"; shift 2 ;;
        --backend) backend="$2"; shift 2 ;;
        --no-append) shift ;;
        -h|--help) sed -n '2,14p' "$0"; exit 0 ;;
        *) echo "pipeline.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
shared="$root/../shared/data"
[ -d "$shared" ] || { echo "pipeline.sh: $shared is missing (the shared recordings sit beside the checkout)" >&2; exit 1; }
if [ -z "${EDTMAP:-}" ]; then
    (cd "$root" && cargo build --release -q -p edtmap-cli)
    target=$(cargo metadata -q --format-version 1 --no-deps --manifest-path "$root/Cargo.toml" |
             python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
    EDTMAP="$target/release/edtmap"
fi
out="$root/bench/out/pipeline"
mkdir -p "$out"
cases=(
    "uav_pillars|--scene uav_pillars ${frames:+--frames $frames}"
    "ugv_corridor|--scene ugv_corridor ${frames:+--frames $frames}"
    "room|--scene room ${frames:+--frames $frames}"
    "planar|--scene planar ${frames:+--frames $frames}"
    "3dmatch-seq01|--config $root/configs/3dmatch.toml --dataset $shared/3dmatch-seq01"
    "velodyne-pair|--config $root/configs/velodyne.toml --dataset $shared/velodyne-pair"
)
for c in "${cases[@]}"; do
    name="${c%%|*}"
    echo "pipeline.sh: $name" >&2
    # shellcheck disable=SC2086
    "$EDTMAP" run ${c#*|} --backend "$backend" --out "$out/$name" >/dev/null
done
table=$(python3 - "$out" "${cases[@]%%|*}" <<'EOF'
import json, statistics, sys
out, names = sys.argv[1], sys.argv[2:]
def p95(xs):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(0.95 * (len(xs) - 1))))]
print("| run | voxel (m) | window | frames | occupancy ms median / p95 | EDT ms median / p95 | total ms median / p95 | map bytes per mapped voxel |")
print("|---|---|---|---|---|---|---|---|")
for name in names:
    r = json.load(open(f"{out}/{name}/report.json"))
    f = r["frames"]
    ogm = [x["ogm_ms"] for x in f]
    edt = [x.get("batch_edt_ms", 0.0) + x["integrate_ms"] for x in f]
    tot = [x["total_ms"] for x in f]
    mapped = max(1, r["map_blocks"] * 512)
    cell = lambda xs: f"{statistics.median(xs):.1f} / {p95(xs):.1f}"
    dims = "×".join(str(d) for d in r["local_dims"])
    print(f"| {name} | {r['voxel_size_m']} | {dims} | {len(f)} | {cell(ogm)} | {cell(edt)} | {cell(tot)} | {f[-1]['map_bytes'] / mapped:.1f} |")
EOF
)
echo "$table"
saved="$root/target/bench/pipeline.md"
mkdir -p "$(dirname "$saved")"
{
    echo "### Pipeline per frame, $(date -u +%Y-%m-%d), commit $(git -C "$root" rev-parse --short HEAD), $(nproc) cores, backend $backend"
    echo
    echo "\`bash bench/pipeline.sh${frames:+ --frames $frames}${backend:+ --backend $backend}\` (occupancy: construction and fusion; EDT: batch EDT plus global integration; bytes per mapped voxel: the global map's blocks, all layers, over the occupancy blocks' voxels)"
    echo
    echo "$table"
} > "$saved"
echo "pipeline.sh: wrote ${saved#"$root"/} (copy it into docs/benchmarks/pipeline.md by hand)" >&2
