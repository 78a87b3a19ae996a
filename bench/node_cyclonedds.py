"""The ESDF cloud of `edtmap node` to a Cyclone DDS reader (the DDS of
rmw_cyclonedds_cpp, through the `cyclonedds` binding of
tests/interop/requirements.txt) with ROS 2's default QoS (reliable, keep
last 10), over loopback.

The scene of bench/node_scene.py (the one bench/node_fastdds.py measures),
frames at 10 Hz with the sensor's pose on /tf. Prints the clouds received
against the frames mapped, their size, and the latency from publishing a
frame to receiving the cloud that carries its stamp.

  python bench/node_cyclonedds.py [--seconds S] [--band LO HI] [--binary PATH]
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from node_scene import ROOT, cloud_bytes, config, latency_ms, sensor_at, world_points  # (bench/)

sys.path.insert(0, str(ROOT / "tests" / "interop"))
# Before cyclonedds is imported: loopback only, unicast discovery.
os.environ["CYCLONEDDS_URI"] = (ROOT / "tests" / "interop" / "cyclonedds_lo.xml").as_uri()

from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402
from ros2_types import (  # noqa: E402
    POINTFIELD_FLOAT32, XCDR1, DiagnosticArray, Header, PointCloud2, PointField, TFMessage, Time, Transform,
    TransformStamped, Vector3,
)

HZ = 10.0


def stamp_s(h):
    return round(h.stamp.sec + h.stamp.nanosec * 1e-9, 3)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--band", type=float, nargs=2, default=[0.0, 2.0], help="esdf_pointcloud_z_m")
    ap.add_argument("--binary", default=os.environ.get("EDTMAP_BIN", str(ROOT / "target" / "debug" / "edtmap")))
    args = ap.parse_args()
    if not os.access(args.binary, os.X_OK):
        sys.exit(f"node_cyclonedds.py: {args.binary} is missing: cargo build -p edtmap-cli (or --binary)")
    domain = 190 + os.getpid() % 40
    work = Path(tempfile.mkdtemp(prefix="edtmap-node-cyclonedds-"))
    (work / "node.toml").write_text(config(args.band, 'pose_topic = "/tf"\nworld_frame = "map"'))
    node = subprocess.Popen([str(Path(args.binary).resolve()), "node", "--config", "node.toml"], cwd=work,
                            env=dict(os.environ, ROS_DOMAIN_ID=str(domain)), stdin=subprocess.DEVNULL,
                            stdout=open(work / "node.out", "wb"), stderr=open(work / "node.err", "wb"))

    dp = DomainParticipant(domain)
    best_effort = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5), XCDR1)
    reliable = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepLast(10), XCDR1)
    points = DataWriter(dp, Topic(dp, "rt/points", PointCloud2), qos=best_effort)
    tf = DataWriter(dp, Topic(dp, "rt/tf", TFMessage), qos=reliable)
    esdf = DataReader(dp, Topic(dp, "rt/edtmap/esdf_pointcloud", PointCloud2), qos=reliable)
    stats = DataReader(dp, Topic(dp, "rt/edtmap/frame_stats", DiagnosticArray), qos=reliable)
    world = world_points()
    fields = [PointField(name=n, offset=4 * i, datatype=POINTFIELD_FLOAT32, count=1) for i, n in enumerate("xyz")]
    time.sleep(3)  # discovery

    sent, got, frames, size = {}, {}, 0, 0

    def take():
        nonlocal frames, size
        for c in esdf.take(N=100):
            got.setdefault(stamp_s(c.header), time.monotonic())
            size = len(c.data)
        for s in stats.take(N=100):
            frames = max([frames] + [int(kv.value) for st in s.status for kv in st.values if kv.key == "frames"])

    start = time.monotonic()
    k, next_frame = 0, start
    while time.monotonic() - start < args.seconds:
        if time.monotonic() >= next_frame:
            t = round(1.0 + k / HZ, 3)
            at = sensor_at(k, HZ)
            for dt in (-0.01, 0.01):
                pose = Transform(translation=Vector3(x=at[0], y=at[1], z=at[2]))
                tf.write(TFMessage(transforms=[TransformStamped(header=Header(stamp=Time.from_s(t + dt), frame_id="map"),
                                                                child_frame_id="sensor", transform=pose)]))
            points.write(PointCloud2(header=Header(stamp=Time.from_s(t), frame_id="sensor"), height=1, width=len(world),
                                     fields=fields, is_bigendian=False, point_step=12, row_step=12 * len(world),
                                     data=cloud_bytes(world, at), is_dense=True))
            sent[t] = time.monotonic()
            k += 1
            next_frame += 1.0 / HZ
        take()
        time.sleep(0.002)
    time.sleep(2)  # the last clouds
    take()
    node.send_signal(2)
    node.wait(timeout=30)
    median, p95 = latency_ms(got[s] - sent[s] for s in got if s in sent)
    print(f"esdf_pointcloud_z_m {args.band}: {len(got)} ESDF clouds of {size} bytes for {frames} frames mapped "
          f"({k} published); latency median {median} ms, p95 {p95} ms")


if __name__ == "__main__":
    main()
