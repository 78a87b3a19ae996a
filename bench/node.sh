#!/usr/bin/env bash
# edtmap node, live over DDS on loopback: for one scene of each sensor kind
# (uav_pillars: PointCloud2 from a LiDAR; room: depth Image + CameraInfo;
# planar: LaserScan), `edtmap record` writes the scene, `edtmap node` maps
# it live, and the player (crates/cli/examples/node_player.rs) publishes it
# one frame as soon as the previous one is mapped (the node's full rate)
# while a second participant asks get_distances continuously. Prints, per
# scene, the mapping rate achieved, the latency from publishing a frame to
# receiving its ESDF cloud, get_distances round trips for 1, 1,000 and
# 100,000 points (one call each), and the node's peak memory. Then a long
# replay (uav_pillars,
# 5 × the frames; the scene's path repeats) without and with map clearing
# (`map_clearing_radius_m = 8`): the map's bytes (map and kept passes, from
# /edtmap/frame_stats) at a quarter, half, three quarters and the end.
# With --ros-python, then a Fast DDS subscriber (rclpy, ROS 2's default
# middleware; bench/node_fastdds.py): every output after every frame at
# 10 Hz for --fastdds-seconds, with each output's delivery ratio and
# latency and the node's memory every 10 s.
# Prints the tables and writes them (with the date, commit and machine) to
# target/bench/node.md; the page docs/benchmarks/node.md is updated from it
# by hand.
#
#   bash bench/node.sh [--frames N] [--no-append] [--ros-python PY [--fastdds-seconds S]]
#
#   --frames N           frames recorded per scene (default 120)
#   --no-append          accepted for older command lines; nothing is appended
#   --ros-python PY      a Python with tests/interop/requirements-ros.txt
#                        installed (python3 -m venv V && V/bin/pip install -r ...)
#   --fastdds-seconds S  how long the Fast DDS run lasts (default 600)
# Builds with `cargo build --release` (CARGO_PROFILE_RELEASE_* apply).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
frames=120
ros_python=""
fastdds_seconds=600
while [ $# -gt 0 ]; do
    case "$1" in
        --frames) frames="$2"; shift 2 ;;
        --no-append) shift ;;
        --ros-python) ros_python="$2"; shift 2 ;;
        --fastdds-seconds) fastdds_seconds="$2"; shift 2 ;;
        -h|--help) sed -n '2,30p' "$0"; exit 0 ;;
        *) echo "node.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
cd "$root"
cargo build --release --quiet --bin edtmap --example node_player
target="${CARGO_TARGET_DIR:-$root/target}/release"
edtmap="$target/edtmap"
player="$target/examples/node_player"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
table="| scene | sensor | frames mapped | rate Hz | ESDF cloud latency median / p95 ms | get_distances 1 pt median ms | 1,000 pts | 100,000 pts | node peak RSS MiB |
|---|---|---|---|---|---|---|---|---|"
domain=$(( 160 + $$ % 60 ))
# run_node NAME SCENE FRAMES TOPIC EXTRA_ROS: records, maps live, sets $result and $rss_kib.
run_node() {
    local name="$1" scene="$2" n="$3" topic="$4" extra="$5"
    local dir="$work/$name"
    mkdir -p "$dir"
    "$edtmap" record --scene "$scene" --frames "$n" "$dir/rec.mcap" >/dev/null
    cp "$dir/rec.toml" "$dir/node.toml"
    printf '\n[ros]\nsensor_topic = "%s"\npose_topic = "/tf"\nworld_frame = "map"\nlocalhost_only = true\nesdf_pointcloud_hz = 1000.0\noccupied_pointcloud_hz = 0.0\nslice_hz = 0.0\npose_wait_s = 2.0\n%b' "$topic" "$extra" >>"$dir/node.toml"
    ROS_DOMAIN_ID=$domain "$edtmap" node --config "$dir/node.toml" >"$dir/node.out" 2>"$dir/node.err" &
    local pid=$!
    result=$("$player" "$dir/rec.mcap" "$topic" "$domain")
    rss_kib=$(awk '/VmHWM/ {print $2}' "/proc/$pid/status" 2>/dev/null || echo 0)
    kill -INT "$pid"
    wait "$pid" || { echo "node.sh: the node on $name failed:" >&2; cat "$dir/node.err" >&2; exit 1; }
    echo "$name: $result" >&2
    domain=$((domain + 1))
}
for spec in "uav_pillars|/points|PointCloud2" "room|/camera/depth/image|Image" "planar|/scan|LaserScan"; do
    IFS='|' read -r scene topic kind <<<"$spec"
    run_node "$scene" "$scene" "$frames" "$topic" ""
    row=$(python3 - "$scene" "$kind" "$rss_kib" "$result" <<'PY'
import json, sys
scene, kind, rss, r = sys.argv[1], sys.argv[2], int(sys.argv[3]), json.loads(sys.argv[4])
q = lambda k: f"{r[k]['median_ms']:.2f} ({r[k]['calls']} calls)"
print(f"| {scene} | {kind} | {r['mapped']} of {r['frames']} | {r['rate_hz']:.1f} | {r['esdf_latency_median_ms']:.1f} / {r['esdf_latency_p95_ms']:.1f} | {q('get_distances_1')} | {q('get_distances_1000')} | {q('get_distances_100000')} | {rss / 1024:.0f} |")
PY
)
    table="$table
