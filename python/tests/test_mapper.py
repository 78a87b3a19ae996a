"""The mapper from Python against the command line (`edtmap run`, `edtmap
query`) on the same recordings, an analytic wall, and bad input."""

import os
import shutil
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest

import edtmap

REPO = Path(__file__).resolve().parents[2]
# Recordings too large for the repository, beside the checkout when present.
SHARED = REPO.parent / "shared" / "data"


def edtmap_binary() -> str:
    """The command-line program: $EDTMAP_BIN, else the workspace's build."""
    if os.environ.get("EDTMAP_BIN"):
        return os.environ["EDTMAP_BIN"]
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    for profile in ("debug", "release"):
        if (target / profile / "edtmap").exists():
            return str(target / profile / "edtmap")
    found = shutil.which("edtmap")
    if found:
        return found
    pytest.skip("no edtmap binary: run `cargo build --bin edtmap` or set EDTMAP_BIN")


def cli(*args, cwd):
    done = subprocess.run([edtmap_binary(), *map(str, args)], cwd=cwd, capture_output=True, text=True)
    assert done.returncode == 0, f"edtmap {' '.join(map(str, args))}: {done.stderr}"
    return done.stdout


def recorded(tmp_path, scene, frames, ext):
    """A built-in scene written by `edtmap record`, with its config."""
    path = tmp_path / f"{scene}.{ext}"
    cli("record", "--scene", scene, "--frames", frames, path, cwd=tmp_path)
    return path, tmp_path / f"{scene}.toml"


def replay(recording, config, frames=None):
    rec = edtmap.read_recording(recording, config, frames)
    mapper = rec.mapper()
    count = 0
    for frame in rec:
        stats = mapper.integrate(frame)
        assert stats["total_ms"] >= 0 and stats["map_blocks"] > 0
        count += 1
    assert rec.skipped == []
    return mapper, count


RECORDINGS = [
    ("room", 5, "mcap", "depth"),
    ("uav_pillars", 4, "bag", "points"),
    ("planar", 6, "mcap", "planar"),
]


@pytest.mark.parametrize("scene,frames,ext,kind", RECORDINGS)
def test_replay_saves_the_map_edtmap_run_saves(tmp_path, scene, frames, ext, kind):
    recording, config = recorded(tmp_path, scene, frames, ext)
    cli("run", "--config", config, "--dataset", recording, "--out", tmp_path / "out",
        "--save", tmp_path / "cli.edtmap", cwd=tmp_path)
    mapper, count = replay(recording, config)
    assert count == frames and mapper.sensor_kind == kind
    mapper.save(tmp_path / "py.edtmap")
    assert (tmp_path / "py.edtmap").read_bytes() == (tmp_path / "cli.edtmap").read_bytes()


@pytest.mark.parametrize("folder,config,frames", [
    ("3dmatch-seq01", "3dmatch.toml", 3),
    ("velodyne-pair", "velodyne.toml", 2),
])
def test_shared_recordings_match_edtmap_run(tmp_path, folder, config, frames):
    # The repository's own data/ first, then ../shared/data beside the checkout.
    data = next((d / folder for d in (REPO / "data", SHARED) if (d / folder).is_dir()), None)
    if data is None:
        pytest.skip(f"{folder} is in neither {REPO / 'data'} nor {SHARED}")
    config = REPO / "configs" / config
    cli("run", "--config", config, "--dataset", data, "--frames", frames, "--out", tmp_path / "out",
        "--save", tmp_path / "cli.edtmap", cwd=tmp_path)
    mapper, count = replay(data, config, frames)
    assert count == frames
    mapper.save(tmp_path / "py.edtmap")
    assert (tmp_path / "py.edtmap").read_bytes() == (tmp_path / "cli.edtmap").read_bytes()


