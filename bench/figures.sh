#!/usr/bin/env bash
# The GIE-mapping paper's Fig. 6 (EDT error against voxel size and
# connectivity) and Fig. 7 (global EDT time over a run, global error against
# voxel size) from our own `edtmap run --eval` reports.
#
#   bash bench/figures.sh [--sweep-frames N]
#
# Runs, each with --eval (every frame, the global EDT is compared with an
# exact EDT of the mapper's own occupancy, over the local window and over
# the whole map), reports in bench/out/figures/<case>/report.json:
#   sweep_*  the first N frames (default 20) of ugv_corridor, room and
#            uav_pillars at voxel sizes 0.05, 0.1 and 0.2 m, wavefront mode
#            with 26-connectivity (our default) and with 6-connectivity (the
#            paper's setting for Fig. 6a); 18-connectivity at 0.1 m (Fig. 6b);
#            exact mode at every voxel size as a check (must be 0 error).
#   run_*    whole runs: ugv_corridor at 0.1 m (150 frames) and uav_pillars
#            at 0.2 m (120 frames), wavefront 26- and 6-connectivity and
#            exact mode (Fig. 7a times, per-frame global error).
# Then the example paper_figures draws docs/img/fig6_*.png and fig7_*.png and
# prints the markdown table of every run.
#
# Cost: the exact EDT of the whole map that --eval computes every frame
# dominates (at 0.05 m about 3-4 s a frame on ugv_corridor and uav_pillars),
# which is why the sweeps stop after N frames. Measured on the 2-core
# development VM under other load: 10 to 13 minutes of runs (three
# measurements), plus the release build.
# Honours CARGO_TARGET_DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
sweep_frames=20
while [ $# -gt 0 ]; do
    case "$1" in
        --sweep-frames) sweep_frames="$2"; shift 2 ;;
        *) echo "usage: bash bench/figures.sh [--sweep-frames N]" >&2; exit 2 ;;
    esac
done
target="${CARGO_TARGET_DIR:-target}"
echo "figures.sh at commit $(git rev-parse --short HEAD), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg)" >&2
cargo build --release --locked -p edtmap-cli >&2
cargo build --release --locked -p edtmap --example paper_figures >&2
out=bench/out/figures
rm -rf "$out"
mkdir -p "$out"

# case NAME ARGS...: one `edtmap run --eval` into $out/NAME, timed.
case_run() {
    local name="$1"
    shift
    local start=$SECONDS
    "$target/release/edtmap" run "$@" --eval --out "$out/$name" >/dev/null
    echo "  $name: $((SECONDS - start)) s" >&2
}

for scene in ugv_corridor room uav_pillars; do
    for voxel in 0.05 0.1 0.2; do
        for conn in 26 6; do
            case_run "sweep_${scene}_v${voxel}_c${conn}_wavefront" --scene "$scene" --frames "$sweep_frames" \
                --voxel-size "$voxel" --integration wavefront --connectivity "$conn"
        done
        case_run "sweep_${scene}_v${voxel}_exact" --scene "$scene" --frames "$sweep_frames" \
            --voxel-size "$voxel" --integration exact
    done
    case_run "sweep_${scene}_v0.1_c18_wavefront" --scene "$scene" --frames "$sweep_frames" \
        --voxel-size 0.1 --integration wavefront --connectivity 18
done

for spec in ugv_corridor:0.1 uav_pillars:0.2; do
    scene="${spec%%:*}"
    voxel="${spec##*:}"
    for conn in 26 6; do
        case_run "run_${scene}_v${voxel}_c${conn}_wavefront" --scene "$scene" --voxel-size "$voxel" \
            --integration wavefront --connectivity "$conn"
    done
    case_run "run_${scene}_v${voxel}_exact" --scene "$scene" --voxel-size "$voxel" --integration exact
done

"$target/release/examples/paper_figures" "$out" docs/img
