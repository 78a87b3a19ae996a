"""Plan a collision-free path through a saved edtmap map, CHOMP-style.

    python python/examples/plan_path.py edtmap-out/map.edtmap --out path.png

Loads the map (`edtmap demo` saves one to edtmap-out/map.edtmap), picks a
start and a goal (or takes --start/--goal), and bends the straight line
between them away from obstacles by gradient descent on an obstacle cost
computed from `Mapper.distance` (signed distances and their gradients)
plus a smoothness cost, with CHOMP's covariant update (Ratliff et al.,
2009). It prints the path's clearance before and after and draws the path
on the distance slice at the path's height as a PNG. It exits 1 if the
path it found still touches an obstacle.
"""

from __future__ import annotations

import argparse
import struct
import sys
import zlib

import numpy as np

import edtmap


def obstacle_cost(d: np.ndarray, eps: float):
    """CHOMP's obstacle cost of signed distances ``d`` and its derivative."""
    cost = np.where(d < 0, -d + eps / 2, np.where(d <= eps, (eps - d) ** 2 / (2 * eps), 0.0))
    slope = np.where(d < 0, -1.0, np.where(d <= eps, (d - eps) / eps, 0.0))
    return cost, slope


def clearance(mapper: edtmap.Mapper, path: np.ndarray, step: float) -> float:
    """Least distance to an obstacle along the polyline, sampled every ``step``."""
    samples = [path[0:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(int(np.ceil(np.linalg.norm(b - a) / step)), 1)
        samples.append(a + (b - a) * (np.arange(1, n + 1)[:, None] / n))
    d, _, _ = mapper.distance(np.concatenate(samples), signed=True)
    return float(np.min(d))


def plan(mapper: edtmap.Mapper, start, goal, waypoints: int, eps: float, iterations: int,
         smoothness: float, step: float) -> np.ndarray:
    """The straight line from ``start`` to ``goal`` bent away from obstacles;
    in the horizontal plane when both ends are at one height."""
    n = waypoints
    path = np.linspace(start, goal, n + 2)
    planar = abs(start[2] - goal[2]) < mapper.voxel_size_m
    # Finite differences of the inner waypoints; A = K^T K is the
    # smoothness metric, b brings in the fixed ends.
    k = np.eye(n + 1, n, k=0) - np.eye(n + 1, n, k=-1)
    a = k.T @ k
    a_inv = np.linalg.inv(a)
    e = np.zeros((n + 1, 3))
    e[0], e[-1] = -path[0], path[-1]
    b = k.T @ e
    for _ in range(iterations):
        inner = path[1:-1]
        d, grad, _ = mapper.distance(inner, signed=True)
        _, slope = obstacle_cost(d, eps)
        g_obs = slope[:, None] * grad
        if planar:
            # Ends at one height: stay in that plane (the map holds no
            # ground below or ceiling above it that the sensor has seen).
            g_obs[:, 2] = 0.0
        g_smooth = a @ inner + b
        g = g_obs + smoothness * g_smooth
        path[1:-1] = inner - step * (a_inv @ g)
    return path


def write_png(path: str, rgb: np.ndarray) -> None:
    """An 8-bit RGB PNG, written without any imaging library."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].astype(np.uint8).tobytes() for y in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


def draw(mapper: edtmap.Mapper, before: np.ndarray, after: np.ndarray, out: str, scale: int = 4) -> None:
    """The distance slice at the path's height, the straight line in blue and
    the planned path in red."""
    vs = mapper.voxel_size_m
    z = float(after[0, 2])
    lo = np.minimum(before.min(axis=0), after.min(axis=0))[:2] - 3.0
    hi = np.maximum(before.max(axis=0), after.max(axis=0))[:2] + 3.0
    dist, states, origin = mapper.export_box([lo[0], lo[1], z], [hi[0], hi[1], z + vs / 2])
    d = dist[:, :, 0].T[::-1]  # rows: y from top to bottom
    s = states[:, :, 0].T[::-1]
    shade = np.clip(d / mapper.max_distance_m, 0, 1)
    rgb = np.stack([shade * 255, shade * 230 + 25, shade * 120 + 60], axis=-1)
    rgb[s == 3] = [0, 0, 0]
    rgb[(s == 0) | (s == 1)] = [150, 150, 150]
    rgb = np.kron(rgb, np.ones((scale, scale, 1)))
    height = rgb.shape[0]

    def plot(p, colour):
        for a, b in zip(p[:-1], p[1:]):
            for t in np.linspace(0, 1, 60):
                x, y = (a + (b - a) * t)[:2]
                col = int((x - origin[0] + vs / 2) / vs * scale)
                row = height - 1 - int((y - origin[1] + vs / 2) / vs * scale)
                if 0 <= row < rgb.shape[0] and 0 <= col < rgb.shape[1]:
                    rgb[max(row - 1, 0):row + 1, max(col - 1, 0):col + 1] = colour

    plot(before, [40, 90, 255])
    plot(after, [230, 20, 20])
    write_png(out, rgb)


def pick_ends(mapper: edtmap.Mapper, z: float, need: float):
    """Two free points at height ``z`` with ``need`` clearance, far apart
    along x, on opposite sides of the mapped area."""
    dist, states, origin = mapper.export_box([-200, -200, z], [200, 200, z + mapper.voxel_size_m / 2])
    ok = np.argwhere((states[:, :, 0] == 2) & (dist[:, :, 0] >= need))
    if len(ok) < 2:
        raise SystemExit(f"no free voxel with {need} m clearance at z = {z} m: give --start and --goal")
    ends = ok[[np.argmin(ok[:, 0]), np.argmax(ok[:, 0])]]
    return [origin + np.array([i, j, 0]) * mapper.voxel_size_m for i, j in ends]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("map", help="a map saved by edtmap (edtmap demo writes edtmap-out/map.edtmap)")
    parser.add_argument("--start", type=float, nargs=3, metavar=("X", "Y", "Z"))
    parser.add_argument("--goal", type=float, nargs=3, metavar=("X", "Y", "Z"))
    parser.add_argument("--height", type=float, default=1.5, help="height of the picked ends (m)")
    parser.add_argument("--margin", type=float, default=0.6, help="clearance the cost asks for (m)")
    parser.add_argument("--waypoints", type=int, default=150)
    parser.add_argument("--iterations", type=int, default=300)
    parser.add_argument("--step", type=float, default=0.01, help="gradient step")
    parser.add_argument("--smoothness", type=float, default=0.2, help="weight of the smoothness cost")
    parser.add_argument("--out", default="path.png", help="picture of the path (PNG)")
    args = parser.parse_args(argv)

    mapper = edtmap.Mapper.load(args.map)
    if args.start is None or args.goal is None:
        start, goal = pick_ends(mapper, args.height, args.margin)
    else:
        start, goal = np.array(args.start), np.array(args.goal)
    straight = np.linspace(start, goal, args.waypoints + 2)
    step = mapper.voxel_size_m / 2
    before = clearance(mapper, straight, step)
    path = plan(mapper, start, goal, args.waypoints, args.margin, args.iterations, args.smoothness, args.step)
    after = clearance(mapper, path, step)
    length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    print(f"start {np.round(start, 2).tolist()} goal {np.round(goal, 2).tolist()}")
    print(f"straight line: {np.linalg.norm(goal - start):.2f} m, clearance {before:.3f} m")
    observed = float(np.mean(mapper.state(path) == 2))
    print(f"planned path:  {length:.2f} m, clearance {after:.3f} m, {observed:.0%} of waypoints in observed free space")
    draw(mapper, straight, path, args.out)
    print(f"wrote {args.out}")
    if after <= 0:
        print("the planned path still touches an obstacle: raise --iterations or --margin", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
