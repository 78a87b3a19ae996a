"""The mapping pipeline from Python: sensors, :class:`Mapper` and
:func:`read_recording`."""

from __future__ import annotations

import json
import math
import os
from typing import Any, Dict, Iterator, Optional, Sequence, Tuple, Union

import numpy as np

from . import _edtmap

__all__ = ["DepthCamera", "SpinningLidar", "PointSensor", "PlanarLidar", "Mapper", "Recording",
           "read_recording"]

PathLike = Union[str, "os.PathLike[str]"]


class _Sensor:
    """A sensor model: the ``[sensor]`` section of a configuration file."""

    def __init__(self, kind: str, fields: Dict[str, Any]):
        self._section = {"kind": kind}
        self._section.update({k: v for k, v in fields.items() if v is not None})

    def section(self) -> Dict[str, Any]:
        """The ``[sensor]`` table this sensor stands for."""
        return dict(self._section)

    def __repr__(self) -> str:
        fields = ", ".join(f"{k}={v!r}" for k, v in self._section.items() if k != "kind")
        return f"{type(self).__name__}({fields})"


class DepthCamera(_Sensor):
    """A pinhole depth camera: focal lengths and principal point in pixels,
    the image size, and the valid depth range in metres."""

    def __init__(self, fx: float, fy: float, cx: float, cy: float, width: int, height: int,
                 min_range_m: float = 0.1, max_range_m: float = 10.0):
        super().__init__("depth", dict(fx=float(fx), fy=float(fy), cx=float(cx), cy=float(cy),
                                       width=int(width), height=int(height),
                                       min_range_m=float(min_range_m), max_range_m=float(max_range_m)))


class SpinningLidar(_Sensor):
    """A spinning LiDAR delivering range images: ``rings`` rings evenly
    spread over ``[elevation_min_deg, elevation_max_deg]`` (or an explicit
    ``ring_elevations_deg``), ``azimuth_bins`` bins per turn."""

    def __init__(self, rings: Optional[int] = None, elevation_min_deg: Optional[float] = None,
                 elevation_max_deg: Optional[float] = None, azimuth_bins: int = 900,
                 min_range_m: float = 0.2, max_range_m: float = 100.0,
                 ring_elevations_deg: Optional[Sequence[float]] = None):
        super().__init__("lidar", dict(
            rings=None if rings is None else int(rings),
            elevation_min_deg=None if elevation_min_deg is None else float(elevation_min_deg),
            elevation_max_deg=None if elevation_max_deg is None else float(elevation_max_deg),
            ring_elevations_deg=None if ring_elevations_deg is None else [float(e) for e in ring_elevations_deg],
            azimuth_bins=int(azimuth_bins), min_range_m=float(min_range_m), max_range_m=float(max_range_m)))


class PointSensor(_Sensor):
    """Any source of 3D points (no ring structure; ray casting)."""

    def __init__(self, min_range_m: float = 0.0, max_range_m: float = 100.0):
        super().__init__("points", dict(min_range_m=float(min_range_m), max_range_m=float(max_range_m)))


class PlanarLidar(_Sensor):
    """A planar LiDAR (laser scans); each scan carries its own angles."""

    def __init__(self, min_range_m: float = 0.0, max_range_m: float = 30.0):
        super().__init__("planar", dict(min_range_m=float(min_range_m), max_range_m=float(max_range_m)))


# Where each keyword of ``Mapper(...)`` goes in the configuration.
_SECTIONS = {
    "occupancy": ("local_size_m", "fixed_height_m", "prob_hit", "prob_miss", "clamp_min", "clamp_max",
                  "occupied_threshold"),
    "edt": ("unknown_as_occupied",),
    "global": ("max_distance_m", "connectivity", "mode", "forbidden", "planar"),
    "sensor": ("construction", "clear_no_return", "free_margin_m", "planar_half_thickness_m"),
}


