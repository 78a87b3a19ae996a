"""`edtmap node` (RustDDS) against a plain Cyclone DDS participant, the DDS
that ROS 2's rmw_cyclonedds_cpp uses, over loopback.

The test is the ROS 2 side: it publishes a wall as sensor_msgs/PointCloud2
on /points with its pose on /tf, reads /edtmap/frame_stats and
/edtmap/esdf_pointcloud, and calls /edtmap/get_distances as
rmw_cyclonedds_cpp lays a service out. Every distance is checked against
a brute-force distance between voxel centres.

Run:  EDTMAP_BIN=target/debug/edtmap python -m pytest -q tests/interop
(`cargo test -p edtmap-cli --test interop_cyclonedds` does this, with a
virtual environment made from requirements.txt).
"""
import math
import os
import random
import re
import signal
import struct
import subprocess
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
# Before cyclonedds is imported: loopback only, unicast discovery.
os.environ["CYCLONEDDS_URI"] = (HERE / "cyclonedds_lo.xml").as_uri()

from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

from ros2_types import (  # noqa: E402
    POINTFIELD_FLOAT32,
    STATE_FREE,
    STATE_OCCUPIED,
    XCDR1,
    DiagnosticArray,
    OccupancyGrid,
    GetDistances_Request,
    GetDistances_Response,
    Header,
    Point,
    PointCloud2,
    PointField,
    TFMessage,
    Time,
    Transform,
    TransformStamped,
)

# A domain of its own per run (ports stay below 65535 up to domain 232).
DOMAIN = 150 + os.getpid() % 80

VOXEL_M = 0.1
CUTOFF_M = 1.0
FRAMES = 5

NODE_CONFIG = f"""\
[sensor]
kind = "points"
construction = "raycast"
min_range_m = 0.1
max_range_m = 20.0

[occupancy]
voxel_size_m = {VOXEL_M}
local_size_m = [6.0, 6.0, 3.0]

[global]
max_distance_m = {CUTOFF_M}
connectivity = 26

[ros]
sensor_topic = "/points"
pose_topic = "/tf"
world_frame = "map"
localhost_only = true
esdf_pointcloud_hz = 50.0
pose_wait_s = 2.0
"""

BEST_EFFORT = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5), XCDR1)


def reliable(depth):
    return Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepLast(depth), XCDR1)


# --- the scene: the plane x = 2.05 m seen from the origin ---------------------

def wall_points():
    """Points of the wall, float32-exact, on a 0.05 m grid (four per voxel)
    offset by half a step so that none lies on a voxel boundary:
    y in [-1.475, 1.475], z in [0.025, 1.975]."""
    f32 = lambda v: struct.unpack("<f", struct.pack("<f", v))[0]  # noqa: E731
    return [(f32(2.05), f32(-1.475 + 0.05 * j), f32(0.025 + 0.05 * k)) for k in range(40) for j in range(60)]


def voxel_of(p):
    return tuple(math.floor(c / VOXEL_M) for c in p)


def centre(v):
    return tuple((i + 0.5) * VOXEL_M for i in v)


def brute_distance(v, occupied):
    """Distance between the centres of voxel `v` and the nearest occupied voxel."""
    return math.sqrt(min((o[0] - v[0]) ** 2 + (o[1] - v[1]) ** 2 + (o[2] - v[2]) ** 2 for o in occupied)) * VOXEL_M


def cloud_msg(points, t):
    data = b"".join(struct.pack("<fff", *p) for p in points)
    fields = [PointField(name=n, offset=4 * i, datatype=POINTFIELD_FLOAT32, count=1) for i, n in enumerate("xyz")]
    return PointCloud2(header=Header(stamp=Time.from_s(t), frame_id="sensor"), height=1, width=len(points), fields=fields,
                       is_bigendian=False, point_step=12, row_step=12 * len(points), data=data, is_dense=True)


def tf_msg(t):
    """map -> sensor, identity."""
    return TFMessage(transforms=[TransformStamped(header=Header(stamp=Time.from_s(t), frame_id="map"), child_frame_id="sensor", transform=Transform())])


