// Exact batch EDT (paper §IV-B, Algorithm 1, Table I), dispatched by edt.rs.
//
// Values are (squared distance, nearest obstacle's linear index) pairs. The
// volume goes through three scans, along x, then y, then z. Before each
// scan a transpose makes the scanned axis the slowest one, so that the
// invocations of a workgroup, one per line, read and write consecutive
// addresses at every step (coalesced), as the paper's transposes do:
//   mask bits (x fastest) -> scan_x into [z x y] -> scan y -> T -> [x y z] scan z
// (scan_x does what two transposes and Meijster's scan would on a binary
// line).
// A cyclic shift of the axes is a 2D transpose of an A x R matrix (A the
// fastest axis, R the product of the other two), done in 16x16 tiles
// through workgroup memory.
//
// Each scan is Meijster's integer lower envelope of parabolas, the same as
// the CPU's: a parabola is kept only where it is strictly lowest, so ties
// go to the lowest position along the axis, the backends' common tie rule.
// All arithmetic is i32; edt.rs refuses grids whose squared diagonal could
// overflow it.

const INF: u32 = 0xffffffffu;
const GROUP: u32 = 64u;

struct Params {
    // Line length (scan), fastest-axis length A (transpose).
    len: u32,
    // Number of lines (scan), product R of the other axes (transpose).
    count: u32,
    // scan_x: the grid's z size.
    aux: u32,
    // Voxels in the grid.
    total: u32,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read> mask: array<u32>;
@group(0) @binding(2) var<storage, read> src: array<vec2<u32>>;
@group(0) @binding(3) var<storage, read_write> dst: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> stack: array<vec2<i32>>;

// One invocation per item over a 2D grid of workgroups (a 1D dispatch is
// limited to 65535 workgroups).
fn flat_id(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wid.x + wid.y * nwg.x) * GROUP + lid;
}

// The scan along x, straight from the mask: invocation l = z + nz y walks
// the x line (y, z) of the mask bits and writes the line's 1D EDT where the
// scan along y reads it, [z x y] (element y of line z + nz x), so no
// transpose is needed in between; neighbouring invocations write
// neighbouring addresses. On a binary line Meijster's envelope is the
// nearest obstacle, the lower one on a tie, which is what this writes.
@compute @workgroup_size(64)
fn scan_x(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let l = flat_id(wid, nwg, lid);
    let c = P.count;
    if (l >= c) {
        return;
    }
    let n = P.len;
    let nz = P.aux;
    let z = l % nz;
    let y = l / nz;
    let base = n * (y + (c / nz) * z);
    // Element x of this line goes to first + nz x.
    let first = z + nz * n * y;
    // Forward: the nearest obstacle at or before x, parked in dst.
    var left = INF;
    for (var x = 0u; x < n; x++) {
        let i = base + x;
        if (((mask[i >> 5u] >> (i & 31u)) & 1u) != 0u) {
            left = x;
        }
        dst[first + nz * x] = vec2<u32>(left, 0u);
    }
    // Backward: against the nearest one after x.
    var right = INF;
    for (var k = n; k > 0u; k--) {
        let x = k - 1u;
        let i = base + x;
        if (((mask[i >> 5u] >> (i & 31u)) & 1u) != 0u) {
            right = x;
        }
        let lo = dst[first + nz * x].x;
        var p = INF;
        if (lo != INF && (right == INF || x - lo <= right - x)) {
            p = lo;
        } else if (right != INF) {
            p = right;
        }
        var value = vec2<u32>(INF, INF);
        if (p != INF) {
            let d = max(x, p) - min(x, p);
            value = vec2<u32>(d * d, base + p);
        }
        dst[first + nz * x] = value;
    }
}

var<workgroup> tile: array<vec2<u32>, 272>;

// dst[r + R a] = src[a + A r]: element (a, r) of an A x R matrix, a fastest
// in, r fastest out. Tiles of 16 x 16, padded to 17 to avoid bank clashes.
@compute @workgroup_size(16, 16)
fn transpose(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
             @builtin(local_invocation_id) lid: vec3<u32>) {
    let big_a = P.len;
    let big_r = P.count;
    let a0 = wid.x * 16u;
    let r0 = (wid.y + wid.z * nwg.y) * 16u;
    if (r0 >= big_r) {
        return;
    }
    let a = a0 + lid.x;
    let r = r0 + lid.y;
    if (a < big_a && r < big_r) {
        tile[lid.y * 17u + lid.x] = src[a + big_a * r];
    }
    workgroupBarrier();
    let r_out = r0 + lid.x;
    let a_out = a0 + lid.y;
    if (a_out < big_a && r_out < big_r) {
        dst[r_out + big_r * a_out] = tile[lid.x * 17u + lid.y];
    }
}

// floor(a / b) for b > 0 (WGSL's `/` truncates towards zero).
fn floor_div(a: i32, b: i32) -> i32 {
    let q = a / b;
    if (a % b < 0) {
        return q - 1;
    }
    return q;
}

// Squared distance stored in `src` for element `pos` of line `l`.
fn f_at(l: u32, pos: i32) -> i32 {
    return i32(src[l + P.count * u32(pos)].x);
}

// One invocation per line: element k of line l is at l + count * k, in
// `src`, `dst`, the outputs and the line's envelope `stack` (position,
// first integer it owns).
@compute @workgroup_size(64)
fn scan(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let l = flat_id(wid, nwg, lid);
    let c = P.count;
    if (l >= c) {
        return;
    }
    let n = i32(P.len);
    var k = 0u;
    for (var q = 0; q < n; q++) {
        let fq_raw = src[l + c * u32(q)].x;
        if (fq_raw == INF) {
            continue;
        }
        let fq = i32(fq_raw);
        // Drop the parabolas that q beats strictly where they start.
        loop {
            if (k == 0u) {
                break;
            }
            let top = stack[l + c * (k - 1u)];
            let at_start = (top.y - top.x) * (top.y - top.x) + f_at(l, top.x);
            let d = top.y - q;
            if (at_start > d * d + fq) {
                k -= 1u;
            } else {
                break;
            }
        }
        var start = 0;
        if (k > 0u) {
            // q is strictly lower than the top from the first integer past
            // the parabolas' intersection.
            let top = stack[l + c * (k - 1u)];
            let num = fq + q * q - f_at(l, top.x) - top.x * top.x;
            start = 1 + floor_div(num, 2 * (q - top.x));
        }
        if (start < n) {
            stack[l + c * k] = vec2<i32>(q, start);
            k += 1u;
        }
    }
    var j = 0u;
    for (var x = 0; x < n; x++) {
        let o = l + c * u32(x);
        var value = vec2<u32>(INF, INF);
        if (k > 0u) {
            if (j + 1u < k && stack[l + c * (j + 1u)].y == x) {
                j += 1u;
            }
            let p = stack[l + c * j].x;
            let e = src[l + c * u32(p)];
            let d = x - p;
            value = vec2<u32>(u32(d * d) + e.x, e.y);
        }
        dst[o] = value;
    }
}
