// Ray casting (paper §IV-A), dispatched by raycast.rs: one invocation per
// ray walks its prepared fixed-point segment with the exact integer rules
// of `edtmap_core::fixed_ray::walk` (copied rule for rule) and sets the
// voxels' observation bits with atomic ORs, which commute, so the result
// is the same in any order. Four voxels share a word, one byte each.

const GROUP: u32 = 64u;
const RAY_WALK: u32 = 1u;
const RAY_SKIP_LAST: u32 = 2u;
const NO_HIT: u32 = 0xffffffffu;
const OBS_MISS: u32 = 1u;
const OBS_HIT: u32 = 2u;

// Eight u32 scalars, as `FixedRay` (a vec3 would be padded).
struct Ray {
    sx: u32, sy: u32, sz: u32,
    ex: u32, ey: u32, ez: u32,
    flags: u32,
    hit: u32,
}

struct Params {
    // Volume dims and voxel count.
    dims: vec4<u32>,
    q: u32,
    rays: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read> rays: array<Ray>;
@group(0) @binding(2) var<storage, read_write> obs: array<atomic<u32>>;

// Rules 1 and 2 of the walk for one axis.
struct Axis {
    cell: u32,
    left: u32,
    up: bool,
    num: u32,
    len: u32,
}

fn axis_new(start: u32, end: u32, n: u32, q: u32) -> Axis {
    let s = min(start, n * q);
    let e = min(end, n * q);
    let first = min(s / q, n - 1u);
    let last = min(e / q, n - 1u);
    var a: Axis;
    a.cell = first;
    a.left = max(first, last) - min(first, last);
    a.up = e > s;
    if (a.left == 0u) {
        a.num = q;
        a.len = 0u;
    } else if (a.up) {
        a.num = (first + 1u) * q - s;
        a.len = e - s;
    } else {
        a.num = s - first * q;
        a.len = s - e;
    }
    return a;
}

// Rule 3's step of one axis; returns the new linear index.
fn axis_step(a: ptr<function, Axis>, linear: u32, stride: u32, q: u32) -> u32 {
    (*a).num += q;
    (*a).left -= 1u;
    if ((*a).left == 0u) {
        (*a).len = 0u;
    }
    if ((*a).up) {
        (*a).cell += 1u;
        return linear + stride;
    }
    (*a).cell -= 1u;
    return linear - stride;
}

// Two bits per voxel, sixteen voxels per word.
fn mark(i: u32, bit: u32) {
    let m = bit << ((i & 15u) * 2u);
    if ((atomicLoad(&obs[i >> 4u]) & m) == 0u) {
        atomicOr(&obs[i >> 4u], m);
    }
}

@compute @workgroup_size(64)
fn cast_rays(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let r = (wid.x + wid.y * nwg.x) * GROUP + lid;
    if (r >= P.rays) {
        return;
    }
    let ray = rays[r];
    let n = P.dims;
    let q = P.q;
    if ((ray.flags & RAY_WALK) != 0u) {
        var x = axis_new(ray.sx, ray.ex, n.x, q);
        var y = axis_new(ray.sy, ray.ey, n.y, q);
        var z = axis_new(ray.sz, ray.ez, n.z, q);
        let stride_y = n.x;
        let stride_z = n.x * n.y;
        var linear = x.cell + stride_y * y.cell + stride_z * z.cell;
        let steps = x.left + y.left + z.left;
        for (var k = 0u; k < steps; k++) {
            mark(linear, OBS_MISS);
            if (x.num * y.len <= y.num * x.len && x.num * z.len <= z.num * x.len) {
                linear = axis_step(&x, linear, 1u, q);
            } else if (y.num * z.len <= z.num * y.len) {
                linear = axis_step(&y, linear, stride_y, q);
            } else {
                linear = axis_step(&z, linear, stride_z, q);
            }
        }
        if ((ray.flags & RAY_SKIP_LAST) == 0u) {
            mark(linear, OBS_MISS);
        }
    }
    if (ray.hit != NO_HIT && ray.hit < n.w) {
        mark(ray.hit, OBS_HIT);
    }
}
