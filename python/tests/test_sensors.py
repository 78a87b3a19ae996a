"""Several sensors into one map from Python: a depth camera and a planar
LiDAR fused in one mapper equal, byte for byte, the map the same frames make
through single-sensor mappers that hand the map on (save, load)."""

from pathlib import Path

import numpy as np
import pytest

import edtmap

REPO = Path(__file__).resolve().parents[2]

CAMERA = edtmap.DepthCamera(fx=40.0, fy=40.0, cx=31.5, cy=23.5, width=64, height=48, min_range_m=0.1,
                            max_range_m=6.0)
SCAN = edtmap.PlanarLidar(min_range_m=0.1, max_range_m=8.0)
PARAMS = dict(max_distance_m=1.0, local_size_m=[6.0, 6.0, 3.0])


def frames():
    """A wall 3 m ahead seen by the camera (optical z forward) and a ring of
    scan returns about 2.5 m away, the robot stepping along x: per frame its
    sensor and a call integrating it, naming the sensor it is given."""
    depth = np.full((48, 64), 3.0, np.float32)
    depth[:, :8] = np.nan
    ranges = (2.5 + 0.2 * np.sin(np.linspace(0, 6, 360))).astype(np.float32)
    out = []
    for k in range(4):
        cam = np.array([[0, 0, 1, 0.1 * k], [-1, 0, 0, 0], [0, -1, 0, 1.0], [0, 0, 0, 1]], float)
        scan_pose = np.eye(4)
        scan_pose[:3, 3] = [0.1 * k, 0.0, 0.5]
        out.append(("camera", lambda m, name, p=cam, s=k: m.integrate_depth(depth, p, stamp=s, sensor=name)))
        out.append(("scan", lambda m, name, p=scan_pose, s=k: m.integrate_scan(
            ranges, 0.0, 2 * np.pi / 360, p, stamp=s, sensor=name)))
    return out


def test_two_sensors_equal_single_sensor_mappers_handing_on_the_map(tmp_path):
    both = edtmap.Mapper(CAMERA, 0.1, **PARAMS)
    assert both.sensors == [("depth", "depth")], "the first sensor is named after its kind"
    assert both.add_sensor("scan", SCAN) == 1
    assert both.sensors == [("depth", "depth"), ("scan", "planar")]
    for sensor, integrate in frames():
        assert integrate(both, "depth" if sensor == "camera" else "scan")["voxels_updated"] > 0
    both.save(tmp_path / "both.edtmap")

    path = None
    for sensor, integrate in frames():
        model = CAMERA if sensor == "camera" else SCAN
        one = edtmap.Mapper(model, 0.1, **PARAMS) if path is None else edtmap.Mapper.load(path, model, **PARAMS)
        integrate(one, None)
        path = tmp_path / "step.edtmap"
        one.save(path)
    assert (tmp_path / "both.edtmap").read_bytes() == path.read_bytes()


def test_sensor_names_are_checked():
    mapper = edtmap.Mapper(CAMERA, 0.1, **PARAMS)
    with pytest.raises(ValueError, match="another sensor"):
        mapper.add_sensor("depth", SCAN)
    with pytest.raises(TypeError, match="unknown option 'colour'"):
        mapper.add_sensor("scan", SCAN, colour="red")
    with pytest.raises(ValueError, match="projection"):
        mapper.add_sensor("cloud", edtmap.PointSensor(), construction="projection")
    with pytest.raises(ValueError, match="the mapper's sensors are depth"):
        mapper.integrate_points(np.ones((4, 3)), np.eye(4), sensor="lidar")
    assert mapper.sensors == [("depth", "depth")] and mapper.map_blocks == 0


def test_a_config_with_several_sensors_gives_them_all():
    config = __import__("pathlib").Path(__file__).resolve().parents[2] / "configs" / "ugv_corridor_camera.toml"
    mapper = edtmap.Mapper.from_config(config)
    assert mapper.sensors == [("lidar_top", "lidar"), ("front_camera", "depth")]
    depth = np.full((120, 160), 2.0, np.float32)
    optical = np.array([[0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 0.3], [0, 0, 0, 1]], float)
    assert mapper.integrate_depth(depth, optical, sensor="front_camera")["voxels_updated"] > 0
    with pytest.raises(ValueError, match="a depth image measurement from a spinning LiDAR sensor"):
        mapper.integrate_depth(np.full((120, 160), 2.0, np.float32), optical, sensor="lidar_top")


def test_a_two_sensor_recording_replays_as_edtmap_run_does(tmp_path):
    from test_mapper import cli  # the command line, or a skip without it

    recording = tmp_path / "two.mcap"
    cli("record", "--config", REPO / "configs" / "ugv_corridor_camera.toml", "--frames", 4, recording, cwd=tmp_path)
    config = tmp_path / "two.toml"
    cli("run", "--config", config, "--dataset", recording, "--out", tmp_path / "out",
        "--save", tmp_path / "cli.edtmap", cwd=tmp_path)
    rec = edtmap.read_recording(recording, config)
    mapper = rec.mapper()
    assert mapper.sensors == [("lidar_top", "points"), ("front_camera", "depth")]
    names = []
    for frame in rec:
        names.append(frame["sensor"])
        mapper.integrate(frame)
    assert rec.skipped == []
    assert names == ["lidar_top", "front_camera"] * 4
    mapper.save(tmp_path / "py.edtmap")
    assert (tmp_path / "py.edtmap").read_bytes() == (tmp_path / "cli.edtmap").read_bytes()
