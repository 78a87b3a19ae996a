"""edtmap node against a Fast DDS subscriber (rclpy on rmw_fastrtps_cpp,
ROS 2's default middleware, from the PyPI wheels of
tests/interop/requirements-ros.txt), over loopback, for a while.

A LiDAR robot patrols a circle of radius 4 m inside a 12 m cylindrical
wall with pillars, at FRAME_HZ. The node runs configs/ros2_lidar.toml's
map and mapping settings with every output published after every frame
(poses from best-effort odometry, loopback only). The script subscribes
to every output with default QoS (reliable, keep last 10, default socket
buffers) and to the occupancy grid transient-local as well, and reports:

- per output: clouds received / frames mapped (the delivery ratio) and
  the latency from publishing a frame to receiving the output that
  carries its stamp (median and 95th percentile);
- the node's resident memory (VmRSS) every 10 s and its peak (VmHWM),
  with the map's own bytes from /edtmap/frame_stats.

Prints one JSON object on stdout.

  python bench/node_fastdds.py [--seconds S] [--hz HZ] [--band LO HI] [--binary PATH]
"""
import argparse
import json
import math
import os
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
os.environ.setdefault("ROS_DOMAIN_ID", str(100 + os.getpid() % 80))
os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", RMW_IMPLEMENTATION="rmw_fastrtps_cpp")

import rclpy  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data  # noqa: E402
from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from nav_msgs.msg import OccupancyGrid, Odometry  # noqa: E402
from sensor_msgs.msg import PointCloud2, PointField  # noqa: E402

OUTPUTS = {
    "esdf_pointcloud": PointCloud2,
    "occupied_pointcloud": PointCloud2,
    "distance_slice": PointCloud2,
    "occupancy_grid": OccupancyGrid,
    "frame_stats": DiagnosticArray,
}


def config(band):
    text = (ROOT / "configs" / "ros2_lidar.toml").read_text()
    ros = text.index("[ros]")
    return text[:ros] + f"""[ros]
sensor_topic = "/points"
pose_topic = "/odom"
pose_type = "odometry"
localhost_only = true
esdf_pointcloud_hz = 1000.0
esdf_pointcloud_z_m = [{band[0]}, {band[1]}]
occupied_pointcloud_hz = 1000.0
slice_hz = 1000.0
slice_height_m = 1.0
pose_wait_s = 0.5
map_clearing_radius_m = 60.0
"""


def world_points():
    """The wall (radius 12 m) and eight pillars (radius 0.5 m at 8 m), 0.1 m apart, -1 to 5 m high."""
    pts = []
    heights = [-1.0 + 0.1 * k for k in range(60)]
    for i in range(760):
        a = 2 * math.pi * i / 760
        pts += [(12.0 * math.cos(a), 12.0 * math.sin(a), z) for z in heights]
    for p in range(8):
        cx, cy = 8.0 * math.cos(p * math.pi / 4), 8.0 * math.sin(p * math.pi / 4)
        for i in range(32):
            a = 2 * math.pi * i / 32
            pts += [(cx + 0.5 * math.cos(a), cy + 0.5 * math.sin(a), z) for z in heights]
    return pts


def stamp(t):
    sec = int(t)
    return Time(sec=sec, nanosec=int(round((t - sec) * 1e9)))


def stamp_s(s):
    return s.sec + s.nanosec * 1e-9


def cloud(points, at, t):
    """The world as seen from `at` (sensor frame = world axes, shifted)."""
    m = PointCloud2()
    m.header.stamp, m.header.frame_id = stamp(t), "lidar"
    xs = [(x - at[0], y - at[1], z - at[2]) for x, y, z in points]
    m.height, m.width = 1, len(xs)
    m.fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, n in enumerate("xyz")]
    m.is_bigendian, m.point_step, m.row_step, m.is_dense = False, 12, 12 * len(xs), True
    m.data = struct.pack(f"<{3 * len(xs)}f", *(c for p in xs for c in p))
    return m


def odom(at, t):
    m = Odometry()
    m.header.stamp, m.header.frame_id, m.child_frame_id = stamp(t), "odom", "lidar"
    m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z = at
    m.pose.pose.orientation.w = 1.0
    return m


