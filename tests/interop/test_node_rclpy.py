"""`edtmap node` against ROS 2 itself: rclpy on rmw_fastrtps_cpp (ROS 2's
default RMW), from PyPI wheels (requirements-ros.txt), over loopback.

The test is a robot: it publishes a wall as sensor_msgs/PointCloud2 and
its pose as nav_msgs/Odometry in frame `odom`, both best effort as
drivers do, with no `world_frame` in the node's config. It subscribes
with default QoS to /edtmap/distance_slice, /edtmap/occupancy_grid and
/edtmap/frame_stats, then joins /edtmap/occupancy_grid late with
transient-local QoS (as Nav2's costmaps and RViz's Map display do), and
calls /edtmap/get_distances (5 points, then 100,000),
/edtmap/get_esdf_box (40³ voxels) and /edtmap/save_map with edtmap_msgs
built from
ros/edtmap_msgs by the wheels' generators; the large replies (3.4 MB and
1.1 MB) span many datagrams. Every distance is checked against a
brute-force distance between voxel centres; every output must be in
frame `odom`.

Run:  python -m pytest -q tests/interop/test_node_rclpy.py
(EDTMAP_BIN: the binary, by default target/debug/edtmap from
`cargo build -p edtmap-cli`; the test skips without it or without rclpy,
and fails instead with EDTMAP_REQUIRE_ROS=1.)
"""
import ctypes
import math
import os
import shutil
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
# A domain of its own per run, loopback only; before rclpy starts.
DOMAIN = 20 + os.getpid() % 80
os.environ.update(ROS_DOMAIN_ID=str(DOMAIN), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", RMW_IMPLEMENTATION="rmw_fastrtps_cpp")

# EDTMAP_REQUIRE_ROS=1 (CI) makes a missing prerequisite a failure, not a skip.
REQUIRE = os.environ.get("EDTMAP_REQUIRE_ROS") == "1"


def unavailable(reason):
    if REQUIRE:
        pytest.fail(reason, pytrace=False)
    pytest.skip(reason)


try:
    import rclpy
except ImportError:
    if REQUIRE:
        raise
    pytest.skip("rclpy is not installed (pip install -r tests/interop/requirements-ros.txt)", allow_module_level=True)
import numpy as np  # noqa: E402  (with the ROS wheels)
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data  # noqa: E402
from nav_msgs.msg import OccupancyGrid, Odometry  # noqa: E402
from sensor_msgs.msg import PointCloud2, PointField  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402

BINARY = Path(os.environ.get("EDTMAP_BIN", ROOT / "target" / "debug" / "edtmap"))
VOXEL_M = 0.1
CUTOFF_M = 1.0
FRAME = "odom"

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
pose_topic = "/odom"
pose_type = "odometry"
localhost_only = true
slice_hz = 50.0
slice_height_m = 1.05
pose_wait_s = 2.0
"""


# --- the scene: the plane x = 2.05 m seen from the origin ---------------------

def f32(v):
    return struct.unpack("<f", struct.pack("<f", v))[0]


def wall_points():
    """Four points per voxel of the wall, none on a voxel boundary."""
    return [(f32(2.05), f32(-1.475 + 0.05 * j), f32(0.025 + 0.05 * k)) for k in range(40) for j in range(60)]


def voxel_of(p):
    return tuple(math.floor(c / VOXEL_M) for c in p)


def brute_distance(v, occupied):
    """Distance between the centres of voxel `v` and the nearest occupied voxel."""
    return math.sqrt(min((o[0] - v[0]) ** 2 + (o[1] - v[1]) ** 2 + (o[2] - v[2]) ** 2 for o in occupied)) * VOXEL_M


def stamp(t):
    from builtin_interfaces.msg import Time
    sec = int(t)
    return Time(sec=sec, nanosec=int(round((t - sec) * 1e9)))


def cloud_msg(points, t):
    m = PointCloud2()
    m.header.stamp, m.header.frame_id = stamp(t), "lidar"
    m.height, m.width = 1, len(points)
    m.fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, n in enumerate("xyz")]
    m.is_bigendian, m.point_step, m.row_step, m.is_dense = False, 12, 12 * len(points), True
    m.data = b"".join(struct.pack("<fff", *p) for p in points)
    return m


def odom_msg(t):
    """odom -> lidar, identity."""
    m = Odometry()
    m.header.stamp, m.header.frame_id, m.child_frame_id = stamp(t), FRAME, "lidar"
    m.pose.pose.orientation.w = 1.0
    return m


def floats(cloud):
    names = [f.name for f in cloud.fields]
    n = cloud.point_step // 4
    values = struct.unpack(f"<{len(cloud.data) // 4}f", bytes(cloud.data))
    return names, [values[i:i + n] for i in range(0, len(values), n)]


# --- edtmap_msgs, built by the wheels' generators -------------------------------

@pytest.fixture(scope="module")
def edtmap_msgs(tmp_path_factory):
    """Builds ros/edtmap_msgs with cmake and the rosidl wheels (no colcon)
    into a temporary prefix and imports its services."""
    if shutil.which("cmake") is None or shutil.which("c++") is None:
        unavailable("building edtmap_msgs needs cmake and a C++ compiler")
    base = tmp_path_factory.mktemp("edtmap_msgs")
    build, prefix = base / "build", base / "install"
    venv = Path(sys.prefix)
    env = dict(os.environ, AMENT_PREFIX_PATH=str(venv), PATH=f"{venv / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}")
    configure = ["cmake", "-S", str(ROOT / "ros" / "edtmap_msgs"), "-B", str(build), f"-DCMAKE_PREFIX_PATH={venv}",
                 f"-DCMAKE_INSTALL_PREFIX={prefix}", f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF",
                 f"-DCMAKE_PROJECT_INCLUDE={HERE / 'wheel_python_includes.cmake'}",
                 f"-DCMAKE_INSTALL_RPATH={prefix / 'lib'};{venv / 'lib'}"]
    for cmd in (configure, ["cmake", "--build", str(build), "-j2", "--target", "install"]):
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, f"{' '.join(cmd)}:\n{r.stdout[-4000:]}\n{r.stderr[-4000:]}"
    lib = prefix / "lib"
    # rclpy finds a package's type support through the ament index and
    # LD_LIBRARY_PATH, read when the type is first used.
    os.environ["AMENT_PREFIX_PATH"] = f"{prefix}{os.pathsep}{os.environ.get('AMENT_PREFIX_PATH', venv)}"
    os.environ["LD_LIBRARY_PATH"] = f"{lib}{os.pathsep}{os.environ.get('LD_LIBRARY_PATH', '')}"
    for name in ("rosidl_generator_c", "rosidl_typesupport_c", "rosidl_typesupport_fastrtps_c", "rosidl_typesupport_introspection_c", "rosidl_generator_py"):
        ctypes.CDLL(str(lib / f"libedtmap_msgs__{name}.so"), mode=ctypes.RTLD_GLOBAL)
    sys.path.insert(0, str(next(lib.glob("python3*/site-packages"))))
    from edtmap_msgs.srv import GetDistances, GetEsdfBox, SaveMap
    return GetDistances, GetEsdfBox, SaveMap


# --- the node ---------------------------------------------------------------------

@pytest.fixture
def node(tmp_path):
    if not os.access(BINARY, os.X_OK):
        unavailable(f"{BINARY} is missing: cargo build -p edtmap-cli (or set EDTMAP_BIN)")
    (tmp_path / "node.toml").write_text(NODE_CONFIG)
    with open(tmp_path / "node.stdout", "wb") as out, open(tmp_path / "node.stderr", "wb") as err:
        proc = subprocess.Popen([str(BINARY.resolve()), "-v", "node", "--config", "node.toml"], cwd=tmp_path,
                                stdin=subprocess.DEVNULL, stdout=out, stderr=err)
    try:
        yield proc, tmp_path
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


def test_node_maps_what_rclpy_publishes_and_answers_it(node, edtmap_msgs):
    proc, log_dir = node
    try:
        exercise(proc, edtmap_msgs, log_dir)
    except BaseException:
        print(f"--- edtmap node stderr (domain {DOMAIN}) ---\n{(log_dir / 'node.stderr').read_text(errors='replace')}")
        raise


def exercise(proc, services, log_dir):
    rclpy.init()
    ros = rclpy.create_node("edtmap_rclpy_test")
    try:
        run(proc, ros, *services, log_dir)
    finally:
        ros.destroy_node()
        rclpy.shutdown()


def spin_until(proc, ros, what, pred, timeout_s, every=None):
    """Spins until `pred()`; `every()` is called every 0.25 s meanwhile."""
    deadline = time.monotonic() + timeout_s
    next_call = time.monotonic()
    while time.monotonic() < deadline:
        if every is not None and time.monotonic() >= next_call:
            every()
            next_call = time.monotonic() + 0.25
        rclpy.spin_once(ros, timeout_sec=0.02)
        if pred():
            return
        if proc.poll() is not None:
            pytest.fail(f"edtmap node exited early with status {proc.returncode}")
    pytest.fail(f"timed out after {timeout_s} s waiting for {what}")


def run(proc, ros, GetDistances, GetEsdfBox, SaveMap, log_dir):
    got = {"slice": None, "grid": None, "stats": None, "late": None}

    def keep(key):
        return lambda m: got.__setitem__(key, m)

    pub_points = ros.create_publisher(PointCloud2, "/points", qos_profile_sensor_data)
    pub_odom = ros.create_publisher(Odometry, "/odom", qos_profile_sensor_data)
    ros.create_subscription(PointCloud2, "/edtmap/distance_slice", keep("slice"), 10)
    ros.create_subscription(OccupancyGrid, "/edtmap/occupancy_grid", keep("grid"), 10)
    ros.create_subscription(DiagnosticArray, "/edtmap/frame_stats", keep("stats"), 10)
    client = ros.create_client(GetDistances, "/edtmap/get_distances")

    spin_until(proc, ros, "the node's /points and /odom subscriptions",
               lambda: pub_points.get_subscription_count() > 0 and pub_odom.get_subscription_count() > 0, 30)
    wall = wall_points()
    sent = []

    def send_frame():
        t = round(1.0 + 0.1 * len(sent), 3)
        pub_odom.publish(odom_msg(t))
        pub_odom.publish(odom_msg(t + 0.05))
        pub_points.publish(cloud_msg(wall, t))
        sent.append(t)

    spin_until(proc, ros, "a distance slice, an occupancy grid and frame stats (the node maps frames)",
               lambda: all(got[k] is not None for k in ("slice", "grid", "stats")), 60, every=send_frame)

    occupied = sorted({voxel_of(p) for p in wall})
    # Frames: every output in the poses' frame, as no world_frame is set.
    assert [got[k].header.frame_id for k in ("slice", "grid", "stats")] == [FRAME] * 3

    # The slice: each observed voxel of the layer with its distance.
    names, points = floats(got["slice"])
    assert names == ["x", "y", "z", "distance"], names
    assert len(points) > 100, len(points)
    bad = [(p, min(brute_distance(voxel_of(p[:3]), occupied), CUTOFF_M)) for p in points
           if abs(p[3] - min(brute_distance(voxel_of(p[:3]), occupied), CUTOFF_M)) > 1e-4]
    assert not bad, f"{len(bad)} slice distances differ from brute force, e.g. {bad[:5]}"

    # The grid: 100 on the wall's voxels of the layer, 0 free, -1 unknown.
    grid = got["grid"]
    check_grid(grid, occupied)

    # A subscriber that joins late, as a costmap does, gets the latest grid.
    late_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    ros.create_subscription(OccupancyGrid, "/edtmap/occupancy_grid", keep("late"), late_qos)
    spin_until(proc, ros, "the occupancy grid on a late transient-local subscription", lambda: got["late"] is not None, 15)
    assert got["late"].header.frame_id == FRAME
    check_grid(got["late"], occupied)

    check_rviz_layout(ros)

    # get_distances, as rclpy on Fast DDS calls it.
    assert client.wait_for_service(timeout_sec=15), "get_distances is not available to rclpy"
    queries = [(1.55, 0.05, 1.05), (1.95, 0.05, 1.05), (1.25, -0.65, 0.75), (0.55, 0.05, 0.25), (2.05, 0.05, 1.05)]
    request = GetDistances.Request()
    from geometry_msgs.msg import Point
    request.points = [Point(x=p[0], y=p[1], z=p[2]) for p in queries]
    request.signed_distance = False
    future = client.call_async(request)
    spin_until(proc, ros, "the get_distances reply", future.done, 15)
    reply = future.result()
    assert reply.success, reply.message
    assert len(reply.distances) == len(queries) == len(reply.states) == len(reply.saturated)
    for p, d, state in zip(queries, reply.distances, reply.states):
        # Voxel centres: the interpolation gives the voxel's own distance.
        want = min(brute_distance(voxel_of(p), occupied), CUTOFF_M)
        assert abs(d - want) < 1e-5, (p, d, want)
        assert state == (GetDistances.Request.STATE_OCCUPIED if want == 0 else GetDistances.Request.STATE_FREE), (p, state)

    # Large replies: 100,000 voxel centres (a 3.4 MB reply) and a 40³ box
    # (1.1 MB), over loopback, each in many datagrams.
    rng = np.random.default_rng(7)
    cells = rng.integers([-5, -20, -5], [30, 20, 25], size=(100_000, 3))
    request.points = [Point(x=(i + 0.5) * VOXEL_M, y=(j + 0.5) * VOXEL_M, z=(k + 0.5) * VOXEL_M) for i, j, k in cells.tolist()]
    future = client.call_async(request)
    spin_until(proc, ros, "the reply to 100,000 points", future.done, 30)
    reply = future.result()
    assert reply.success, reply.message
    check_observed(cells, np.array(reply.distances), np.array(reply.states), occupied, GetDistances.Request)

    box_client = ros.create_client(GetEsdfBox, "/edtmap/get_esdf_box")
    assert box_client.wait_for_service(timeout_sec=15), "get_esdf_box is not available to rclpy"
    box = GetEsdfBox.Request()
    box.min_corner, box.max_corner = Point(x=-0.95, y=-1.95, z=-0.45), Point(x=2.95, y=1.95, z=3.45)
    box.signed_distance = False
    future = box_client.call_async(box)
    spin_until(proc, ros, "the get_esdf_box reply", future.done, 30)
    reply = future.result()
    assert reply.success, reply.message
    assert list(reply.size) == [40, 40, 40], list(reply.size)
    first = [round(c / VOXEL_M - 0.5) for c in (reply.origin.x, reply.origin.y, reply.origin.z)]
    assert first == [-10, -20, -5], first
    grid = np.stack(np.meshgrid(*(np.arange(40) + f for f in first), indexing="ij"), axis=-1)
    cells = grid.transpose(2, 1, 0, 3).reshape(-1, 3)  # x fastest, then y, then z
    check_observed(cells, np.array(reply.distances), np.array(reply.states), occupied, GetDistances.Request)

    # save_map: the node writes its map where asked; `edtmap info` reads it
    # back; a path it cannot write is an error reply, not silence.
    save_client = ros.create_client(SaveMap, "/edtmap/save_map")
    assert save_client.wait_for_service(timeout_sec=15), "save_map is not available to rclpy"
    for path, ok in ((log_dir / "saved.edtmap", True), (log_dir / "no-such-dir" / "saved.edtmap", False)):
        future = save_client.call_async(SaveMap.Request(path=str(path)))
        spin_until(proc, ros, "the save_map reply", future.done, 30)
        reply = future.result()
        assert reply.success == ok, reply.message
        assert reply.message, "a reply says what was written, or why not"
    info = subprocess.run([str(BINARY.resolve()), "info", str(log_dir / "saved.edtmap")], capture_output=True, text=True, timeout=60)
    assert info.returncode == 0 and "mapped box" in info.stdout, info.stdout + info.stderr


RVIZ_TYPES = {
    "rviz_default_plugins/PointCloud2": "sensor_msgs/msg/PointCloud2",
    "rviz_default_plugins/Map": "nav_msgs/msg/OccupancyGrid",
}


def check_rviz_layout(ros):
    """Every display of ros/edtmap.rviz names a topic the node publishes,
    with the display's message type, and a durability the publisher offers."""
    import yaml
    layout = yaml.safe_load((ROOT / "ros" / "edtmap.rviz").read_text())
    displays = [d for d in layout["Visualization Manager"]["Displays"] if "Topic" in d]
    assert len(displays) == 4, displays
    graph = {}
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and not all(d["Topic"]["Value"] in graph for d in displays):
        graph = dict(ros.get_topic_names_and_types())
        rclpy.spin_once(ros, timeout_sec=0.05)
    for d in displays:
        topic = d["Topic"]["Value"]
        assert topic in graph, f"{d['Name']}: {topic} is not published ({sorted(graph)})"
        assert RVIZ_TYPES[d["Class"]] in graph[topic], (topic, graph[topic])
        offered = [i.qos_profile.durability for i in ros.get_publishers_info_by_topic(topic)]
        if d["Topic"]["Durability Policy"] == "Transient Local":
            assert DurabilityPolicy.TRANSIENT_LOCAL in offered, (topic, offered)


def test_the_launch_file_compiles_and_starts_the_layout():
    """ros/launch/edtmap.launch.py (no launch wheels here: it is compiled,
    and the files it names exist)."""
    path = ROOT / "ros" / "launch" / "edtmap.launch.py"
    code = compile(path.read_text(), str(path), "exec")
    assert "generate_launch_description" in code.co_names
    assert (ROOT / "configs" / "ros2_lidar.toml").is_file() and (ROOT / "ros" / "edtmap.rviz").is_file()


def check_observed(cells, distances, states, occupied, consts):
    """Every observed voxel's distance equals brute force's, capped at the cutoff."""
    occ = np.array(occupied)
    seen = (states == consts.STATE_FREE) | (states == consts.STATE_OCCUPIED)
    assert seen.sum() > 1000, f"only {seen.sum()} of {len(cells)} voxels observed"
    want = np.empty(len(cells))
    for s in range(0, len(cells), 4096):
        d2 = ((cells[s:s + 4096, None, :] - occ[None, :, :]) ** 2).sum(axis=2).min(axis=1)
        want[s:s + 4096] = np.minimum(np.sqrt(d2) * VOXEL_M, CUTOFF_M)
    bad = np.flatnonzero(seen & (np.abs(distances - want) > 1e-5))
    assert len(bad) == 0, f"{len(bad)} distances differ from brute force, e.g. {[(cells[i].tolist(), distances[i], want[i]) for i in bad[:5]]}"
    assert np.all((states[seen] == consts.STATE_OCCUPIED) == (want[seen] == 0))


def check_grid(grid, occupied):
    info = grid.info
    assert abs(info.resolution - VOXEL_M) < 1e-6
    layer = math.floor(info.origin.position.z / VOXEL_M)
    ox, oy = round(info.origin.position.x / VOXEL_M), round(info.origin.position.y / VOXEL_M)
    walls = {(o[0], o[1]) for o in occupied if o[2] == layer}
    cells = {}
    for r in range(info.height):
        for c in range(info.width):
            cells[(ox + c, oy + r)] = grid.data[r * info.width + c]
    assert {v for v, cell in cells.items() if cell == 100} == walls & set(cells), "occupied cells differ from the wall's voxels"
    assert sum(1 for cell in cells.values() if cell == 0) > 100


# --- a large ESDF cloud to a default-QoS subscriber ----------------------------

# configs/ros2_lidar.toml's map (0.2 m voxels, a 40 x 40 x 8 m window, a
# 2 m cutoff), poses from /odom, the ESDF cloud at 2 Hz.
LIDAR_CONFIG = """\
[sensor]
kind = "points"
construction = "raycast"
min_range_m = 0.5
max_range_m = 40.0

[occupancy]
voxel_size_m = 0.2
local_size_m = [40.0, 40.0, 8.0]

[global]
max_distance_m = 2.0
connectivity = 26

[ros]
sensor_topic = "/points"
pose_topic = "/odom"
pose_type = "odometry"
localhost_only = true
esdf_pointcloud_hz = 2.0
slice_hz = 0.0
occupied_pointcloud_hz = 0.0
pose_wait_s = 2.0
"""


def cylinder_points():
    """A wall around the sensor: a cylinder of radius 12 m, 8 m high."""
    n_around, n_up = 760, 80
    return [(f32(12.0 * math.cos(2 * math.pi * i / n_around)), f32(12.0 * math.sin(2 * math.pi * i / n_around)), f32(-3.95 + 0.1 * k))
            for k in range(n_up) for i in range(n_around)]


def packed_cloud(points, t):
    m = cloud_msg([], t)
    m.width, m.row_step = len(points), 12 * len(points)
    m.data = struct.pack(f"<{3 * len(points)}f", *(c for p in points for c in p))
    return m


@pytest.fixture
def lidar_node(tmp_path):
    if not os.access(BINARY, os.X_OK):
        unavailable(f"{BINARY} is missing: cargo build -p edtmap-cli (or set EDTMAP_BIN)")
    (tmp_path / "node.toml").write_text(LIDAR_CONFIG + os.environ.get("EDTMAP_ESDF_CONFIG_EXTRA", ""))
    with open(tmp_path / "node.stdout", "wb") as out, open(tmp_path / "node.stderr", "wb") as err:
        proc = subprocess.Popen([str(BINARY.resolve()), "node", "--config", "node.toml"], cwd=tmp_path,
                                stdin=subprocess.DEVNULL, stdout=out, stderr=err)
    try:
        yield proc, tmp_path
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


def test_esdf_pointcloud_reaches_a_default_qos_subscriber(lidar_node):
    """The ESDF cloud of configs/ros2_lidar.toml's map around a wall,
    published at 2 Hz, to an rclpy subscriber with default QoS (reliable,
    keep last 10, Fast DDS's default 208 KiB socket buffer): prints the
    delivery ratio over 10 s and the time from the first frame to the
    first cloud, and requires that clouds arrive. The node's writer sends
    a cloud larger than the reader's socket buffer in bursts of 64 KiB,
    1 ms apart, and repairs what was lost in runs of up to 64 KiB
    (EDTMAP_ESDF_CONFIG_EXTRA adds [ros] lines, e.g.
    `esdf_pointcloud_z_m = [-1000.0, 1000.0]` for the whole window)."""
    proc, _ = lidar_node
    rclpy.init()
    ros = rclpy.create_node("edtmap_rclpy_esdf")
    try:
        received = []
        ros.create_subscription(PointCloud2, "/edtmap/esdf_pointcloud", lambda m: received.append((time.monotonic(), len(m.data))), 10)
        pub_points = ros.create_publisher(PointCloud2, "/points", qos_profile_sensor_data)
        pub_odom = ros.create_publisher(Odometry, "/odom", qos_profile_sensor_data)
        spin_until(proc, ros, "the node's /points and /odom subscriptions",
                   lambda: pub_points.get_subscription_count() > 0 and pub_odom.get_subscription_count() > 0, 30)
        wall = cylinder_points()
        sent = []

        def send_frame():
            t = round(1.0 + 0.1 * len(sent), 3)
            pub_odom.publish(odom_msg(t))
            pub_odom.publish(odom_msg(t + 0.05))
            pub_points.publish(packed_cloud(wall, t))
            sent.append(time.monotonic())

        first_sent = time.monotonic()
        deadline = first_sent + 20.0
        while not received and time.monotonic() < deadline:
            if not sent or time.monotonic() - sent[-1] > 0.5:
                send_frame()
            rclpy.spin_once(ros, timeout_sec=0.02)
        first_latency = received[0][0] - first_sent if received else float("inf")
        # Then 10 s of frames at 10 Hz: the node publishes a cloud after the
        # first frame at least 0.5 s after its last, 20 clouds or a few less.
        received.clear()
        start = time.monotonic()
        while time.monotonic() - start < 10.0:
            if time.monotonic() - sent[-1] > 0.1:
                send_frame()
            rclpy.spin_once(ros, timeout_sec=0.02)
        ratio = len(received) / 20.0
        size = max((n for _, n in received), default=0)
        print(f"\nesdf_pointcloud to a default-QoS rclpy subscriber: {len(received)}/20 delivered in 10 s (ratio {ratio:.2f}), "
              f"{size} bytes each, first after {first_latency:.2f} s")
        assert received, f"no ESDF cloud arrived in 10 s (the first after {first_latency:.2f} s)"
    finally:
        ros.destroy_node()
        rclpy.shutdown()
