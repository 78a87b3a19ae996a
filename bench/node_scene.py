"""The scene and node configuration that bench/node_fastdds.py and
bench/node_cyclonedds.py share (no DDS import here: each script runs in the
virtual environment of its own DDS binding).

configs/ros2_lidar.toml's mapping (0.2 m voxels, 40 x 40 x 8 m window, 2 m
cutoff) of a LiDAR circling at 4 m inside a 12 m cylindrical wall with eight
pillars, one lap in 40 s, with the sensor frame's axes the world's.
"""
import math
import statistics
import struct
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def config(band, poses):
    """configs/ros2_lidar.toml with a [ros] section that publishes every
    output after every frame, the ESDF cloud within heights `band`, poses
    from the [ros] lines `poses`, on loopback only."""
    text = (ROOT / "configs" / "ros2_lidar.toml").read_text()
    return text[:text.index("[ros]")] + f"""[ros]
sensor_topic = "/points"
{poses}
localhost_only = true
esdf_pointcloud_hz = 1000.0
esdf_pointcloud_z_m = [{band[0]}, {band[1]}]
occupied_pointcloud_hz = 1000.0
slice_hz = 1000.0
slice_height_m = 1.0
pose_wait_s = 0.5
map_clearing_radius_m = 60.0
"""


def world_points():
    """The wall (radius 12 m) and eight pillars (radius 0.5 m at 8 m), 0.1 m apart, -1 to 5 m high."""
    pts = []
    heights = [-1.0 + 0.1 * k for k in range(60)]
    for i in range(760):
        a = 2 * math.pi * i / 760
        pts += [(12.0 * math.cos(a), 12.0 * math.sin(a), z) for z in heights]
    for p in range(8):
        cx, cy = 8.0 * math.cos(p * math.pi / 4), 8.0 * math.sin(p * math.pi / 4)
        for i in range(32):
            a = 2 * math.pi * i / 32
            pts += [(cx + 0.5 * math.cos(a), cy + 0.5 * math.sin(a), z) for z in heights]
    return pts


def sensor_at(k, hz):
    """The sensor's position at frame `k` of frames at `hz`: a circle of
    radius 4 m, one lap in 40 s."""
    a = 2 * math.pi * k / (hz * 40.0)
    return (4.0 * math.cos(a), 4.0 * math.sin(a), 0.0)


def cloud_bytes(points, at):
    """The points as seen from `at`, packed as float32 x, y, z."""
    return struct.pack(f"<{3 * len(points)}f", *(c for x, y, z in points for c in (x - at[0], y - at[1], z - at[2])))


def latency_ms(delays_s):
    """Median and 95th percentile of delays in seconds, in milliseconds
    (None and None when there are none)."""
    lat = sorted(d * 1e3 for d in delays_s)
    if not lat:
        return None, None
    return round(statistics.median(lat), 1), round(lat[int(0.95 * (len(lat) - 1))], 1)