def test_distance_equals_edtmap_query(tmp_path):
    recording, config = recorded(tmp_path, "room", 4, "mcap")
    mapper, _ = replay(recording, config)
    mapper.save(tmp_path / "map.edtmap")
    rng = np.random.default_rng(11)
    points = rng.uniform([-1.0, -1.0, 0.0], [6.0, 6.0, 3.0], size=(300, 3))
    np.savetxt(tmp_path / "pts.csv", points, delimiter=",", fmt="%.17g")
    for signed in (False, True):
        args = ["query", "--points", tmp_path / "pts.csv", tmp_path / "map.edtmap"] + (["--signed"] if signed else [])
        rows = [line.split(",") for line in cli(*args, cwd=tmp_path).splitlines()[1:]]
        want_d = np.array([float(r[3]) for r in rows])
        want_g = np.array([[float(v) for v in r[4:7]] for r in rows])
        names = {"outside": 0, "unknown": 1, "free": 2, "occupied": 3}
        want_s = np.array([names[r[7]] for r in rows])
        d, g, s = mapper.distance(points, signed=signed)
        assert d.shape == (300,) and g.shape == (300, 3) and s.dtype == np.uint8
        # The command line prints 6 decimals.
        np.testing.assert_allclose(d, want_d, atol=5e-7, rtol=0)
        np.testing.assert_allclose(g, want_g, atol=5e-7, rtol=0)
        np.testing.assert_array_equal(s, want_s)
        np.testing.assert_array_equal(mapper.state(points), want_s)
        assert (s == 3).any() and (s == 2).any()


def wall_mapper():
    """A wall of returns at x = 2.05 m (the centres of voxel column 20)."""
    mapper = edtmap.Mapper(edtmap.PointSensor(0.1, 20.0), 0.1, max_distance_m=2.0)
    ys, zs = np.meshgrid(np.arange(-1.0, 1.0, 0.05) + 0.025, np.arange(-0.5, 0.5, 0.05) + 0.025)
    wall = np.stack([np.full(ys.size, 2.05), ys.ravel(), zs.ravel()], axis=1)
    pose = np.eye(4)
    pose[:3, 3] = [0.0, 0.0, 1.0]
    stats = mapper.integrate_points(wall, pose)
    assert stats["voxels_updated"] > 0
    return mapper


def test_wall_distances_and_gradients_are_analytic():
    mapper = wall_mapper()
    # Voxel centres in front of the wall, on the sensor's rays: the distance
    # is exactly the gap to the wall's voxel centres.
    xs = np.arange(5, 20) * 0.1 + 0.05
    points = np.stack([xs, np.full_like(xs, 0.05), np.full_like(xs, 1.05)], axis=1)
    d, g, s = mapper.distance(points)
    np.testing.assert_allclose(d, np.minimum(2.05 - xs, 2.0), atol=1e-9)
    # Free up to half a voxel diagonal in front of the return.
    assert (s[:-1] == 2).all() and s[-1] == 1
    assert (g[:, 0] < 0).all()
    d, _, s = mapper.distance([[2.05, 0.05, 1.05]])
    assert abs(d[0]) < 1e-12 and s[0] == 3
    ds, gs, _ = mapper.distance([[2.05, 0.05, 1.05], [1.55, 0.05, 1.05]], signed=True)
    assert ds[0] < 0 < ds[1]
    dist, states, origin = mapper.export_box([1.0, 0.0, 1.0], [2.2, 0.1, 1.1])
    assert dist.shape == (12, 1, 1) and states.shape == (12, 1, 1)
    np.testing.assert_allclose(origin, [1.05, 0.05, 1.05])
    np.testing.assert_allclose(dist[:, 0, 0], np.minimum(np.abs(2.05 - (1.05 + 0.1 * np.arange(12))), 2.0),
                               atol=1e-6)
    local = mapper.local_edt()
    assert local["distance_m"].ndim == 3 and local["states"].shape == local["distance_m"].shape
    front = mapper.frontiers()
    assert front.ndim == 2 and front.shape[1] == 3 and len(front) > 0


def test_save_load_round_trip(tmp_path):
    mapper = wall_mapper()
    mapper.save(tmp_path / "a.edtmap")
    loaded = edtmap.Mapper.load(tmp_path / "a.edtmap")
    assert loaded.voxel_size_m == 0.1 and loaded.max_distance_m == 2.0
    points = np.random.default_rng(2).uniform(-1, 3, size=(500, 3))
    for a, b in zip(mapper.distance(points), loaded.distance(points)):
        np.testing.assert_array_equal(a, b)
    loaded.save(tmp_path / "b.edtmap")
    assert (tmp_path / "a.edtmap").read_bytes() == (tmp_path / "b.edtmap").read_bytes()


