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
    // scan_x from resident blocks (FROM_BLOCKS): the grid's origin within
    // its first block (0..7 per axis).
    o8: vec4<u32>,
    // The grid's blocks along x and y (x fastest in `slots`).
    nb: vec4<u32>,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read> mask: array<u32>;
@group(0) @binding(2) var<storage, read> src: array<vec2<u32>>;
@group(0) @binding(3) var<storage, read_write> dst: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> stack: array<vec2<i32>>;
// With FROM_BLOCKS: the pool slot of each of the grid's blocks, EMPTY for a
// block with no obstacle, FULL for one of obstacles only; `mask` is then
// the pool, 16 words per slot, voxel o = x + 8 (y + 8 z) of a block at
// bit o % 32 of word o / 32.
@group(0) @binding(5) var<storage, read> slots: array<u32>;

const EMPTY: u32 = 0xffffffffu;
const FULL: u32 = 0xfffffffeu;

// Whether scan_x reads resident blocks (its second pipeline, `edt.rs`)
// rather than the grid's own bits.
override FROM_BLOCKS: bool = false;

// The obstacle bits of the x line (y, z) from voxel x (linear index i)
// to the end of the word that holds it: the bits, voxel x lowest, and how
// many voxels they cover (to the end of a 32-bit word of the grid's own
// bits, or of a block's row of 8).
fn bits_from(x: u32, i: u32, y: u32, z: u32) -> vec2<u32> {
    if (!FROM_BLOCKS) {
        return vec2<u32>(mask[i >> 5u] >> (i & 31u), 32u - (i & 31u));
    }
    let gx = x + P.o8.x;
    return vec2<u32>(block_row(gx >> 3u, y, z) >> (gx & 7u), 8u - (gx & 7u));
}

// The 8 bits of the row of block column `bx` that holds the x line (y, z).
fn block_row(bx: u32, y: u32, z: u32) -> u32 {
    let g = vec2<u32>(y, z) + P.o8.yz;
    let slot = slots[bx + P.nb.x * ((g.x >> 3u) + P.nb.y * (g.y >> 3u))];
    if (slot == EMPTY) {
        return 0u;
    }
    if (slot == FULL) {
        return 0xffu;
    }
    let o = ((g.x & 7u) << 3u) | ((g.y & 7u) << 6u);
    return (mask[slot * 16u + (o >> 5u)] >> (o & 31u)) & 0xffu;
}

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
    var x = 0u;
    while (x < n) {
        let run = bits_from(x, base + x, y, z);
        var bits = run.x;
        let end = min(n, x + run.y);
        for (; x < end; x++) {
            if ((bits & 1u) != 0u) {
                left = x;
            }
            bits >>= 1u;
            dst[first + nz * x] = vec2<u32>(left, 0u);
        }
    }
    // Backward: against the nearest one after x. Voxel x is an obstacle
    // when the forward pass found itself as the nearest before it.
    var right = INF;
    for (var k = n; k > 0u; k--) {
        let x = k - 1u;
        let lo = dst[first + nz * x].x;
        if (lo == x) {
            right = x;
        }
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