# --- the node ---------------------------------------------------------------------

class NodeProcess:
    def __init__(self, proc, dir_):
        self.proc = proc
        self.dir = dir_

    def log(self, name):
        path = self.dir / name
        return path.read_text(errors="replace") if path.exists() else ""

    def check_alive(self):
        rc = self.proc.poll()
        if rc is not None:
            pytest.fail(f"edtmap node exited early with status {rc}\n--- node stderr ---\n{self.log('node.stderr')}")

    def dump(self):
        print(f"--- edtmap node stdout (domain {DOMAIN}) ---\n{self.log('node.stdout')}")
        print(f"--- edtmap node stderr ---\n{self.log('node.stderr')}")


@pytest.fixture
def node(tmp_path):
    binary = os.environ.get("EDTMAP_BIN")
    if not binary:
        pytest.fail("set EDTMAP_BIN to the edtmap binary (e.g. EDTMAP_BIN=target/debug/edtmap after cargo build -p edtmap-cli)")
    if not os.access(binary, os.X_OK):
        pytest.fail(f"EDTMAP_BIN={binary} is not an executable file")
    (tmp_path / "node.toml").write_text(NODE_CONFIG)
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN))
    with open(tmp_path / "node.stdout", "wb") as out, open(tmp_path / "node.stderr", "wb") as err:
        proc = subprocess.Popen([os.path.abspath(binary), "-v", "node", "--config", "node.toml", "--save", "node.edtmap"],
                                cwd=tmp_path, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=err)
    handle = NodeProcess(proc, tmp_path)
    try:
        yield handle
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def wait_until(node, what, pred, timeout_s):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if pred():
            return
        node.check_alive()
        time.sleep(0.02)
    pytest.fail(f"timed out after {timeout_s} s waiting for {what}")


def frames_in(stats):
    for status in stats.status[:1]:
        for kv in status.values:
            if kv.key == "frames":
                return int(kv.value)
    raise AssertionError(f"frame_stats without a 'frames' value: {stats}")


def value_of(stats, key):
    return next((kv.value for s in stats.status[:1] for kv in s.values if kv.key == key), None)


# --- the test -----------------------------------------------------------------------

def test_node_maps_a_wall_published_by_cyclonedds_and_answers_get_distances(node):
    try:
        exercise(node)
    except BaseException:
        node.dump()
        raise


