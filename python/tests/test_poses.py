"""Poses as published: a rotation within 1e-2 of orthonormal (|R^T R - I|)
or a quaternion whose norm is within 1e-2 of 1 is replaced by the nearest
rotation; beyond, it is refused naming the problem. A recording warns once."""

import warnings
from pathlib import Path

import numpy as np
import pytest

import edtmap

REPO = Path(__file__).resolve().parents[2]


def rotation_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def nearest_rotation(m):
    """The orthogonal polar factor, by NumPy's SVD: an independent oracle."""
    u, _, vt = np.linalg.svd(m)
    return u @ vt


def wall():
    ys, zs = np.meshgrid(np.arange(-1.0, 1.0, 0.05) + 0.025, np.arange(-0.5, 0.5, 0.05) + 0.025)
    return np.stack([np.full(ys.size, 2.05), ys.ravel(), zs.ravel()], axis=1)


def test_a_published_matrix_maps_as_its_nearest_rotation():
    rng = np.random.default_rng(5)
    noisy = np.eye(4)
    noisy[:3, :3] = rotation_z(0.3) + rng.uniform(-2e-4, 2e-4, (3, 3))
    noisy[:3, 3] = [0.1, -0.2, 1.0]
    deviation = np.abs(noisy[:3, :3].T @ noisy[:3, :3] - np.eye(3)).max()
    assert 1e-4 < deviation < 1e-2
    exact = noisy.copy()
    exact[:3, :3] = nearest_rotation(noisy[:3, :3])
    maps = []
    for pose in (noisy, exact):
        mapper = edtmap.Mapper(edtmap.PointSensor(0.1, 20.0), 0.1, max_distance_m=2.0)
        mapper.integrate_points(wall(), pose)
        probe = np.array([[x, y, 1.0] for x in np.arange(0.0, 3.0, 0.1) for y in np.arange(-1.0, 1.0, 0.1)])
        maps.append((mapper.state(probe), mapper.distance(probe)[0]))
    np.testing.assert_array_equal(maps[0][0], maps[1][0])
    np.testing.assert_allclose(maps[0][1], maps[1][1], atol=1e-6)


def test_a_quaternion_with_three_decimals_is_normalised_and_a_bad_one_refused():
    mapper = edtmap.Mapper(edtmap.PointSensor(0.1, 20.0), 0.1, max_distance_m=2.0)
    mapper.integrate_points(wall(), [0.0, 0.0, 1.0, 0.0, 0.0, 0.149, 0.989])  # |q| = 1.0002
    mapper = edtmap.Mapper(edtmap.PointSensor(0.1, 20.0), 0.1, max_distance_m=2.0)
    scaled = np.eye(4)
    scaled[:3, :3] *= 1.02
    with pytest.raises(ValueError, match="not orthonormal"):
        mapper.integrate_points(wall(), scaled)
    with pytest.raises(ValueError, match="norm"):
        mapper.integrate_points(wall(), [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.9])


def test_a_recording_warns_once_about_the_poses_it_adjusted(tmp_path):
    folder = tmp_path / "clouds"
    folder.mkdir()
    rng = np.random.default_rng(9)
    lines = []
    for k in range(3):
        points = wall().astype(np.float32)
        header = ("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                  f"WIDTH {len(points)}\nHEIGHT 1\nPOINTS {len(points)}\nDATA ascii\n")
        (folder / f"00000{k}.pcd").write_text(header + "\n".join(" ".join(f"{v:.4f}" for v in p) for p in points) + "\n")
        m = np.hstack([rotation_z(0.05 * k) + rng.uniform(-2e-4, 2e-4, (3, 3)), [[0.1 * k], [0.0], [1.0]]])
        lines.append(" ".join(f"{v:.6f}" for v in m.ravel()))
    (folder / "poses.txt").write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frames = list(edtmap.read_recording(folder, REPO / "configs" / "velodyne.toml"))
    assert len(frames) == 3
    notes = [str(w.message) for w in caught if "orthonormal only to" in str(w.message)]
    assert len(notes) == 1 and "3 poses" in notes[0], [str(w.message) for w in caught]
    # The frames' poses are rotations: orthonormal to float precision.
    for f in frames:
        r = np.asarray(f["t_world_sensor"])[:3, :3]
        assert np.abs(r.T @ r - np.eye(3)).max() < 1e-12
