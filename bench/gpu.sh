#!/usr/bin/env bash
# The GPU backend against the CPU backend: batch EDT of dense cubes, every
# built-in scene and both shared recordings end to end, on each backend this
# machine has.
#
#   bash bench/gpu.sh [--quick] [--device]
#
#   --quick   cubes of 64³ and 128³ only, 10 frames per scene
#             (default: 128³, 256³ and 512³, 60 frames per scene)
#   --device  on a machine with a GPU and no toolchain or network (the
#             device tool's): builds nothing, takes the binary, the GPU test
#             executables and the recordings from .device/bundle.tar.xz
#             (made here by `bash bench/gpu_bundle.sh`), unpacks the Vulkan
#             loader from .device/gl/ if the machine has none, runs every
#             GPU test with EDTMAP_REQUIRE_GPU=1 first, then measures; the
#             tables also go to $OUT/gpu.md when OUT is set
#
# What it does:
#   1. Builds the release CLI (cargo build --release --locked -p edtmap-cli;
#      honours CARGO_TARGET_DIR, default ./target).
#   2. Finds the backends: cpu always; gpu when `edtmap edt --backend gpu`
#      works on a tiny grid (otherwise it prints the reason and skips gpu).
#      Prints the device names, nproc and the date.
#   3. Batch EDT: writes N³ uint8 grids with 1 % obstacles (python3, standard
#      library only, seeded) and runs `edtmap edt --repeat K` on each backend;
#      table of median and min ms and the gpu/cpu ratio of the medians.
#      512³ needs several GB of host memory on a software Vulkan device
#      (lavapipe); it is skipped, with a note, when `free -g` shows less than
#      12 GB available. A size the gpu backend refuses (e.g. a buffer over
#      the device's limits) shows as "not run", with the error under the
#      table; the script goes on.
#   4. Scenes: `edtmap run --scene S --frames F --backend B` for every scene
#      and backend, then uav_pillars at --voxel-size 0.05 (the 10 x 10 x 3 m
#      window at 0.05 m: 200 x 200 x 60 voxels, the issue's full-update
#      target) with a third of the frames; one table per run with the median
#      per-frame stage times (ogm, batch_edt, integrate, total) from
#      report.json. What the GPU backend leaves to the CPU (fusion into the
#      block map, the few voxels a projection leaves uncertain) runs on the
#      CPU inside a gpu run.
#      The four scenes again in wavefront mode (--integration wavefront).
#      Then the shared recordings (3dmatch-seq01 with configs/3dmatch.toml,
#      velodyne-pair with configs/velodyne.toml; from $EDTMAP_DATA, default
#      ../shared/data, skipped with a note when missing), whole. Each table
#      also has the device traffic per frame (up and down MB; "× floor",
#      up and down over the frame's sensor data plus its changed blocks,
#      occupancy and EDT, at 2 KiB each, the least a resident pipeline that
#      keeps the host's map current moves; dispatches,
#      submissions), the device memory held after the last frame, the
#      device time per stage (timestamp queries; medians) and "host ms",
#      the frame's total less the time the host waited for the device
#      (report.json's gpu_wait_ms; the median over frames): the host's
#      share, which a faster device does not shorten.
#   5. Checks that the maps saved (--save) by the cpu and gpu runs of every
#      run are byte-identical (cmp): prints "maps identical" or fails.
# Grids, reports and maps land in bench/out/gpu/.
#
# Needs: bash, cargo, python3. Exit status 1 when a run fails or the maps
# differ.
set -euo pipefail
cd "$(dirname "$0")/.."
# Mesa's window-system probing complains without a runtime directory.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
quick=0
device=0
while [ $# -gt 0 ]; do
    case "$1" in
        --quick) quick=1; shift ;;
        --device) device=1; shift ;;
        -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "usage: bash bench/gpu.sh [--quick] [--device]" >&2; exit 2 ;;
    esac
done
if [ "$quick" = 1 ]; then
    sizes=(64 128); frames=10
else
    sizes=(128 256 512); frames=60