def exercise(node):
    dp = DomainParticipant(DOMAIN)
    w_points = DataWriter(dp, Topic(dp, "rt/points", PointCloud2), qos=BEST_EFFORT)
    w_tf = DataWriter(dp, Topic(dp, "rt/tf", TFMessage), qos=reliable(100))
    r_esdf = DataReader(dp, Topic(dp, "rt/edtmap/esdf_pointcloud", PointCloud2), qos=reliable(4))
    r_stats = DataReader(dp, Topic(dp, "rt/edtmap/frame_stats", DiagnosticArray), qos=reliable(20))
    r_occupied = DataReader(dp, Topic(dp, "rt/edtmap/occupied_pointcloud", PointCloud2), qos=reliable(4))
    r_grid = DataReader(dp, Topic(dp, "rt/edtmap/occupancy_grid", OccupancyGrid), qos=reliable(4))
    w_request = DataWriter(dp, Topic(dp, "rq/edtmap/get_distancesRequest", GetDistances_Request), qos=reliable(10))
    r_reply = DataReader(dp, Topic(dp, "rr/edtmap/get_distancesReply", GetDistances_Response), qos=reliable(10))

    # Discovery: every endpoint matched with the node's before anything is sent
    # (the outputs are volatile: a reader that joins late misses them).
    for what, endpoint in [("the node's /points subscription", w_points), ("the node's /tf subscription", w_tf),
                           ("the node's get_distances request reader", w_request)]:
        wait_until(node, what, lambda e=endpoint: len(e.get_matched_subscriptions()) > 0, 20)
    for what, endpoint in [("the node's esdf_pointcloud publisher", r_esdf), ("the node's frame_stats publisher", r_stats),
                           ("the node's occupied_pointcloud publisher", r_occupied), ("the node's occupancy_grid publisher", r_grid),
                           ("the node's get_distances reply writer", r_reply)]:
        wait_until(node, what, lambda e=endpoint: len(e.get_matched_publications()) > 0, 20)

    # Frames: the pose, then the cloud at the same stamp. A frame that does not
    # show up in frame_stats is sent again at the next stamp (a best-effort
    # sample can be lost; the scene is static, so an extra frame is harmless).
    wall = wall_points()
    state = {"frames": 0, "stats": None, "esdf": None}

    def drain():
        for s in r_stats.take(N=100):
            if isinstance(s, DiagnosticArray):
                n = frames_in(s)
                if n >= state["frames"]:
                    state["frames"], state["stats"] = n, s
        for s in r_esdf.take(N=100):
            if isinstance(s, PointCloud2):
                state["esdf"] = s
        return state

    sent = []

    def send_frame():
        t = round(1.0 + 0.1 * len(sent), 3)
        w_tf.write(tf_msg(t))
        w_points.write(cloud_msg(wall, t))
        sent.append(t)

    def wait_streaming(what, pred, timeout_s):
        """Wait for an output while the sensor keeps streaming a frame every
        0.25 s, as a live sensor does: the node publishes only after a frame,
        each output at its own rate, and a sample the node's writer sent
        before it had matched this reader is gone (the outputs are volatile;
        matching is seen from each side at its own time)."""
        next_frame = time.monotonic() + 0.25

        def streaming():
            nonlocal next_frame
            if pred():
                return True
            if time.monotonic() >= next_frame:
                send_frame()
                next_frame = time.monotonic() + 0.25
            return False

        wait_until(node, what, streaming, timeout_s)

    deadline = time.monotonic() + 30
    while state["frames"] < FRAMES:
        assert time.monotonic() < deadline, f"only {state['frames']} of {FRAMES} frames integrated after 30 s ({len(sent)} sent)"
        send_frame()
        want = state["frames"] + 1
        retry_at = time.monotonic() + 3.0
        while drain()["frames"] < want and time.monotonic() < retry_at:
            node.check_alive()
            time.sleep(0.02)

    # The ESDF cloud goes out at every frame here (50 Hz), the occupied cloud
    # and the slice's grid at 1 and 2 Hz.
    wait_streaming("an esdf_pointcloud", lambda: drain()["esdf"] is not None, 10)
    check_esdf_cloud(state["esdf"], wall, sent)
    latest = {}

    def take_latest(reader, kind):
        for s in reader.take(N=10):
            if isinstance(s, kind):
                latest[kind] = s
        return kind in latest

    wait_streaming("an occupied_pointcloud", lambda: take_latest(r_occupied, PointCloud2), 10)
    check_occupied_cloud(latest[PointCloud2], wall, sent)
    wait_streaming("an occupancy_grid", lambda: take_latest(r_grid, OccupancyGrid), 10)
    check_occupancy_grid(latest[OccupancyGrid], wall, sent)

    # The sensor stops; the map the service answers from is the last frame
    # in frame_stats once no frame has come for a second.
    quiet_since, seen = time.monotonic(), state["frames"]
    while time.monotonic() - quiet_since < 1.0:
        node.check_alive()
        if drain()["frames"] != seen:
            quiet_since, seen = time.monotonic(), state["frames"]
        time.sleep(0.02)
    stats = state["stats"]
    assert stats.header.frame_id == "map"
    last_stamp = stats.header.stamp
    assert round(last_stamp.to_s(), 3) in sent, f"frame_stats stamp {last_stamp} is none of the stamps sent {sent}"
    assert value_of(stats, "skipped") == "0", f"the node skipped messages: {stats.status[0].values}"

    check_get_distances(node, w_request, r_reply, wall, last_stamp)

    # SIGINT: the node stops cleanly, saves the map and reports its frames.
    node.proc.send_signal(signal.SIGINT)
    try:
        rc = node.proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        pytest.fail("edtmap node still running 30 s after SIGINT")
    assert rc == 0, f"edtmap node exited with status {rc}"
    out = node.log("node.stdout")
    m = re.search(r"(\d+) frames integrated", out)
    assert m, f"no 'N frames integrated' on the node's stdout: {out!r}"
    assert int(m.group(1)) >= state["frames"], out
    assert (node.dir / "node.edtmap").stat().st_size > 0