# The type each keyword takes: "number" (metres or a probability),
# "numbers3" (three numbers), "bool", "int", "str", or None (checked by the
# core: forbidden zones, the memory budget).
_KINDS = {
    "local_size_m": "numbers3", "fixed_height_m": "number", "prob_hit": "number", "prob_miss": "number",
    "clamp_min": "number", "clamp_max": "number", "occupied_threshold": "number",
    "unknown_as_occupied": "bool", "max_distance_m": "number", "connectivity": "int", "mode": "str",
    "forbidden": None, "planar": "bool", "construction": "str", "clear_no_return": "bool",
    "free_margin_m": "number", "planar_half_thickness_m": "number",
}


def _typed(key: str, value: Any) -> Any:
    """``value`` of the keyword ``key`` as the configuration takes it, or a
    ``TypeError`` naming the keyword and what it takes."""
    kind = _KINDS.get(key)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()

    def number(v: Any, name: str) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise TypeError(f"{name} must be a number, not {type(v).__name__}")
        return float(v)

    if kind == "number":
        return number(value, key)
    if kind == "numbers3":
        if not isinstance(value, (list, tuple)) or len(value) != 3:
            raise TypeError(f"{key} must be three numbers (x, y, z), not {value!r}")
        return [number(v, f"{key}[{i}]") for i, v in enumerate(value)]
    if kind == "bool":
        if not isinstance(value, bool):
            raise TypeError(f"{key} must be True or False, not {type(value).__name__}")
        return value
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise TypeError(f"{key} must be an integer, not {type(value).__name__}")
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise TypeError(f"{key} must be a string, not {type(value).__name__}")
        return value
    return value


def _finite(value: Any, name: str) -> Any:
    """``value`` with every number in it checked finite (JSON, which carries
    the parameters to the core, has no NaN or infinity)."""
    if isinstance(value, (list, tuple)):
        return [_finite(v, f"{name}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value}")
    return value


def _json(config: Dict[str, Any]) -> str:
    return json.dumps(config, allow_nan=False)


def _config(sensor: _Sensor, voxel_size_m: float, params: Dict[str, Any]) -> Dict[str, Any]:
    if not isinstance(sensor, _Sensor):
        raise TypeError("sensor must be edtmap.DepthCamera, SpinningLidar, PointSensor or PlanarLidar, "
                        f"not {type(sensor).__name__}")
    try:
        voxel = float(voxel_size_m)
    except (TypeError, ValueError):
        raise TypeError(f"voxel_size_m must be a number (metres), not {type(voxel_size_m).__name__}") from None
    section = {k: _finite(v, f"{type(sensor).__name__} {k}") for k, v in sensor.section().items()}
    config: Dict[str, Any] = {"sensor": section, "occupancy": {"voxel_size_m": _finite(voxel, "voxel_size_m")}}
    for key, value in params.items():
        if key == "max_memory":
            config.setdefault("memory", {})["max"] = str(value)
            continue
        section = next((s for s, keys in _SECTIONS.items() if key in keys), None)
        if section is None:
            known = sorted(k for keys in _SECTIONS.values() for k in keys) + ["max_memory"]
            raise TypeError(f"Mapper() got an unknown parameter {key!r}; known: {', '.join(known)}")
        config.setdefault(section, {})[key] = _finite(_typed(key, value), key)
    return config


def _pose(t_world_sensor) -> list:
    """A pose as the core takes it: 16 row-major values of a 4 x 4 rigid
    transform, or ``[x, y, z, qx, qy, qz, qw]``."""
    try:
        a = np.asarray(t_world_sensor, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise TypeError(f"t_world_sensor must be a 4 x 4 array or [x, y, z, qx, qy, qz, qw]: {e}") from None
    if a.shape == (4, 4) or a.shape == (7,):
        return a.ravel().tolist()
    raise ValueError(f"t_world_sensor must have shape (4, 4) or (7,), not {a.shape}")


def _stamp(stamp) -> float:
    s = float(stamp)
    if not math.isfinite(s):
        raise ValueError(f"stamp must be finite, got {s}")
    return s


def _float_array(a, name: str, ndim: int, dtype) -> np.ndarray:
    arr = np.asarray(a)
    if arr.dtype.kind not in "fiu":
        raise TypeError(f"{name} must hold numbers, not {arr.dtype}")
    if arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimensions, not shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape})")
    return np.ascontiguousarray(arr, dtype=dtype)


