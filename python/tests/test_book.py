"""The Python examples of the README and the book (docs/python.md), which
show the code between this file's ANCHOR lines (checked by
.ci/check_docs.py), run here so that what they show works."""

import os
from pathlib import Path

import numpy as np

import edtmap

REPO = Path(__file__).resolve().parents[2]


def test_distance_transforms():
    # ANCHOR: transforms
    import numpy as np, edtmap

    grid = np.random.default_rng(0).random((128, 128, 128)) > 0.01      # True = free, False = obstacle
    d, idx = edtmap.distance_transform_edt(grid, sampling=(0.1, 0.1, 0.2), return_indices=True)
    e = edtmap.edt(grid.astype(np.uint8), anisotropy=(0.1, 0.1, 0.2), black_border=False, parallel=0)
    dist, nearest = edtmap.obstacle_distance(~grid, voxel_size=0.1, return_nearest=True)
    # ANCHOR_END: transforms
    assert d.shape == grid.shape and idx.shape == (3,) + grid.shape
    assert np.allclose(d, e, rtol=1e-6) and dist.shape == grid.shape


def test_a_mapper_and_the_readme(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    # ANCHOR: mapper
    import numpy as np, edtmap

    mapper = edtmap.Mapper(edtmap.DepthCamera(fx=525, fy=525, cx=319.5, cy=239.5, width=640, height=480,
                                              min_range_m=0.3, max_range_m=6.0),
                           voxel_size_m=0.05, local_size_m=[8, 8, 6], max_distance_m=2.0)
    # A wall 2 m ahead of the camera (its z axis), seen from the origin (4 x 4 T_world_sensor).
    stats = mapper.integrate_depth(np.full((480, 640), 2.0, np.float32), np.eye(4))
    d, grad, state = mapper.distance(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.9], [0.0, 0.0, 2.0]]))
    print(d, grad[:, 2], state)     # [1.025 0.125 0.025] [-1. -1. -1.] [2 2 3]
                                    # (states: 0 outside, 1 unknown, 2 free, 3 occupied)
    mapper.save("map.edtmap")       # for edtmap query / edtmap.Mapper.load
    # ANCHOR_END: mapper
    assert np.allclose(d, [1.025, 0.125, 0.025]) and np.allclose(grad[:, 2], -1.0)
    assert list(state) == [2, 2, 3] and stats["total_ms"] >= 0
    (tmp_path / "edtmap-out").mkdir()
    os.replace("map.edtmap", "edtmap-out/map.edtmap")
    # ANCHOR: readme
    import numpy as np, edtmap

    mapper = edtmap.Mapper.load("edtmap-out/map.edtmap")          # or Mapper.from_config(...)
    dist, grad, state = mapper.distance(np.array([[1.0, 2.0, 0.5]]))
    d = edtmap.distance_transform_edt(np.random.default_rng(0).random((64, 64, 64)) > 0.01)   # SciPy's call, exact
    # ANCHOR_END: readme
    assert dist.shape == (1,) and d.shape == (64, 64, 64)


