"""The ESDF cloud of `edtmap node` to a Cyclone DDS reader (the DDS of
rmw_cyclonedds_cpp; the `cyclonedds` binding of tests/interop/requirements.txt)
with ROS 2's default QoS (reliable, keep last 10), over loopback.

configs/ros2_lidar.toml's mapping of a 12 m cylindrical wall, frames at
10 Hz with their poses on /tf, the ESDF cloud after every frame. Prints the
clouds received against the frames mapped, and the latency from publishing
a frame to receiving the cloud that carries its stamp.

  python bench/node_cyclonedds.py [BAND] [SECONDS]
  BAND: esdf_pointcloud_z_m, default "[0.0, 2.0]"; "[-1e4, 1e4]" for the whole window
  EDTMAP_BIN: the binary (default target/debug/edtmap)
"""
import math, os, subprocess, sys, tempfile, time, struct
from pathlib import Path
ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "interop"))
os.environ["CYCLONEDDS_URI"] = (ROOT / "tests/interop/cyclonedds_lo.xml").as_uri()
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration
from ros2_types import XCDR1, DiagnosticArray, Header, PointCloud2, PointField, TFMessage, Time, Transform, TransformStamped, POINTFIELD_FLOAT32, Vector3
DOMAIN = 190 + os.getpid() % 40
band = sys.argv[1] if len(sys.argv) > 1 else "[0.0, 2.0]"
secs = float(sys.argv[2]) if len(sys.argv) > 2 else 20.0
text = (ROOT / "configs/ros2_lidar.toml").read_text()
cfg = text[:text.index("[ros]")] + f'''[ros]
sensor_topic = "/points"
pose_topic = "/tf"
world_frame = "map"
localhost_only = true
esdf_pointcloud_hz = 1000.0
esdf_pointcloud_z_m = {band}
occupied_pointcloud_hz = 0.0
slice_hz = 0.0
pose_wait_s = 0.5
'''
work = Path(tempfile.mkdtemp(prefix="edtmap-node-cyclonedds-"))
(work / "node.toml").write_text(cfg)
env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN))
binary = Path(os.environ.get("EDTMAP_BIN", ROOT / "target" / "debug" / "edtmap")).resolve()
node = subprocess.Popen([str(binary), "node", "--config", "node.toml"], cwd=work, env=env, stdout=open(work/"out","w"), stderr=open(work/"err","w"))
dp = DomainParticipant(DOMAIN)
be = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5), XCDR1)
rel = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepLast(10), XCDR1)
pts_w = DataWriter(dp, Topic(dp, "rt/points", PointCloud2), qos=be)
tf_w = DataWriter(dp, Topic(dp, "rt/tf", TFMessage), qos=rel)
esdf_r = DataReader(dp, Topic(dp, "rt/edtmap/esdf_pointcloud", PointCloud2), qos=rel)
stats_r = DataReader(dp, Topic(dp, "rt/edtmap/frame_stats", DiagnosticArray), qos=rel)
heights = [-1.0 + 0.1 * k for k in range(60)]
world = [(12.0 * math.cos(2 * math.pi * i / 760), 12.0 * math.sin(2 * math.pi * i / 760), z) for i in range(760) for z in heights]
data = struct.pack(f"<{3*len(world)}f", *(c for p in world for c in p))
fields = [PointField(name=n, offset=4 * i, datatype=POINTFIELD_FLOAT32, count=1) for i, n in enumerate("xyz")]
time.sleep(3)
sent = {}; got = {}; frames = 0; size = 0
start = time.monotonic(); k = 0; nxt = start
while time.monotonic() - start < secs:
    now = time.monotonic()
    if now >= nxt:
        t = round(1.0 + k / 10, 3)
        for dt in (-0.01, 0.01):
            tf_w.write(TFMessage(transforms=[TransformStamped(header=Header(stamp=Time.from_s(t + dt), frame_id="map"), child_frame_id="sensor", transform=Transform())]))
        pts_w.write(PointCloud2(header=Header(stamp=Time.from_s(t), frame_id="sensor"), height=1, width=len(world), fields=fields, is_bigendian=False, point_step=12, row_step=12*len(world), data=data, is_dense=True))
        sent[t] = time.monotonic(); k += 1; nxt += 0.1
    for c in esdf_r.take(N=20):
        s = round(c.header.stamp.sec + c.header.stamp.nanosec * 1e-9, 3)
        got.setdefault(s, time.monotonic()); size = len(c.data)
    for s in stats_r.take(N=20):
        for st in s.status:
            for kv in st.values:
                if kv.key == "frames": frames = max(frames, int(kv.value))
    time.sleep(0.002)
time.sleep(2)
for c in esdf_r.take(N=100):
    s = round(c.header.stamp.sec + c.header.stamp.nanosec * 1e-9, 3); got.setdefault(s, time.monotonic())
node.send_signal(2); node.wait(30)
lat = sorted((got[s] - sent[s]) * 1e3 for s in got if s in sent)
print(f"band {band}: {len(got)} ESDF clouds of {size} bytes for {frames} frames mapped ({k} published); latency median {lat[len(lat)//2] if lat else float('nan'):.1f} ms, p95 {lat[int(0.95*(len(lat)-1))] if lat else float('nan'):.1f} ms")