def check_esdf_cloud(msg, wall, sent):
    """Every point: a voxel centre, its distance the brute-force distance to
    the wall's voxels, and within the cutoff."""
    assert msg.header.frame_id == "map"
    assert round(msg.header.stamp.to_s(), 3) in sent, f"esdf stamp {msg.header.stamp} is none of the stamps sent {sent}"
    fields = [(f.name, f.offset, f.datatype, f.count) for f in msg.fields]
    assert fields == [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("distance", 12, 7, 1)], fields
    assert (msg.height, msg.point_step, msg.row_step, msg.is_bigendian) == (1, 16, 16 * msg.width, False)
    raw = bytes(msg.data)
    assert len(raw) == msg.row_step * msg.height, f"{len(raw)} data bytes for {msg.width} points"
    points = list(struct.iter_unpack("<4f", raw))
    assert len(points) > 100, f"only {len(points)} points in the esdf cloud"

    occupied = sorted({voxel_of(p) for p in wall})
    assert len(occupied) == 30 * 20
    seen = {}
    bad = []
    for x, y, z, d in points:
        v = voxel_of((x, y, z))
        if max(abs(a - b) for a, b in zip((x, y, z), centre(v))) > 1e-5:
            bad.append(f"({x}, {y}, {z}) is not the centre of voxel {v}")
            continue
        if v in seen:
            bad.append(f"voxel {v} twice")
        seen[v] = d
        brute = brute_distance(v, occupied)
        if abs(d - brute) > 1e-5 or brute > CUTOFF_M + 1e-9:
            bad.append(f"voxel {v} at ({x:.3f}, {y:.3f}, {z:.3f}): distance {d} (brute force {brute:.6f}, cutoff {CUTOFF_M})")
    assert not bad, f"{len(bad)} of {len(points)} esdf points wrong, e.g.:\n" + "\n".join(bad[:15])

    # 0.5 m in front of the wall, and the wall itself.
    front = voxel_of((1.55, 0.05, 1.05))
    assert front in seen, f"voxel {front} (0.5 m in front of the wall) is not in the esdf cloud"
    assert abs(seen[front] - 0.5) < 1e-5, seen[front]
    on_wall = [v for v, d in seen.items() if d == 0.0]
    assert len(on_wall) > 100 and all(v in set(occupied) for v in on_wall), f"{len(on_wall)} zero-distance voxels"


def check_occupied_cloud(msg, wall, sent):
    """x, y, z of occupied voxel centres: the wall's voxels."""
    assert msg.header.frame_id == "map" and round(msg.header.stamp.to_s(), 3) in sent, msg.header
    fields = [(f.name, f.offset, f.datatype, f.count) for f in msg.fields]
    assert fields == [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1)], fields
    assert (msg.height, msg.point_step, msg.row_step, len(msg.data)) == (1, 12, 12 * msg.width, 12 * msg.width)
    occupied = {voxel_of(p) for p in wall}
    voxels = [voxel_of(p) for p in struct.iter_unpack("<3f", bytes(msg.data))]
    assert len(voxels) > 100, f"only {len(voxels)} occupied voxels"
    stray = [v for v in voxels if v not in occupied]
    assert not stray, f"{len(stray)} occupied voxels off the wall, e.g. {stray[:5]}"