def test_backends():
    mapper = edtmap.Mapper(edtmap.PointSensor(), 0.1, backend="cpu")
    assert mapper.backend.startswith("cpu")
    with pytest.raises(ValueError, match="backend must be"):
        edtmap.Mapper(edtmap.PointSensor(), 0.1, backend="tpu")
    try:
        gpu = edtmap.Mapper(edtmap.PointSensor(), 0.1, backend="auto")
    except ValueError as e:
        # A build without the gpu feature says how to get it.
        assert "--features gpu" in str(e)
    else:
        assert gpu.backend


def test_from_config_and_local_edt(tmp_path):
    mapper = edtmap.Mapper.from_config(REPO / "configs" / "uav_pillars.toml")
    assert mapper.sensor_kind == "lidar" and mapper.voxel_size_m == 0.2
    assert mapper.local_edt() is None


def test_sensor_helpers_build_mappers():
    cam = edtmap.DepthCamera(500.0, 500.0, 32.0, 24.0, 64, 48, min_range_m=0.2, max_range_m=5.0)
    mapper = edtmap.Mapper(cam, 0.05, local_size_m=[4.0, 4.0, 2.0], max_distance_m=1.0)
    depth = np.full((48, 64), 2.0, dtype=np.float32)
    stats = mapper.integrate_depth(depth, np.eye(4))
    assert stats["voxels_updated"] > 0
    raw = np.full((48, 64), 2000, dtype=np.uint16)
    mapper2 = edtmap.Mapper(cam, 0.05, local_size_m=[4.0, 4.0, 2.0], max_distance_m=1.0)
    mapper2.integrate_depth(raw, np.eye(4), depth_scale=0.001)
    points = np.random.default_rng(4).uniform(-1, 3, size=(200, 3))
    for a, b in zip(mapper.distance(points), mapper2.distance(points)):
        np.testing.assert_array_equal(a, b)
    lidar = edtmap.Mapper(edtmap.SpinningLidar(16, -15, 15, 360, 0.2, 30.0), 0.2)
    lidar.integrate_range_image(np.full((16, 360), 5.0, dtype=np.float32), np.eye(4))
    planar = edtmap.Mapper(edtmap.PlanarLidar(0.1, 10.0), 0.1)
    planar.integrate_scan(np.full(180, 3.0, dtype=np.float32), -np.pi / 2, np.pi / 180, np.eye(4))
    d, _, _ = planar.distance([[2.95, 0.05, 0.05]])
    assert d[0] < 0.2


def test_planar_map_distances_are_its_layers_brute_force(tmp_path):
    # A planar LiDAR in a square room with a pillar, mapped planar: every
    # distance in the scan's layer equals a brute-force 2D EDT of the
    # layer's occupied voxels, and nothing is stored above or below it.
    mapper = edtmap.Mapper(edtmap.PlanarLidar(0.1, 10.0), 0.1, planar=True, local_size_m=[8.0, 8.0, 0.1],
                           max_distance_m=1.0)
    angles = -np.pi + (np.arange(720) + 0.5) * (2 * np.pi / 720)
    c, s = np.cos(angles), np.sin(angles)
    walls = np.minimum(np.where(c != 0, 2.93 / np.abs(c), np.inf), np.where(s != 0, 2.57 / np.abs(s), np.inf))
    # The pillar: a disc of radius 0.3 m at (1.2, 0.7).
    b = 1.2 * c + 0.7 * s
    disc = b - np.sqrt(np.maximum(b * b - (1.2 ** 2 + 0.7 ** 2 - 0.09), 0.0))
    hits = np.where((b * b >= 1.2 ** 2 + 0.7 ** 2 - 0.09) & (disc > 0), disc, np.inf)
    ranges = np.minimum(walls, hits).astype(np.float32)
    pose = np.eye(4)
    pose[2, 3] = 1.05
    for yaw in (0.0, 0.3):
        pose[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
        mapper.integrate_scan(ranges, -np.pi + 0.5 * np.pi / 360 - yaw, 2 * np.pi / 720, pose)
    xs = (np.arange(-40, 40) + 0.5) * 0.1
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    layer = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, 1.05)], axis=1)
    d, g, states = mapper.distance(layer)
    occupied = layer[states == 3][:, :2]
    assert len(occupied) > 100
    truth = np.sqrt(((layer[:, None, :2] - occupied[None]) ** 2).sum(-1)).min(1)
    np.testing.assert_allclose(d, np.minimum(truth, 1.0), atol=1e-9)
    assert (g[:, 2] == 0).all()
    above = layer + [0.0, 0.0, 0.1]
    d_above, _, _ = mapper.distance(above)
    assert (d_above == 1.0).all()
    mapper.save(tmp_path / "planar.edtmap")
    loaded = edtmap.Mapper.load(tmp_path / "planar.edtmap")
    for a, b in zip(mapper.distance(layer), loaded.distance(layer)):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="planar"):
        edtmap.Mapper(edtmap.PlanarLidar(0.1, 10.0), 0.1, planar=True, mode="wavefront")


