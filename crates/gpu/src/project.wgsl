// Volumetric projection (paper §IV-A), dispatched by project.rs: one
// invocation per word of sixteen voxels, two bits each (each owns its word:
// no atomics but the uncertain voxels' list)
// decides edtmap_core::ProjectJob::is_miss in f32 together with a bound on
// how far each quantity it thresholds can be from the CPU's value. A voxel
// is written NOT_MISS or MISS only when every threshold is farther than
// SLACK times that bound; otherwise UNCERTAIN, and the host decides it.
//
// Error model (u = 2^-24, the f32 unit roundoff; "ulp" = 2u relative):
// add, sub, mul are correctly rounded (error <= u |result|), a fused
// multiply-add rounds once (never worse than unfused), division is within
// 2.5 ulp (5u), sqrt within ~4.5 ulp (inverseSqrt then a division). The CPU
// computes the point in f64 (its error, from the host, is P.err.x) and
// rounds it to f32 (u |p|), then evaluates the sensor model in correctly
// rounded f32.

const GROUP: u32 = 64u;
const U: f32 = 5.9604645e-8;
// Every bound below is multiplied by SLACK before it is compared.
const SLACK: f32 = 10.0;
const NOT_MISS: u32 = 0u;
const MISS: u32 = 1u;
const UNCERTAIN: u32 = 2u;
const KIND_DEPTH: i32 = 0;
const KIND_LIDAR: i32 = 2;
const PI: f32 = 3.14159265358979;
const TAU: f32 = 6.28318530717959;
// Error of atan2_acc against the exact atan2 of its (f32) arguments, rad;
// see there (the analysis gives 27u = 1.6e-6).
const ANGLE_ERR: f32 = 4e-6;

struct Params {
    // Volume dims and voxel count.
    dims: vec4<u32>,
    // Integer part n of (o / s - 1/2) per axis (o: sensor origin from the
    // volume's corner), and the kind (0 depth, 1 planar, 2 LiDAR).
    base: vec4<i32>,
    // Fraction f = o / s - 1/2 - n per axis (|f| <= 1/2) and the voxel size.
    frac: vec4<f32>,
    // Rows of the rotation sensor <- world (w unused).
    rot0: vec4<f32>,
    rot1: vec4<f32>,
    rot2: vec4<f32>,
    // Pinhole fx, fy, cx, cy (f32, as the CPU casts them).
    cam: vec4<f32>,
    // Image width and height, beams of a scan.
    img: vec4<u32>,
    // Scan: angle_min mod 2 pi, sign of the increment, |increment|, planar
    // half thickness.
    scan: vec4<f32>,
    // Beam indices the CPU wraps to 0 (lo..=hi).
    wrap: vec4<i32>,
    // Bounds on the CPU's f64 errors: x on the point, m; y on the scan
    // angle relative to angle_min (and the host's reduction mod 2 pi), rad.
    err: vec4<f32>,
    // LiDAR: azimuth bins, rings, and where in `free_below` the ring
    // elevations (rings words) and the rings' elevation bounds (rings + 1
    // words: ring k is nearest on [bound k, bound k + 1)) start.
    lidar: vec4<u32>,
}

@group(0) @binding(0) var<uniform> P: Params;
// Per pixel or beam: the range below which a point is free
// (ProjectJob::free_below_m, computed on the host), f32::MIN for never;
// for a LiDAR (beam ring * bins + bin), then its rings and ring bounds.
@group(0) @binding(1) var<storage, read> free_below: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<u32>;
// [0]: how many voxels were left uncertain; from [1]: their linear indices,
// in no particular order (for a host that keeps the codes on the device and
// decides only these).
@group(0) @binding(3) var<storage, read_write> uncertain: array<atomic<u32>>;

fn merge(a: u32, b: u32) -> u32 {
    return select(UNCERTAIN, a, a == b);
}

// `value < threshold`, or UNCERTAIN when they are within `margin`. The
// threshold is finite (f32::MIN for never), so the difference is too.
fn compare(value: f32, threshold: f32, margin: f32) -> u32 {
    if (abs(value - threshold) <= margin) {
        return UNCERTAIN;
    }
    return select(NOT_MISS, MISS, value < threshold);
}

// One pixel candidate: outside the image is unseen (not a miss).
fn pixel(u: f32, v: f32, depth: f32, margin: f32) -> u32 {
    if (u < 0.0 || v < 0.0 || u >= f32(P.img.x) || v >= f32(P.img.y)) {
        return NOT_MISS;
    }
    return compare(depth, free_below[u32(u) + P.img.x * u32(v)], margin);
}