fi
scenes=(uav_pillars ugv_corridor room planar)
start=$SECONDS
out=bench/out/gpu
rm -rf "$out"
mkdir -p "$out"
# Everything printed from here on is also kept in $out/gpu.md (and in
# $OUT/gpu.md on the device tool's machine).
exec > >(tee "$out/gpu.md" ${OUT:+"$OUT/gpu.md"})
test_failures=0
if [ "$device" = 1 ]; then
    [ -f .device/bundle.tar.xz ] || { echo "gpu.sh --device: .device/bundle.tar.xz is missing (make it with bash bench/gpu_bundle.sh and carry .device)" >&2; exit 1; }
    bundle=$(mktemp -d)
    tar -C "$bundle" -xJf .device/bundle.tar.xz
    edtmap="$bundle/bin/edtmap"
    data="$bundle/data"
    if ! ldconfig -p | grep -q 'libvulkan.so.1'; then
        for f in .device/gl/*.deb; do [ -e "$f" ] && dpkg -x "$f" /; done
        ldconfig
    fi
    nvidia_icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    if [ -z "${VK_DRIVER_FILES:-}" ] && [ -e "$nvidia_icd" ] && ! ls /usr/share/vulkan/icd.d/nvidia* /etc/vulkan/icd.d/nvidia* >/dev/null 2>&1; then
        export VK_DRIVER_FILES="$nvidia_icd"
    fi
    command -v nvidia-smi >/dev/null && nvidia-smi -L
    # 0. Every GPU test, a missing adapter a failure.
    echo "### GPU tests (EDTMAP_REQUIRE_GPU=1)"
    echo
    for t in "$bundle"/tests/*; do
        if EDTMAP_REQUIRE_GPU=1 "$t" >"$out/test_$(basename "$t").log" 2>&1; then
            echo "- $(basename "$t"): $(grep -h '^test result' "$out/test_$(basename "$t").log" | tail -n 1)"
        else
            echo "- $(basename "$t"): FAILED"
            grep -h -A15 -- '---- .* stdout ----\|panicked' "$out/test_$(basename "$t").log" | head -n 40
            test_failures=1
        fi
    done
    echo
else
    target="${CARGO_TARGET_DIR:-target}"
    cargo build --release --locked -p edtmap-cli >&2
    edtmap="$target/release/edtmap"
    data="${EDTMAP_DATA:-../shared/data}"
fi

# grid N FILE: an N³ uint8 C-order .npy (format 1.0), 1 % obstacles, seed N.
grid() {
    python3 - "$1" "$2" <<'PY'
import random, struct, sys
n, path = int(sys.argv[1]), sys.argv[2]
total = n ** 3
cells = bytearray(total)
for i in random.Random(n).sample(range(total), total // 100):
    cells[i] = 1
header = "{'descr': '|u1', 'fortran_order': False, 'shape': (%d, %d, %d), }" % (n, n, n)
header += " " * (63 - (10 + len(header)) % 64) + "\n"  # total header a multiple of 64
with open(path, "wb") as f:
    f.write(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode("latin1"))
    f.write(cells)
PY
}

# field KEY: one field of the JSON object on stdin.
field() { python3 -c 'import json, sys; print(json.load(sys.stdin)[sys.argv[1]])' "$1"; }

# Backends: cpu always, gpu when a tiny transform works.
grid 8 "$out/tiny.npy"
backends=(cpu)
devices=("$("$edtmap" edt "$out/tiny.npy" "$out/tiny_edt.npy" --repeat 1 2>"$out/cpu_probe.log" | field backend)")
if gpu_line=$("$edtmap" edt "$out/tiny.npy" "$out/tiny_edt.npy" --backend gpu --repeat 1 2>"$out/gpu_probe.log"); then
    backends+=(gpu)
    devices+=("$(field backend <<<"$gpu_line")")
else
    echo "gpu backend unavailable, skipped: $(grep -v XDG_RUNTIME_DIR "$out/gpu_probe.log" | tail -n 1)"
fi

echo "gpu.sh at commit $(git rev-parse --short HEAD), $(date -u '+%Y-%m-%d %H:%M UTC'), nproc $(nproc)," \
     "load $(cut -d' ' -f1-3 /proc/loadavg)"
for d in "${devices[@]}"; do echo "device: $d"; done
echo

# 1. Batch EDT of N³ cubes.
avail_gb=$(free -g | awk '/^Mem:/ {print $7}')
echo "### Batch EDT, N³ grid, 1 % obstacles (edtmap edt --repeat K)"
echo
echo "| size | backend (device) | K | median (ms) | min (ms) | gpu/cpu (median) |"
echo "|---|---|---|---|---|---|"
notes=()
for n in "${sizes[@]}"; do
    if [ "$n" -ge 512 ] && [ "$avail_gb" -lt 12 ]; then
        notes+=("${n}³ skipped: free -g shows ${avail_gb} GB available, under the 12 GB it needs")
        continue
    fi
    case "$n" in 512) k=3 ;; 256) k=5 ;; *) k=10 ;; esac
    grid "$n" "$out/grid$n.npy"
    cpu_median=
    for b in "${backends[@]}"; do
        if ! line=$("$edtmap" edt "$out/grid$n.npy" "$out/edt${n}_$b.npy" --backend "$b" --repeat "$k" 2>"$out/edt${n}_$b.log"); then
            # The reference must run; a GPU may refuse a size (buffer limits).
            [ "$b" != cpu ] || { echo "edtmap edt ${n}³ --backend cpu failed:" >&2; cat "$out/edt${n}_$b.log" >&2; exit 1; }
            echo "| ${n}³ | $b | $k | not run | not run | – |"
            notes+=("${n}³ on $b: $(grep -v XDG_RUNTIME_DIR "$out/edt${n}_$b.log" | tail -n 1)")
            continue
        fi
        echo "$line" >"$out/edt${n}_$b.json"
        python3 - "$n" "$b" "$k" "$line" "$cpu_median" <<'PY'
import json, sys
n, b, k, r, cpu = sys.argv[1], sys.argv[2], sys.argv[3], json.loads(sys.argv[4]), sys.argv[5]
ratio = f"{r['median_ms'] / float(cpu):.1f}" if b != "cpu" and cpu else "–"
print(f"| {n}³ | {r['backend']} | {k} | {r['median_ms']:.1f} | {r['min_ms']:.1f} | {ratio} |")
PY
        [ "$b" = cpu ] && cpu_median=$(field median_ms <<<"$line")
        rm -f "$out/edt${n}_$b.npy"
    done
    rm -f "$out/grid$n.npy"
done
for note in "${notes[@]+"${notes[@]}"}"; do echo; echo "($note)"; done
echo

# 2. Built-in scenes end to end, then the issue's full-update target: the
#    10 x 10 x 3 m window at 0.05 m (uav_pillars at --voxel-size 0.05,
#    200 x 200 x 60 voxels), fewer frames.
runs=()
for sc in "${scenes[@]}"; do runs+=("$sc|$sc, $frames frames|--scene $sc --frames $frames"); done
# The paper's wavefront integration too (the default is the exact mode).
for sc in "${scenes[@]}"; do runs+=("${sc}_wavefront|$sc, wavefront mode, $frames frames|--scene $sc --frames $frames --integration wavefront"); done
f05=$(( frames / 3 > 5 ? frames / 3 : 5 ))
runs+=("uav_pillars_0.05|uav_pillars at 0.05 m, $f05 frames|--scene uav_pillars --voxel-size 0.05 --frames $f05")
if [ -d "$data/3dmatch-seq01" ] && [ -d "$data/velodyne-pair" ]; then
    runs+=("3dmatch|3dmatch-seq01, whole|--config configs/3dmatch.toml --dataset $data/3dmatch-seq01")
    runs+=("velodyne|velodyne-pair, whole|--config configs/velodyne.toml --dataset $data/velodyne-pair")
else
    echo "(the shared recordings are not in $data: set EDTMAP_DATA; skipped)"
fi
mismatch=0
for run in "${runs[@]}"; do
    IFS='|' read -r tag title args <<<"$run"
    read -r -a extra <<<"$args"
    echo "### $title (edtmap run $args): median ms per frame"
    echo
    echo "| backend (device) | local volume | ogm | batch_edt | integrate | total | up MB | down MB | × floor | dispatches | submits | device MB | device ms ogm / edt / int | host ms |"
    echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    for b in "${backends[@]}"; do
        dir="$out/run_${tag}_$b"
        rm -f "$out/map_${tag}_$b.edtmap"
        if ! "$edtmap" run "${extra[@]}" --backend "$b" --out "$dir" --save "$out/map_${tag}_$b.edtmap" >/dev/null 2>"$dir.log"; then
            # The CPU must always work; a GPU may refuse a size over its limits.
            if [ "$b" = cpu ]; then echo "edtmap run $args --backend cpu failed:" >&2; cat "$dir.log" >&2; exit 1; fi
            echo "| $b | not run: $(grep -o 'edtmap: error: .*' "$dir.log" | head -1 | cut -c16-) | | | | | | | | | | | | |"
            continue
        fi
        python3 - "$dir/report.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
s = r["summary"]
dims = "×".join(str(d) for d in r["local_dims"])
stages = " | ".join(f"{s[k]['median']:.1f}" if k in s else "–" for k in ("ogm_ms", "batch_edt_ms", "integrate_ms", "total_ms"))
# Per-frame device traffic (medians); a CPU run has none.
mb = lambda k: f"{s[k]['median'] / 1e6:.2f}" if k in s else "–"
count = lambda k: f"{s[k]['median']:.0f}" if k in s else "–"
# The traffic over its floor: the frame's sensor data plus its changed
# blocks, occupancy and EDT (2 KiB each, as the device holds them), the
# median over frames.
def over_floor():
    floor = lambda f: f["sensor_bytes"] + 2048 * (f["edt_changed_blocks"] + f.get("occupancy_rewritten_blocks", 0))
    ratios = sorted((f["gpu_uploaded_bytes"] + f["gpu_downloaded_bytes"]) / floor(f) for f in r["frames"] if "gpu_uploaded_bytes" in f and floor(f) > 0)
    return f"{ratios[len(ratios) // 2]:.2f}" if ratios else "–"
device = f"{mb('gpu_uploaded_bytes')} | {mb('gpu_downloaded_bytes')} | {over_floor()} | {count('gpu_dispatches')} | {count('gpu_submissions')}"
# Device memory held after the last frame.
held = r["frames"][-1].get("gpu_memory_bytes") if r.get("frames") else None
device += f" | {held / 1e6:.1f}" if held else " | –"
# Device time per stage (timestamp queries; 0 without them).
times = [f"{s[k]['median']:.2f}" for k in ("gpu_ogm_device_ms", "gpu_batch_edt_device_ms", "gpu_integrate_device_ms") if k in s]
device += f" | {' / '.join(times)}" if times else " | –"
# The host's share of a frame: its total less the time the host waited for
# the device (the median over frames), what a faster device does not shorten.
host = sorted(f["total_ms"] - f["gpu_wait_ms"] for f in r["frames"] if "gpu_wait_ms" in f)
device += f" | {host[len(host) // 2]:.1f}" if host else " | –"
print(f"| {r['backend']} | {dims} at {r['voxel_size_m']} m | {stages} | {device} |")
PY
    done
    echo
    # 3. The same map from every backend.
    if [ "${#backends[@]}" -gt 1 ] && [ ! -e "$out/map_${tag}_gpu.edtmap" ]; then
        echo "(no gpu map to compare for $tag)"
        echo
    elif [ "${#backends[@]}" -gt 1 ]; then
        if cmp -s "$out/map_${tag}_cpu.edtmap" "$out/map_${tag}_gpu.edtmap"; then
            echo "maps identical ($tag, cpu and gpu --save)"
        else
            echo "MAPS DIFFER: $out/map_${tag}_cpu.edtmap and $out/map_${tag}_gpu.edtmap" >&2
            mismatch=1
        fi
        echo
    fi
done
[ "${#backends[@]}" -gt 1 ] || echo "(one backend only: no map comparison)"
echo
echo "total runtime $((SECONDS - start)) s (build included)"
[ "$mismatch" = 0 ] && [ "$test_failures" = 0 ] || exit 1