def proc_kib(pid, key):
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--hz", type=float, default=10.0, help="frames per second published")
    ap.add_argument("--band", type=float, nargs=2, default=[0.0, 2.0], help="esdf_pointcloud_z_m")
    ap.add_argument("--binary", default=str(ROOT / "target" / "release" / "edtmap"))
    args = ap.parse_args()
    if not os.access(args.binary, os.X_OK):
        sys.exit(f"node_fastdds.py: {args.binary} is missing: cargo build --release -p edtmap-cli (or --binary)")

    work = Path(tempfile.mkdtemp(prefix="edtmap-node-fastdds-"))
    (work / "node.toml").write_text(config(args.band))
    node = subprocess.Popen([str(Path(args.binary).resolve()), "node", "--config", "node.toml"], cwd=work,
                            stdin=subprocess.DEVNULL, stdout=open(work / "node.out", "wb"), stderr=open(work / "node.err", "wb"))
    rclpy.init()
    ros = rclpy.create_node("edtmap_bench_fastdds")
    sent = {}  # frame stamp -> wall time published
    got = {k: {} for k in OUTPUTS}  # output -> frame stamp -> wall time received
    stats = {"frames": 0, "map_bytes": 0}

    def on(key):
        def cb(m):
            now = time.monotonic()
            got[key].setdefault(round(stamp_s(m.header.stamp), 3), now)
            if key == "frame_stats":
                for s in m.status:
                    for kv in s.values:
                        if kv.key in ("frames", "map_bytes"):
                            stats[kv.key] = int(float(kv.value))
        return cb

    for key, ty in OUTPUTS.items():
        ros.create_subscription(ty, f"/edtmap/{key}", on(key), 10)
    late = {"grid": None}
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    ros.create_subscription(OccupancyGrid, "/edtmap/occupancy_grid", lambda m: late.__setitem__("grid", m), latched)
    pub_points = ros.create_publisher(PointCloud2, "/points", qos_profile_sensor_data)
    pub_odom = ros.create_publisher(Odometry, "/odom", qos_profile_sensor_data)
    deadline = time.monotonic() + 30
    while pub_points.get_subscription_count() == 0 or pub_odom.get_subscription_count() == 0:
        rclpy.spin_once(ros, timeout_sec=0.05)
        if time.monotonic() > deadline or node.poll() is not None:
            sys.exit(f"node_fastdds.py: the node did not subscribe (see {work}/node.err)")

    world = world_points()
    rss = []
    start = time.monotonic()
    next_frame, next_rss, k = start, start, 0
    while time.monotonic() - start < args.seconds:
        now = time.monotonic()
        if now >= next_frame:
            t = round(1.0 + k / args.hz, 3)
            a = 2 * math.pi * k / (args.hz * 40.0)  # one lap in 40 s
            at = (4.0 * math.cos(a), 4.0 * math.sin(a), 0.0)
            pub_odom.publish(odom(at, t - 0.01))
            pub_odom.publish(odom(at, t + 0.01))
            pub_points.publish(cloud(world, at, t))
            sent[t] = time.monotonic()
            k += 1
            next_frame += 1.0 / args.hz
        if now >= next_rss:
            rss.append({"s": round(now - start), "rss_mib": round(proc_kib(node.pid, "VmRSS") / 1024, 1),
                        "map_mib": round(stats["map_bytes"] / 2**20, 1)})
            next_rss += 10.0
        rclpy.spin_once(ros, timeout_sec=0.002)
        if node.poll() is not None:
            sys.exit(f"node_fastdds.py: the node exited with {node.returncode} (see {work}/node.err)")
    # Let the last outputs arrive.
    until = time.monotonic() + 2.0
    while time.monotonic() < until:
        rclpy.spin_once(ros, timeout_sec=0.02)
    peak = proc_kib(node.pid, "VmHWM")
    node.send_signal(2)
    node.wait(timeout=30)

    frames = stats["frames"]
    per_output = {}
    for key in OUTPUTS:
        lat = sorted((got[key][s] - sent[s]) * 1e3 for s in got[key] if s in sent)
        per_output[key] = {
            "received": len(got[key]),
            "delivery": round(len(got[key]) / frames, 3) if frames else 0.0,
            "latency_ms_median": round(statistics.median(lat), 1) if lat else None,
            "latency_ms_p95": round(lat[int(0.95 * (len(lat) - 1))], 1) if lat else None,
        }
    print(json.dumps({
        "seconds": args.seconds, "frames_published": k, "frames_mapped": frames, "frame_hz": args.hz,
        "esdf_pointcloud_z_m": args.band, "outputs": per_output,
        "late_transient_local_grid": late["grid"] is not None,
        "node_rss_every_10_s": rss, "node_peak_rss_mib": round(peak / 1024, 1),
    }, indent=1))
    ros.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