// PinholeCamera::project, then the depth test. With ep the bound on
// |p_gpu - p_cpu| per coordinate and pz > 2 ep, the exact pixel coordinate
// u = fx px / pz + cx + 1/2 moves by at most 2 fx ep (1 + |px / pz|) / pz
// between the two points; the CPU's four roundings of it and the GPU's
// (its division 5u) add at most u (11 |fx px / pz| + 4 |cx| + 3). Within
// SLACK times that of an integer the pixel is either of two: both
// candidates of both axes are decided, and must agree. Whatever the
// margin, an interval wholly outside the image is unseen.
fn depth(p: vec3<f32>, ep: f32) -> u32 {
    let mz = SLACK * ep;
    if (p.z <= mz) {
        return select(UNCERTAIN, NOT_MISS, p.z < -mz);
    }
    let fq = P.cam.x * p.x / p.z;
    let fr = P.cam.y * p.y / p.z;
    let uu = fq + P.cam.z + 0.5;
    let vv = fr + P.cam.w + 0.5;
    let mu = SLACK * (2.0 * ep * (P.cam.x + abs(fq)) / p.z + U * (11.0 * abs(fq) + 4.0 * abs(P.cam.z) + 3.0));
    let mv = SLACK * (2.0 * ep * (P.cam.y + abs(fr)) / p.z + U * (11.0 * abs(fr) + 4.0 * abs(P.cam.w) + 3.0));
    // Wholly outside the image (often so near the camera plane, where the
    // margins are wide).
    if (uu + mu < 0.0 || vv + mv < 0.0 || uu - mu >= f32(P.img.x) || vv - mv >= f32(P.img.y)) {
        return NOT_MISS;
    }
    if (mu >= 0.5 || mv >= 0.5) {
        return UNCERTAIN;
    }
    let u0 = floor(uu - mu);
    let u1 = floor(uu + mu);
    let v0 = floor(vv - mv);
    let v1 = floor(vv + mv);
    var r = pixel(u0, v0, p.z, mz);
    r = merge(r, pixel(u1, v0, p.z, mz));
    r = merge(r, pixel(u0, v1, p.z, mz));
    return merge(r, pixel(u1, v1, p.z, mz));
}

// atan2 with a proven error bound (ANGLE_ERR), as the builtin's (4096 ulp)
// is too loose. Octant reduction to a = min / max in [0, 1] (5u, and atan
// is 1-Lipschitz), then to |t| <= tan(pi/8) + 1e-7 < 0.4143 by
// atan(a) = pi/4 + atan((a - 1) / (a + 1)) (<= 7u |t| <= 3u). The Taylor
// series to t^15 alternates with decreasing terms, so its truncation error
// is below |t|^17 / 17 < 1.9e-8 (0.32u); Horner in f32 adds at most 16u
// times sum |t|^k / k <= 7u. Undoing the reduction (pi/4 +, pi/2 -, pi -,
// with the constants' own rounding) adds at most 2u + 3.2u + 6.3u. Total
// 27u = 1.6e-6 rad < ANGLE_ERR. Needs max(|x|, |y|) > 0.
fn atan2_acc(y: f32, x: f32) -> f32 {
    let ax = abs(x);
    let ay = abs(y);
    let a = min(ax, ay) / max(ax, ay);
    var t = a;
    var base = 0.0;
    if (a > 0.41421357) {
        t = (a - 1.0) / (a + 1.0);
        base = PI / 4.0;
    }
    let t2 = t * t;
    var s = -1.0 / 15.0;
    s = 1.0 / 13.0 + t2 * s;
    s = -1.0 / 11.0 + t2 * s;
    s = 1.0 / 9.0 + t2 * s;
    s = -1.0 / 7.0 + t2 * s;
    s = 1.0 / 5.0 + t2 * s;
    s = -1.0 / 3.0 + t2 * s;
    var ang = base + (t + t * t2 * s);
    if (ay > ax) {
        ang = PI / 2.0 - ang;
    }
    if (x < 0.0) {
        ang = PI - ang;
    }
    if (y < 0.0) {
        ang = -ang;
    }
    return ang;
}

// One beam candidate of LaserScan::beam (i = floor(rel + 1/2), wrapped).
fn beam(fi: f32, range: f32, margin: f32) -> u32 {
    var i = i32(fi);
    if (i >= P.wrap.x && i <= P.wrap.y) {
        i = 0;
    }
    if (i < 0 || u32(i) >= P.img.z) {
        return NOT_MISS;
    }
    return compare(range, free_below[u32(i)], margin);
}