def test_bad_input_raises_and_keeps_the_map(tmp_path):
    mapper = wall_mapper()
    points = np.random.default_rng(3).uniform(-1, 3, size=(100, 3))
    before = mapper.distance(points)
    good = np.ones((10, 3), dtype=np.float32)
    nan_pose = np.eye(4)
    nan_pose[0, 3] = np.nan
    skew = np.eye(4)
    skew[0, 1] = 0.5
    cases = [
        (ValueError, "points", lambda: mapper.integrate_points(np.ones((10, 2)), np.eye(4))),
        (ValueError, "empty", lambda: mapper.integrate_points(np.ones((0, 3)), np.eye(4))),
        (TypeError, "points", lambda: mapper.integrate_points(np.array([["a", "b", "c"]]), np.eye(4))),
        (ValueError, "t_world_sensor", lambda: mapper.integrate_points(good, nan_pose)),
        (ValueError, "t_world_sensor", lambda: mapper.integrate_points(good, skew)),
        (ValueError, "t_world_sensor", lambda: mapper.integrate_points(good, np.eye(3))),
        (ValueError, "t_world_sensor", lambda: mapper.integrate_points(good, [0, 0, 0, 0, 0, 0, 2.0])),
        (ValueError, "stamp", lambda: mapper.integrate_points(good, np.eye(4), stamp=np.inf)),
        (ValueError, "depth", lambda: mapper.integrate_depth(np.ones((4, 4), np.float32), np.eye(4))),
        (TypeError, "depth", lambda: mapper.integrate_depth(np.ones((4, 4), np.int32), np.eye(4))),
        (ValueError, "points", lambda: mapper.distance(np.ones((5, 4)))),
        (ValueError, "min_m", lambda: mapper.export_box([0, 0], [1, 1, 1])),
        (ValueError, "box", lambda: mapper.export_box([1, 1, 1], [0, 0, 0])),
        (TypeError, "unknown parameter", lambda: edtmap.Mapper(edtmap.PointSensor(), 0.1, cutof=2.0)),
        (TypeError, "sensor", lambda: edtmap.Mapper("lidar", 0.1)),
        (ValueError, "voxel", lambda: edtmap.Mapper(edtmap.PointSensor(), -0.1)),
        (ValueError, "connectivity", lambda: edtmap.Mapper(edtmap.PointSensor(), 0.1, connectivity=7)),
    ]
    for exc, words, call in cases:
        with pytest.raises(exc, match=f"(?i){words}"):
            call()
    after = mapper.distance(points)
    for a, b in zip(before, after):
        np.testing.assert_array_equal(a, b)
    (tmp_path / "bad.edtmap").write_bytes(b"not a map at all")
    with pytest.raises((ValueError, OSError), match="bad.edtmap"):
        edtmap.Mapper.load(tmp_path / "bad.edtmap")
    with pytest.raises(OSError, match="missing.toml"):
        edtmap.Mapper.from_config(tmp_path / "missing.toml")
    with pytest.raises((ValueError, OSError)):
        edtmap.read_recording(tmp_path / "nothing.mcap", REPO / "configs" / "room.toml")


@pytest.mark.parametrize("field", ["voxel_size_m", "local_size_m", "max_distance_m", "prob_hit"])
@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_parameters_name_the_argument(field, value):
    params = {"voxel_size_m": 0.1, "max_distance_m": 2.0}
    params[field] = [4.0, value, 2.0] if field == "local_size_m" else value
    voxel = params.pop("voxel_size_m")
    with pytest.raises(ValueError, match=rf"^{field}(\[1\])? must be a finite number, got -?(nan|inf)$"):
        edtmap.Mapper(edtmap.PointSensor(), voxel, **params)


