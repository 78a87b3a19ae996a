"""edtmap node against a Fast DDS subscriber (rclpy on rmw_fastrtps_cpp,
ROS 2's default middleware, from the PyPI wheels of
tests/interop/requirements-ros.txt), over loopback, for a while.

The scene of bench/node_scene.py: a LiDAR circling inside a 12 m walled
yard with pillars, frames at --hz, configs/ros2_lidar.toml's mapping with
every output published after every frame (poses from best-effort
odometry, loopback only). The script subscribes
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
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from node_scene import ROOT, cloud_bytes, config, latency_ms, sensor_at, world_points  # noqa: E402  (bench/)

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


def stamp(t):
    sec = int(t)
    return Time(sec=sec, nanosec=int(round((t - sec) * 1e9)))


def stamp_s(s):
    return s.sec + s.nanosec * 1e-9


def cloud(points, at, t):
    """The world as seen from `at` (sensor frame = world axes, shifted)."""
    m = PointCloud2()
    m.header.stamp, m.header.frame_id = stamp(t), "lidar"
    m.height, m.width = 1, len(points)
    m.fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, n in enumerate("xyz")]
    m.is_bigendian, m.point_step, m.row_step, m.is_dense = False, 12, 12 * len(points), True
    m.data = cloud_bytes(points, at)
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
    (work / "node.toml").write_text(config(args.band, 'pose_topic = "/odom"\npose_type = "odometry"'))
    node = subprocess.Popen([str(Path(args.binary).resolve()), "node", "--config", "node.toml"], cwd=work,
                            stdin=subprocess.DEVNULL, stdout=open(work / "node.out", "wb"), stderr=open(work / "node.err", "wb"))
    rclpy.init()
    ros = rclpy.create_node("edtmap_bench_fastdds")
    sent = {}  # frame stamp -> wall time published
    got = {k: {} for k in OUTPUTS}  # output -> frame stamp -> wall time received
    largest = {k: 0 for k in OUTPUTS}  # output -> largest payload received, bytes
    stats = {"frames": 0, "map_bytes": 0}

    def on(key):
        def cb(m):
            now = time.monotonic()
            got[key].setdefault(round(stamp_s(m.header.stamp), 3), now)
            if key != "frame_stats":
                largest[key] = max(largest[key], len(m.data))
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
            at = sensor_at(k, args.hz)
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
        median, p95 = latency_ms(got[key][s] - sent[s] for s in got[key] if s in sent)
        per_output[key] = {
            "received": len(got[key]),
            "largest_bytes": largest[key],
            "delivery": round(len(got[key]) / frames, 3) if frames else 0.0,
            "latency_ms_median": median,
            "latency_ms_p95": p95,
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