// The plane test, LaserScan::beam, then the range test. The scan's angle
// relative to angle_min, taken mod 2 pi (as the CPU takes rel mod
// 2 pi / |inc|), is off by at most ANGLE_ERR, plus 2 (1.5 ep) / r from the
// point's error (r > 4 ep), plus 15 pi u for reducing it (angle_min mod
// 2 pi and up to two turns, each rounded, with 2 pi's own rounding), plus
// the host's error; divided by |inc|, and the division (5u) and + 1/2 add
// u (6 rel + 1). Near the wrap (rel near 0 or near 2 pi / |inc|) both
// sides give beam 0, so the wrap needs no margin. The range sqrt(x² + y²)
// differs by at most 1.5 ep (it is 1-Lipschitz) + 15u r (the CPU's three
// roundings, the GPU's square root).
fn planar(p: vec3<f32>, ep: f32) -> u32 {
    let mz = SLACK * ep;
    let h = P.scan.w;
    if (abs(abs(p.z) - h) <= mz) {
        return UNCERTAIN;
    }
    if (abs(p.z) > h) {
        return NOT_MISS;
    }
    let r = sqrt(p.x * p.x + p.y * p.y);
    if (r <= 4.0 * ep) {
        return UNCERTAIN;
    }
    var delta = P.scan.y * (atan2_acc(p.y, p.x) - P.scan.x);
    if (delta < 0.0) {
        delta += TAU;
    }
    if (delta < 0.0) {
        delta += TAU;
    }
    if (delta >= TAU) {
        delta -= TAU;
    }
    let rel = delta / P.scan.z;
    let ma = SLACK * ((ANGLE_ERR + 3.0 * ep / r + 15.0 * PI * U + P.err.y) / P.scan.z + U * (6.0 * rel + 1.0));
    if (ma >= 0.5) {
        return UNCERTAIN;
    }
    let k = rel + 0.5;
    let mr = SLACK * (1.5 * ep + 15.0 * U * r);
    return merge(beam(floor(k - ma), r, mr), beam(floor(k + ma), r, mr));
}

// Three-valued AND: NOT_MISS if either is, MISS if both are.
fn both(a: u32, b: u32) -> u32 {
    if (a == NOT_MISS || b == NOT_MISS) {
        return NOT_MISS;
    }
    return select(UNCERTAIN, MISS, a == MISS && b == MISS);
}

// The ring SpinningLidar::nearest_ring gives elevation x (binary search of
// the bounds), or `rings` for none (outside the fan).
fn ring_at(x: f32) -> u32 {
    let n = P.lidar.y;
    var lo = 0u;
    var hi = n + 1u;
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (free_below[P.lidar.w + mid] <= x) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    // lo bounds lie at or below x.
    if (lo == 0u || lo > n) {
        return n;
    }
    return lo - 1u;
}

// One (ring, bin) candidate: the range test, then whether the ring passes
// within half a voxel (SpinningLidar::ring_passes_at: |ring - el| <=
// asin(radius / r)); `mring` bounds that comparison's error.
fn lidar_beam(ring: u32, bin: u32, r: f32, mr: f32, el: f32, reach: f32, mring: f32) -> u32 {
    if (ring >= P.lidar.y) {
        return NOT_MISS;
    }
    let range = compare(r, free_below[ring * P.lidar.x + bin], mr);
    let ring_el = free_below[P.lidar.z + ring];
    return both(range, compare(abs(ring_el - el), reach, mring));
}