@pytest.mark.parametrize("field, value, words", [
    ("max_distance_m", "2", "max_distance_m must be a number, not str"),
    ("local_size_m", [4.0, 4.0], r"local_size_m must be three numbers \(x, y, z\)"),
    ("local_size_m", [4.0, "4", 2.0], r"local_size_m\[1\] must be a number, not str"),
    ("prob_hit", True, "prob_hit must be a number, not bool"),
    ("planar", 1, "planar must be True or False, not int"),
    ("connectivity", 26.0, "connectivity must be an integer, not float"),
    ("mode", 1, "mode must be a string, not int"),
])
def test_parameters_of_the_wrong_type_name_the_argument(field, value, words):
    with pytest.raises(TypeError, match=f"^{words}"):
        edtmap.Mapper(edtmap.PointSensor(), 0.1, **{field: value})


def test_numpy_parameters_are_taken_as_numbers():
    m = edtmap.Mapper(edtmap.PointSensor(), np.float32(0.5), max_distance_m=np.float64(2.0),
                      local_size_m=np.array([4.0, 4.0, 2.0]), connectivity=np.int64(26), planar=np.bool_(False))
    assert m is not None


def test_non_finite_sensor_fields_name_the_argument():
    cam = edtmap.DepthCamera(np.nan, 500.0, 32.0, 24.0, 64, 48)
    with pytest.raises(ValueError, match="^DepthCamera fx must be a finite number, got nan$"):
        edtmap.Mapper(cam, 0.05)
    with pytest.raises(TypeError, match="voxel_size_m must be a number"):
        edtmap.Mapper(edtmap.PointSensor(), "fine")


def test_byte_swapped_depth_is_converted():
    cam = edtmap.DepthCamera(500.0, 500.0, 32.0, 24.0, 64, 48, min_range_m=0.2, max_range_m=5.0)
    raw = np.random.default_rng(6).integers(500, 4000, size=(48, 64)).astype(np.uint16)
    native = edtmap.Mapper(cam, 0.05, local_size_m=[4.0, 4.0, 2.0])
    native.integrate_depth(raw, np.eye(4), depth_scale=0.001)
    swapped = edtmap.Mapper(cam, 0.05, local_size_m=[4.0, 4.0, 2.0])
    swapped.integrate_depth(raw.astype(">u2"), np.eye(4), depth_scale=0.001)
    points = np.random.default_rng(7).uniform(-1, 3, size=(300, 3))
    for a, b in zip(native.distance(points), swapped.distance(points)):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(TypeError, match=r"^depth must be float \(metres\) or uint16 \(raw, either byte order\), "
                                        r"not int32$"):
        native.integrate_depth(raw.astype(np.int32), np.eye(4))


def test_queries_from_threads_while_integrating(tmp_path):
    recording, config = recorded(tmp_path, "uav_pillars", 6, "mcap")
    frames = list(edtmap.read_recording(recording, config))
    points = np.random.default_rng(9).uniform([-5, -5, 0], [15, 5, 3], size=(2000, 3))
    # The answer after each number of frames, from a mapper nobody else uses.
    reference = edtmap.read_recording(recording, config).mapper()
    expected = [reference.distance(points)[0]]
    for frame in frames:
        reference.integrate(frame)
        expected.append(reference.distance(points)[0])
    mapper = edtmap.read_recording(recording, config).mapper()
    done = threading.Event()
    seen, errors = [], []

    def query():
        try:
            while not done.is_set():
                d = mapper.distance(points)[0]
                match = [k for k, e in enumerate(expected) if np.array_equal(d, e, equal_nan=True)]
                if not match:
                    errors.append("an answer matching no frame")
                seen.append(match[0] if match else -1)
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(repr(e))

    threads = [threading.Thread(target=query) for _ in range(4)]
    for t in threads:
        t.start()
    for frame in frames:
        mapper.integrate(frame)
    done.set()
    for t in threads:
        t.join()
    assert not errors, errors[:3]
    assert len(seen) >= 4
    np.testing.assert_array_equal(mapper.distance(points)[0], expected[-1])