def check_occupancy_grid(msg, wall, sent):
    """The window's layer at 1 m: free in front of the wall, occupied on it."""
    info = msg.info
    assert msg.header.frame_id == "map" and round(msg.header.stamp.to_s(), 3) in sent, msg.header
    assert abs(info.resolution - VOXEL_M) < 1e-6, info
    assert info.width > 0 and info.height > 0 and len(msg.data) == info.width * info.height, info
    q = info.origin.orientation
    assert (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.0, 1.0), info
    assert set(msg.data) <= {-1, 0, 100}, sorted(set(msg.data))
    layer = math.floor(1.0 / VOXEL_M)
    occupied = {voxel_of(p) for p in wall}
    bad, walls, free = [], 0, 0
    for r in range(info.height):
        for c in range(info.width):
            cell = msg.data[r * info.width + c]
            v = voxel_of((info.origin.position.x + (c + 0.5) * VOXEL_M, info.origin.position.y + (r + 0.5) * VOXEL_M, 0.0))
            v = (v[0], v[1], layer)
            walls += cell == 100
            free += cell == 0
            if (cell == 100) != (v in occupied):
                bad.append(f"cell ({c}, {r}) = voxel {v}: {cell}")
            if cell == 0 and not (0 <= v[0] < 20):
                bad.append(f"cell ({c}, {r}) = voxel {v}: free, yet not between the sensor and the wall")
    assert not bad, f"{len(bad)} grid cells wrong, e.g.:\n" + "\n".join(bad[:15])
    assert walls == 30 and free > 100, (walls, free)


def check_get_distances(node, w_request, r_reply, wall, last_stamp):
    """get_distances at voxel centres in front of the wall (the interpolation
    between centres gives the voxel's own distance there)."""
    occupied = sorted({voxel_of(p) for p in wall})
    queries = [
        # point, expected distance, state, saturated (None: either)
        ((1.55, 0.05, 1.05), 0.5, STATE_FREE, False),
        ((1.95, 0.05, 1.05), 0.1, STATE_FREE, False),
        ((1.25, -0.65, 0.75), 0.8, STATE_FREE, False),
        ((1.05, 0.35, 0.55), 1.0, STATE_FREE, None),  # exactly the cutoff
        ((0.55, 0.05, 0.25), CUTOFF_M, STATE_FREE, True),  # 1.5 m: beyond the cutoff, which it reports
        ((2.05, 0.05, 1.05), 0.0, STATE_OCCUPIED, False),
    ]
    for p, want, _, saturated in queries:
        brute = brute_distance(voxel_of(p), occupied)
        assert abs(min(brute, CUTOFF_M) - want) < 1e-9 and (saturated is not True or brute > CUTOFF_M), (p, brute, want)

    guid = random.getrandbits(63) | 1
    seq = 1
    w_request.write(GetDistances_Request(client_guid=guid, seq=seq, points=[Point(*p) for p, *_ in queries], signed_distance=False))
    reply = None

    def take_reply():
        nonlocal reply
        for s in r_reply.take(N=10):
            if isinstance(s, GetDistances_Response) and s.client_guid == guid and s.seq == seq:
                reply = s
        return reply is not None

    wait_until(node, "the get_distances reply", take_reply, 10)
    n = len(queries)
    assert (len(reply.distances), len(reply.gradients), len(reply.states), len(reply.saturated)) == (n, n, n, n), reply
    assert (reply.map_stamp.sec, reply.map_stamp.nanosec) == (last_stamp.sec, last_stamp.nanosec), (reply.map_stamp, last_stamp)
    bad = []
    for i, (p, want, state, saturated) in enumerate(queries):
        got = (reply.distances[i], reply.states[i], reply.saturated[i])
        if abs(got[0] - want) > 1e-5 or got[1] != state or (saturated is not None and got[2] != saturated):
            bad.append(f"{p}: distance, state, saturated {got}, want {(want, state, saturated)}")
    g = reply.gradients[0]
    if max(abs(g.x + 1.0), abs(g.y), abs(g.z)) > 1e-6:
        bad.append(f"gradient at (1.55, 0.05, 1.05) is {g}, want (-1, 0, 0)")
    assert not bad, "get_distances:\n" + "\n".join(bad)