class Mapper:
    """An occupancy map and an exact global EDT, built frame by frame.

    ``Mapper(sensor, voxel_size_m, **params)`` with a sensor model
    (:class:`DepthCamera`, :class:`SpinningLidar`, :class:`PointSensor`,
    :class:`PlanarLidar`) and any field of the configuration file's
    ``[occupancy]`` (``local_size_m``, ``fixed_height_m``, ``prob_hit``, ...),
    ``[edt]`` (``unknown_as_occupied``), ``[global]`` (``max_distance_m``,
    ``connectivity``, ``mode``, ``forbidden``, ``planar``) and ``[sensor]``
    (``construction``, ``clear_no_return``, ...) sections, plus
    ``max_memory`` (``"4GiB"``). Or :meth:`from_config` with a TOML file.
    ``backend``: ``"cpu"``, ``"gpu"`` (in a build with the ``gpu``
    feature) or ``"auto"`` (a hardware GPU where there is one, else the
    CPU); every backend gives the same map, bit for bit. A planar map
    (``planar=True``: distances within each horizontal layer) runs on the
    CPU (``"auto"`` picks it).

    Poses are ``T_world_sensor``: a 4 x 4 rigid transform, or
    ``[x, y, z, qx, qy, qz, qw]``. Integration and queries release the GIL;
    queries from any thread read the map as it was after the last frame.
    """

    def __init__(self, sensor: _Sensor, voxel_size_m: float, backend: str = "cpu", **params: Any):
        config = _config(sensor, voxel_size_m, params)
        self._config = config
        self._core = _edtmap.Mapper.from_config_json(_json(config), "edtmap.Mapper(...)", backend)

    @classmethod
    def _wrap(cls, core, config: Optional[Dict[str, Any]]) -> "Mapper":
        mapper = cls.__new__(cls)
        mapper._core = core
        mapper._config = config
        return mapper

    @classmethod
    def from_config(cls, path: PathLike, backend: str = "cpu") -> "Mapper":
        """A mapper from a TOML configuration file (as ``edtmap run --config``)."""
        return cls._wrap(_edtmap.Mapper.from_config_file(os.fspath(path), backend), None)

    @classmethod
    def load(cls, path: PathLike, sensor: Optional[_Sensor] = None, backend: str = "cpu",
             **params: Any) -> "Mapper":
        """A mapper that goes on from a saved map (``map.edtmap``). The map's
        voxel size, probabilities and global EDT parameters are kept; the
        sensor (default :class:`PointSensor`) and ``params`` are for the
        frames integrated from now on."""
        config = _config(sensor if sensor is not None else PointSensor(), 1.0, params)
        core = _edtmap.Mapper.load(os.fspath(path), _json(config), "edtmap.Mapper.load(...)", backend)
        return cls._wrap(core, config)

    @property
    def backend(self) -> str:
        """What the mapper runs on: ``cpu (N threads)`` or the GPU's name."""
        return self._core.backend

    @property
    def voxel_size_m(self) -> float:
        """Voxel edge length, metres."""
        return self._core.voxel_size_m

    @property
    def max_distance_m(self) -> float:
        """The global EDT's cutoff, metres: distances saturate there."""
        return self._core.max_distance_m

    @property
    def sensor_kind(self) -> str:
        """``depth``, ``lidar``, ``points`` or ``planar``."""
        return self._core.sensor_kind

    @property
    def sensors(self) -> list:
        """The sensors frames may name, in the order they were added:
        ``(name, kind)`` pairs. The first is the mapper's own sensor, named
        after its kind (or its config's ``name``)."""
        return list(self._core.sensors)

    def add_sensor(self, name: str, sensor: _Sensor, **options: Any) -> int:
        """Adds a sensor whose frames go into the same map: ``name`` (what
        the ``sensor=`` keyword of the ``integrate_*`` methods takes), a
        sensor model and its ``[sensor]`` options (``construction``,
        ``clear_no_return``, ``free_margin_m``, ``planar_half_thickness_m``).
        Returns its index. Frames of every sensor are fused in the order
        they are integrated, each with its own pose."""
        if not isinstance(name, str):
            raise TypeError(f"name must be a string, not {type(name).__name__}")
        if not isinstance(sensor, _Sensor):
            raise TypeError("sensor must be edtmap.DepthCamera, SpinningLidar, PointSensor or PlanarLidar, "
                            f"not {type(sensor).__name__}")
        section = {k: _finite(v, f"{type(sensor).__name__} {k}") for k, v in sensor.section().items()}
        for key, value in options.items():
            if key not in _SECTIONS["sensor"]:
                raise TypeError(f"add_sensor() got an unknown option {key!r}; known: {', '.join(_SECTIONS['sensor'])}")
            section[key] = _finite(_typed(key, value), key)
        return self._core.add_sensor(name, _json(section), f"edtmap.Mapper.add_sensor({name!r})")

    def _sensor(self, sensor: Optional[str]) -> int:
        """The index of the sensor named ``sensor`` (``None``: the first)."""
        if sensor is None:
            return 0
        names = [name for name, _ in self._core.sensors]
        if not isinstance(sensor, str):
            raise TypeError(f"sensor must be a sensor's name (a string), not {type(sensor).__name__}")
        if sensor not in names:
            raise ValueError(f"sensor {sensor!r}: the mapper's sensors are {', '.join(names)}")
        return names.index(sensor)

    @property
    def map_blocks(self) -> int:
        """Blocks (8³ voxels) of the map's layers."""
        return self._core.map_blocks

    def integrate_depth(self, depth, t_world_sensor, stamp: float = 0.0,
                        depth_scale: float = 0.001, sensor: Optional[str] = None) -> Dict[str, Any]:
        """Adds a depth image: H x W float metres (NaN, inf or 0: no
        return), or uint16 raw values of ``depth_scale`` metres each (0: no
        return). Returns the frame's statistics. ``sensor``: the name of
        the sensor it came from (default: the first; see
        :meth:`add_sensor`), as for every ``integrate_*`` method."""
        arr = np.asarray(depth)
        pose, stamp, index = _pose(t_world_sensor), _stamp(stamp), self._sensor(sensor)
        if arr.dtype.kind == "u" and arr.dtype.itemsize == 2:
            # Byte-swapped raw depth (">u2", as some PNG readers give) is
            # converted to native order.
            arr = _float_array(arr, "depth", 2, np.uint16)
            return self._core.integrate_depth_u16(arr, float(depth_scale), pose, stamp, index)
        if arr.dtype.kind != "f":
            raise TypeError(f"depth must be float (metres) or uint16 (raw, either byte order), not {arr.dtype}")
        return self._core.integrate_depth_m(_float_array(arr, "depth", 2, np.float32), pose, stamp, index)

    def integrate_points(self, points, t_world_sensor, stamp: float = 0.0,
                         sensor: Optional[str] = None) -> Dict[str, Any]:
        """Adds a point cloud: N x 3 points in the sensor frame, metres
        (float32 or float64; non-finite points are no return)."""
        arr = _float_array(points, "points", 2, np.float32)
        if arr.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), not {arr.shape}")
        return self._core.integrate_points(arr, _pose(t_world_sensor), _stamp(stamp), self._sensor(sensor))

    def integrate_scan(self, ranges, angle_min: float, angle_increment: float, t_world_sensor,
                       stamp: float = 0.0, range_limits: Optional[Tuple[float, float]] = None,
                       sensor: Optional[str] = None) -> Dict[str, Any]:
        """Adds a planar scan: ``ranges`` in metres, beam ``i`` at angle
        ``angle_min + i * angle_increment`` (radians) in the sensor's x-y
        plane; ``range_limits`` (min, max) default to the sensor's."""
        arr = _float_array(ranges, "ranges", 1, np.float32)
        limits = None if range_limits is None else (float(range_limits[0]), float(range_limits[1]))
        return self._core.integrate_scan(arr, float(angle_min), float(angle_increment),
                                         _pose(t_world_sensor), _stamp(stamp), limits, self._sensor(sensor))

    def integrate_range_image(self, ranges, t_world_sensor, stamp: float = 0.0,
                              sensor: Optional[str] = None) -> Dict[str, Any]:
        """Adds a spinning LiDAR's range image: rings x azimuth bins, metres
        (bin ``b`` centred on azimuth ``-pi + (b + 0.5) * 2 pi / bins``)."""
        arr = _float_array(ranges, "ranges", 2, np.float32)
        return self._core.integrate_range_image(arr, _pose(t_world_sensor), _stamp(stamp), self._sensor(sensor))

    def integrate(self, frame: Dict[str, Any]) -> Dict[str, Any]:
        """Adds a frame of :func:`read_recording`, exactly as ``edtmap run``
        would (its ``pose`` is used bit for bit); a ``sensor`` entry names
        the sensor it came from."""
        kind, pose, stamp, sensor = frame["kind"], frame["pose"], frame["stamp"], frame.get("sensor")
        if kind == "depth":
            return self.integrate_depth(frame["depth"], pose, stamp, frame.get("depth_scale", 0.001), sensor)
        if kind == "points":
            return self.integrate_points(frame["points"], pose, stamp, sensor)
        if kind == "lidar":
            return self.integrate_range_image(frame["ranges"], pose, stamp, sensor)
        if kind == "planar":
            return self.integrate_scan(frame["ranges"], frame["angle_min"], frame["angle_increment"], pose,
                                       stamp, frame.get("range_limits"), sensor)
        raise ValueError(f"frame kind {kind!r} is not depth, points, lidar or planar")

    def distance(self, points, signed: bool = False) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distance to the nearest obstacle at N world points (metres),
        trilinear between voxel centres, with its gradient and each point's
        state. Returns ``(distance (N,), gradient (N, 3), state (N,) uint8)``;
        states are 0 outside the mapped blocks, 1 unknown, 2 free, 3
        occupied. Distances saturate at :attr:`max_distance_m`; a point that
        is not finite gets NaN. ``signed``: negative inside obstacle voxels."""
        return self._core.distance(self._points(points), bool(signed))

    def state(self, points) -> np.ndarray:
        """State code (uint8, see :meth:`distance`) of N world points."""
        return self._core.state(self._points(points))

    def export_box(self, min_m, max_m, signed: bool = False) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every voxel overlapping the box ``[min_m, max_m)``: distances
        (float32, metres) and state codes, both indexed ``[ix, iy, iz]``,
        and ``origin_m``, the centre of element ``[0, 0, 0]``."""
        lo = [float(v) for v in np.asarray(min_m, dtype=np.float64).ravel()]
        hi = [float(v) for v in np.asarray(max_m, dtype=np.float64).ravel()]
        if len(lo) != 3 or len(hi) != 3:
            raise ValueError("min_m and max_m must have 3 values each")
        dist, state, origin = self._core.export_box(lo, hi, bool(signed))
        return dist.T, state.T, (np.asarray(origin, dtype=np.float64) + 0.5) * self.voxel_size_m

    def local_edt(self) -> Optional[Dict[str, np.ndarray]]:
        """The exact EDT of the local volume around the last frame's sensor:
        ``distance_m`` (float32, ``inf`` with no obstacle in the volume),
        ``states`` (codes of :meth:`distance`), both indexed ``[ix, iy,
        iz]``, and ``origin_m``, the centre of element ``[0, 0, 0]``.
        ``None`` before the first frame."""
        local = self._core.local_edt()
        if local is None:
            return None
        dist_sq, states, origin = local
        dist = np.sqrt(dist_sq.astype(np.float64)) * self.voxel_size_m
        dist[dist_sq == np.iinfo(np.uint32).max] = np.inf
        return {"distance_m": dist.astype(np.float32).T, "states": states.T,
                "origin_m": (np.asarray(origin, dtype=np.float64) + 0.5) * self.voxel_size_m}

    def frontiers(self) -> np.ndarray:
        """Exploration frontiers (observed free voxels beside unknown ones):
        their centres, K x 3 metres."""
        cells = self._core.frontiers()
        return (cells.astype(np.float64) + 0.5) * self.voxel_size_m

    def save(self, path: PathLike) -> None:
        """Writes the whole map (atomically) for ``edtmap query`` or
        :meth:`load`."""
        self._core.save(os.fspath(path))

    def _points(self, points) -> np.ndarray:
        arr = np.asarray(points)
        if arr.dtype.kind not in "fiu":
            raise TypeError(f"points must hold numbers, not {arr.dtype}")
        if arr.ndim == 1 and arr.shape == (3,):
            arr = arr[None, :]
        if arr.ndim != 2 or arr.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), not {arr.shape}")
        return np.ascontiguousarray(arr, dtype=np.float64)