$row"
done
long="| uav_pillars, $((5 * frames)) frames | map + kept bytes at 1/4 | 1/2 | 3/4 | end | node peak RSS MiB |
|---|---|---|---|---|---|"
for clearing in 0 8; do
    run_node "long$clearing" uav_pillars $((5 * frames)) /points "map_clearing_radius_m = $clearing.0\n"
    row=$(python3 - "$clearing" "$rss_kib" "$result" <<'PY'
import json, sys
c, rss, r = int(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3])
q = [f"{b / 2**20:.1f} MiB" for b in r["map_bytes_quartiles"]]
label = "no clearing" if c == 0 else f"map_clearing_radius_m = {c}"
print(f"| {label} | {q[0]} | {q[1]} | {q[2]} | {q[3]} | {rss / 1024:.0f} |")
PY
)
    long="$long
$row"
done
fastdds=""
if [ -n "$ros_python" ]; then
    "$ros_python" "$here/node_fastdds.py" --seconds "$fastdds_seconds" --binary "$edtmap" >"$work/fastdds.json"
    fastdds=$(python3 - "$work/fastdds.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
print(f"Fast DDS subscriber (rclpy, default QoS), {r['seconds']:.0f} s at {r['frame_hz']:.0f} Hz, {r['frames_mapped']} of {r['frames_published']} frames mapped, ESDF band {r['esdf_pointcloud_z_m']} m:")
print()
print("| output | delivered | latency median / p95 ms |")
print("|---|---|---|")
for k, o in r["outputs"].items():
    print(f"| {k} | {o['received']} ({100 * o['delivery']:.0f} %) | {o['latency_ms_median']} / {o['latency_ms_p95']} |")
print()
rss = r["node_rss_every_10_s"]
marks = [rss[0], rss[len(rss) // 4], rss[len(rss) // 2], rss[3 * len(rss) // 4], rss[-1]]
print("| node at s | " + " | ".join(str(m["s"]) for m in marks) + " | peak |")
print("|---|" + "---|" * (len(marks) + 1))
print("| RSS MiB | " + " | ".join(str(m["rss_mib"]) for m in marks) + f" | {r['node_peak_rss_mib']} |")
print("| map + kept MiB | " + " | ".join(str(m["map_mib"]) for m in marks) + " | |")
PY
)
fi
echo "$table"
echo
echo "$long"
[ -n "$fastdds" ] && { echo; echo "$fastdds"; }
saved="$root/target/bench/node.md"
mkdir -p "$(dirname "$saved")"
{
    echo "### edtmap node over DDS on loopback ($(date -u +%Y-%m-%d), commit $(git rev-parse --short HEAD), $(nproc) cores)"
    echo
    echo "\`bash bench/node.sh --frames $frames\`: each scene published one frame as soon as the previous was mapped, get_distances asked continuously from a second participant meanwhile."
    echo
    echo "$table"
    echo
    echo "$long"
    if [ -n "$fastdds" ]; then
        echo
        echo "$fastdds"
    fi
} >"$saved"
echo "node.sh: wrote ${saved#"$root"/} (copy it into docs/benchmarks/node.md by hand)" >&2