def test_a_recording(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for folder in ("data", "configs"):
        os.symlink(REPO / folder, tmp_path / folder)
    # ANCHOR: recording
    rec = edtmap.read_recording("data/velodyne-pair", "configs/velodyne.toml")   # two Velodyne scans
    mapper = rec.mapper()
    for frame in rec:
        mapper.integrate(frame)
    mapper.save("velodyne.edtmap")
    # ANCHOR_END: recording
    assert rec.skipped == [] and (tmp_path / "velodyne.edtmap").stat().st_size > 0


def test_a_map_file_read_without_edtmap(tmp_path):
    # ANCHOR: read_edtmap
    import struct, tomllib, zlib

    NO_OFFSET = (-32768,) * 3  # an EDT voxel with no obstacle within the cutoff

    def read_edtmap(path):
        """(voxel_size_m, params, sections): each section maps a block key to
        the block's values in voxel offset order, every layer filled in."""
        b = open(path, "rb").read()
        assert b[:8] == b"EDTMAP\r\n", "not an edtmap map file"
        version, flags, total, voxel_size_m, p = struct.unpack_from("<IIQdI", b, 8)
        assert version in (1, 2, 3) and flags == 0 and total == len(b)
        assert struct.unpack_from("<I", b, len(b) - 4)[0] == zlib.crc32(b[:-4])
        params = tomllib.loads(b[36:36 + p].decode())
        # Per section: one layer's layout, and what a layer that is not stored holds.
        layers = {"occupancy": ("<64f", (float("-inf"),) * 64),
                  "edt": ("<192h", NO_OFFSET * 64),  # the offset x, y, z to the nearest obstacle
                  "fixed": ("<Q", (0,))}             # one bit a voxel
        at, sections = 36 + p, {}
        for name, (layer, empty) in layers.items():
            (n,), at = struct.unpack_from("<Q", b, at), at + 8
            blocks = sections[name] = {}
            for _ in range(n):
                key, at = struct.unpack_from("<3i", b, at), at + 12
                if version == 1 and name == "edt":  # 512 dist_sq, then 512 nearest voxel indices
                    blocks[key], at = struct.unpack_from("<512I1536i", b, at), at + 8192
                    continue
                mask = 0xFF
                if version >= 3:
                    mask, at = b[at], at + 1
                values = ()
                for z in range(8):
                    if mask >> z & 1:
                        values += struct.unpack_from(layer, b, at)
                        at += struct.calcsize(layer)
                    else:
                        values += empty
                blocks[key] = values
        return voxel_size_m, params, sections
    # ANCHOR_END: read_edtmap
    mapper = edtmap.Mapper(edtmap.PointSensor(0.1, 20.0), 0.1, max_distance_m=1.0)
    wall = np.array([[3.0, y, z] for y in np.arange(-1.0, 1.0, 0.05) for z in np.arange(-0.5, 0.5, 0.05)])
    mapper.integrate_points(wall, np.eye(4))
    mapper.save(tmp_path / "wall.edtmap")
    voxel_size_m, params, sections = read_edtmap(tmp_path / "wall.edtmap")
    assert voxel_size_m == 0.1 and params["global"]["max_distance_m"] == 1.0
    # Occupied voxels (log-odds above 0) are those the mapper says are occupied,
    # and each is its own nearest obstacle.
    occupied = []
    for key, log_odds in sections["occupancy"].items():
        for o, v in enumerate(log_odds):
            if v > 0:
                occupied.append((key, o))
                assert sections["edt"][key][3 * o:3 * o + 3] == (0, 0, 0)
    centres = np.array([[(8 * k[0] + o % 8 + 0.5) * 0.1, (8 * k[1] + o // 8 % 8 + 0.5) * 0.1,
                         (8 * k[2] + o // 64 + 0.5) * 0.1] for k, o in occupied])
    assert len(occupied) > 100 and (mapper.state(centres) == 3).all()


def exported_box(folder):
    """`box.npy` and `box.npy.json` in `folder`: `edtmap export` of a map
    with one obstacle, at x 2.0 m."""
    from test_mapper import cli  # the command line, or a skip without it

    mapper = edtmap.Mapper(edtmap.PointSensor(0.1, 20.0), 0.1, max_distance_m=1.0)
    mapper.integrate_points(np.array([[2.0, 0.0, 0.0]]), np.eye(4))
    mapper.save(folder / "map.edtmap")
    cli("export", "map.edtmap", "box.npy", cwd=folder)


def test_an_exported_box_read_with_numpy(tmp_path, monkeypatch):
    exported_box(tmp_path)
    monkeypatch.chdir(tmp_path)
    # ANCHOR: read_box
    import json, numpy as np

    dist = np.load("box.npy")
    meta = json.load(open("box.npy.json"))
    vs, origin = meta["voxel_size_m"], np.array(meta["origin_m"])
    k, j, i = np.unravel_index(np.argmin(dist), dist.shape)
    print("closest to an obstacle at", origin + vs * np.array([i, j, k]), "m")
    # ANCHOR_END: read_box
    closest = origin + vs * np.array([i, j, k])
    assert np.allclose(closest, [2.05, 0.05, 0.05])