class Recording:
    """The frames of a recording, read a few frames ahead by a thread.
    Iterate over it for frame dicts; :meth:`mapper` makes the mapper
    ``edtmap run`` would."""

    def __init__(self, core):
        self._core = core

    def __len__(self) -> int:
        return len(self._core)

    def __iter__(self) -> Iterator[Dict[str, Any]]:
        return iter(self._core)

    @property
    def kind(self) -> str:
        """``depth``, ``lidar``, ``points`` or ``planar``."""
        return self._core.kind

    @property
    def skipped(self) -> list:
        """Messages of the frames skipped so far (``[dataset] on_error``)."""
        return self._core.skipped

    def mapper(self, backend: str = "cpu") -> Mapper:
        """A mapper for this recording's configuration, the recording's
        camera calibration applied as ``edtmap run --dataset`` does."""
        return Mapper._wrap(self._core.mapper(backend), None)


def read_recording(path: PathLike, config: PathLike, frames: Optional[int] = None) -> Recording:
    """Opens any recording edtmap reads (a ROS 1 bag, a ROS 2 MCAP file, a
    folder of depth images or point clouds) with a TOML configuration whose
    ``[dataset]`` section says how (topics, poses, extrinsics, depth scale).

    Iterating gives one dict per frame: ``kind``, ``stamp`` (seconds),
    ``t_world_sensor`` (4 x 4), ``pose`` (``[x, y, z, qx, qy, qz, qw]``) and
    the data: ``depth`` (H x W float32 metres, or uint16 with
    ``depth_scale``), ``points`` (N x 3 float32), ``ranges`` (a LiDAR's rings
    x bins, or a planar scan's beams with ``angle_min``,
    ``angle_increment`` and ``range_limits``), and ``sensor``, the name of
    the config's sensor it came from (a ROS recording replays every
    ``[[sensors]]`` entry from its ``topic``). Bad frames are skipped
    (listed in ``skipped``) or raise ``ValueError``, as ``[dataset]
    on_error`` says.
    """
    return Recording(_edtmap.Recording(os.fspath(path), os.fspath(config), frames))