// A spinning LiDAR (SpinningLidar::project, the range test, the ring test).
// With |p_gpu - p_cpu| <= ep per coordinate (1.75 ep in length):
// - the range r = |p| differs by 1.75 ep + 15u r (as in `planar`);
// - the azimuth by ANGLE_ERR + 3.5 ep / h (h the horizontal range, > 4 ep),
//   and the bin coordinate t = (az + pi) / 2pi * bins by that times
//   bins / 2pi plus u (4 t + 4) for the GPU's roundings; the cut at ±pi
//   (bin 0 on one side, bins - 1 on the other) takes both candidates;
// - the elevation atan2(z, h) by ANGLE_ERR + 1.75 ep / r + 8u (h's
//   roundings: 12u relative, halved by the derivative), plus 2u for the
//   rings' and bounds' rounding to f32 (|el| < pi/2);
// - the ring's reach asin(x), x = radius / r <= 2/3 (r >= 1.5 radius, else
//   uncertain): ANGLE_ERR + 10u (asin through atan2_acc and a square root)
//   + x (1.75 ep + 20u r) / (0.745 r) (dx, over sqrt(1 - x²) >= 0.745).
// Near the ring bounds and bin edges both candidates are decided and must
// agree.
fn lidar(p: vec3<f32>, ep: f32) -> u32 {
    let radius = P.scan.w;
    let r = sqrt(dot(p, p));
    let h = sqrt(p.x * p.x + p.y * p.y);
    if (r < 1.5 * radius || h <= 4.0 * ep || r <= 4.0 * ep) {
        return UNCERTAIN;
    }
    let mr = SLACK * (1.75 * ep + 15.0 * U * r);
    // Azimuth bin candidates.
    let bins = P.lidar.x;
    let az = atan2_acc(p.y, p.x);
    let t = (az + PI) / TAU * f32(bins);
    let mt = SLACK * ((ANGLE_ERR + 3.5 * ep / h) * f32(bins) / TAU + U * (4.0 * t + 4.0));
    if (mt >= 0.5) {
        return UNCERTAIN;
    }
    let k0 = floor(t - mt);
    let k1 = floor(t + mt);
    var b0 = u32(max(k0, 0.0));
    var b1 = min(u32(max(k1, 0.0)), bins - 1u);
    if (k0 < 0.0 || k1 >= f32(bins)) {
        b0 = 0u;
        b1 = bins - 1u;
    }
    b0 = min(b0, bins - 1u);
    // Ring candidates.
    let el = atan2_acc(p.z, h);
    let me = SLACK * (ANGLE_ERR + 1.75 * ep / r + 10.0 * U);
    let r0 = ring_at(el - me);
    let r1 = ring_at(el + me);
    // The ring's reach.
    let x = radius / r;
    let reach = atan2_acc(x, sqrt((1.0 - x) * (1.0 + x)));
    let mring = me + SLACK * (ANGLE_ERR + 10.0 * U + x * (1.75 * ep + 20.0 * U * r) / (0.745 * r));
    var out = lidar_beam(r0, b0, r, mr, el, reach, mring);
    out = merge(out, lidar_beam(r0, b1, r, mr, el, reach, mring));
    out = merge(out, lidar_beam(r1, b0, r, mr, el, reach, mring));
    return merge(out, lidar_beam(r1, b1, r, mr, el, reach, mring));
}

// The voxel's centre in the sensor frame. d / s = (x - n) - f: the integer
// part exact, f rounded (u/2), the difference rounded (u |d / s|); times s
// (s rounded, product rounded: 2u); each row of R (unit norm, entries
// rounded: u) dotted with d (3u, any order or fusion): by Cauchy-Schwarz
// the error is at most u (7 |p| + 0.87 s), plus the CPU's rounding to f32
// (u |p|) and its f64 error. ep = u (8.5 |p|_1 + s) + host >= that.
fn decide(i: u32) -> u32 {
    let nx = P.dims.x;
    let ny = P.dims.y;
    let c = vec3<i32>(i32(i % nx), i32((i / nx) % ny), i32(i / (nx * ny)));
    let d = (vec3<f32>(c - P.base.xyz) - P.frac.xyz) * P.frac.w;
    let p = vec3<f32>(dot(P.rot0.xyz, d), dot(P.rot1.xyz, d), dot(P.rot2.xyz, d));
    let ep = U * (8.5 * (abs(p.x) + abs(p.y) + abs(p.z)) + P.frac.w) + P.err.x;
    if (P.base.w == KIND_DEPTH) {
        return depth(p, ep);
    }
    if (P.base.w == KIND_LIDAR) {
        return lidar(p, ep);
    }
    return planar(p, ep);
}

@compute @workgroup_size(64)
fn project(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let w = (wid.x + wid.y * nwg.x) * GROUP + lid;
    let first = 16u * w;
    if (first >= P.dims.w) {
        return;
    }
    var word = 0u;
    for (var k = 0u; k < 16u; k++) {
        if (first + k < P.dims.w) {
            let code = decide(first + k);
            if (code == UNCERTAIN) {
                // Counted past the list's end, listed while it has room.
                let at = atomicAdd(&uncertain[0], 1u);
                if (at + 1u < arrayLength(&uncertain)) {
                    atomicStore(&uncertain[1u + at], first + k);
                }
            }
            word |= code << (2u * k);
        }
    }
    out[w] = word;
}
