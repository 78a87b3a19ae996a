// Wavefront integration (paper §IV-C, Algorithms 2 and 3), dispatched by
// integrate.rs. The same algorithm as the CPU's `integrate::wavefront`, on
// a dense copy of the working region (the window grown by the cutoff's
// reach plus one), with the same results bit for bit.
//
// A voxel's value is the pair (S, D): the nearest obstacle's linear index
// in the source box (the region grown by the reach) and the squared
// distance; (INF, INF) is "far". Pairs are ordered by D, then S, as the
// CPU orders its packed u64 (D << 32 | S); `cur` holds them interleaved,
// S at 2i and D at 2i + 1, which is that u64's memory layout.
//
// Without 64-bit atomics, one level of the lowering waves runs in two
// rounds: (A) an atomic minimum of D over every candidate, marking the
// voxels whose D went down; their S is reset; (B) an atomic minimum of S
// over the candidates whose D equals the new minimum. The level's result
// and its next frontier (the voxels whose pair went down) are those of
// the CPU's atomic minimum of packed values. Each level reads its
// frontier's pairs as they stood when it began (the `front` snapshot).
//
// Hierarchical frontiers (the paper's Table II): while a frontier has at
// most LOCAL_CAP voxels, `lower_local` runs level after level in a single
// workgroup, its frontier in workgroup memory and the levels separated by
// barriers instead of dispatches; a frontier that grows past that goes to
// the storage buffers and the one-dispatch-per-step levels, which use the
// whole device. Both run exactly the same steps per level.

const INF: u32 = 0xffffffffu;
const GROUP: u32 = 64u;
// Frontier entries `lower_local` keeps in workgroup memory (16 KiB).
const LOCAL_CAP: u32 = 1024u;
const LOCAL_SIZE: u32 = 256u;

// Slots of `ctrl`.
const C_DOWN: u32 = 0u;
const C_UP: u32 = 1u;
const C_NEXT: u32 = 2u;
const C_FRONT: u32 = 3u;
const C_STAMP: u32 = 4u;
const C_LEVELS: u32 = 5u;
const C_RAISED: u32 = 6u;
const C_KEPT: u32 = 7u;
const C_SEEDS: u32 = 8u;
const C_LOWERED: u32 = 9u;
const C_DIRTY: u32 = 10u;

// Indirect dispatch arguments in `args`, three words each.
const A_DOWN: u32 = 0u;
const A_UP: u32 = 3u;
const A_FRONT: u32 = 6u;
const A_NEXT: u32 = 9u;
const A_GATHER: u32 = 12u;

struct Params {
    // Region dims and voxel count.
    region: vec4<u32>,
    // Window dims and voxel count.
    window: vec4<u32>,
    // Source box dims.
    source: vec4<u32>,
    // Window origin in region coordinates (all axes), region origin in
    // source coordinates (all axes), the cutoff, the neighbour count.
    win_in_region: u32,
    shift: u32,
    max_dist_sq: u32,
    n_offsets: u32,
    // This region's origin minus the resident one's (xyz), and whether the
    // device holds the previous frame's region (w = 1).
    delta: vec4<i32>,
    // Blocks overlapping the region (xyz) and their count.
    blocks: vec4<u32>,
    // The region origin's position in its block (origin mod 8).
    o8: vec4<u32>,
    // Newly covered voxels uploaded in `fresh` (x).
    fresh: vec4<u32>,
    offsets: array<vec4<i32>, 26>,
}

@group(0) @binding(0) var<uniform> P: Params;
// Pairs before the frame, (S, D): uploaded, then the part the device
// already held overwritten by `shift`.
@group(0) @binding(1) var<storage, read_write> old_v: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read_write> cur: array<atomic<u32>>;
// The window's batch EDT: per window voxel l, the squared distance at 2l
// and the nearest obstacle's window index at 2l + 1 (edt.wgsl's pairs).
@group(0) @binding(3) var<storage, read> batch: array<u32>;
// Per region voxel: the stamp of the last frontier it joined.
@group(0) @binding(4) var<storage, read_write> mark: array<atomic<u32>>;
// Voxel queues: down at [0, R), up at [R, 2R), next frontier at [2R, 3R).
@group(0) @binding(5) var<storage, read_write> queues: array<u32>;
// The frontier's snapshot: (voxel, S, D, 0).
@group(0) @binding(6) var<storage, read_write> front: array<vec4<u32>>;
@group(0) @binding(7) var<storage, read_write> ctrl: array<atomic<u32>>;
// Per block of the region: changed (0/1) at [0, NB), then the changed
// blocks' indices at [NB, 2NB).
@group(0) @binding(8) var<storage, read_write> blk: array<atomic<u32>>;
// (old S, old D, new S, new D) of every voxel of the changed blocks,
// 512 per block in block order.
@group(0) @binding(9) var<storage, read_write> pairs: array<vec2<u32>>;
// With the region resident: the newly covered voxels, (index, S, D, 0).
@group(0) @binding(10) var<storage, read> fresh: array<vec4<u32>>;
@group(1) @binding(0) var<storage, read_write> args: array<u32>;

fn flat_id(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wid.x + wid.y * nwg.x) * GROUP + lid;
}

// Writes dispatch arguments for `items` invocations at `at` (as dispatch.rs's
// groups_1d).
fn set_groups(at: u32, items: u32) {
    let groups = max((items + GROUP - 1u) / GROUP, 1u);
    args[at] = min(groups, 65535u);
    args[at + 1u] = (groups + 65534u) / 65535u;
    args[at + 2u] = 1u;
}

fn region_coords(i: u32) -> vec3<i32> {
    let r = P.region;
    return vec3<i32>(vec3<u32>(i % r.x, (i / r.x) % r.y, i / (r.x * r.y)));
}

fn source_coords(s: u32) -> vec3<i32> {
    let r = P.source;
    return vec3<i32>(vec3<u32>(s % r.x, (s / r.x) % r.y, s / (r.x * r.y)));
}

fn in_box(c: vec3<i32>, lo: vec3<i32>, dims: vec3<u32>) -> bool {
    return all(c >= lo) && all(c < lo + vec3<i32>(dims));
}

// (S, D) pairs ordered by D, then S.
fn less(a: vec2<u32>, b: vec2<u32>) -> bool {
    return a.y < b.y || (a.y == b.y && a.x < b.x);
}

fn push(base: u32, counter: u32, v: u32) {
    let k = atomicAdd(&ctrl[counter], 1u);
    queues[base + k] = v;
}

fn load(i: u32) -> vec2<u32> {
    return vec2<u32>(atomicLoad(&cur[2u * i]), atomicLoad(&cur[2u * i + 1u]));
}

// Steps 1 and 2, one invocation per region voxel: raise the voxels whose
// obstacle in the window vanished, merge the window's batch EDT, and queue
// the voxels whose pair went down or up.
@compute @workgroup_size(64)
fn merge(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let i = flat_id(wid, nwg, lid);
    if (i >= P.region.w) {
        return;
    }
    let far = vec2<u32>(INF, INF);
    let old = old_v[i];
    let c = region_coords(i);
    let w = P.window;
    let win_lo = vec3<i32>(i32(P.win_in_region));
    let win_in_source = win_lo + vec3<i32>(i32(P.shift));
    // The old obstacle's window index, when it lies in the window.
    var src_win = INF;
    if (old.y != INF) {
        let sc = source_coords(old.x);
        if (in_box(sc, win_in_source, w.xyz)) {
            let wc = vec3<u32>(sc - win_in_source);
            src_win = wc.x + w.x * (wc.y + w.y * wc.z);
        }
    }
    let vanished = src_win != INF && batch[2u * src_win] != 0u;
    var valid = old;
    if (vanished) {
        atomicAdd(&ctrl[C_RAISED], 1u);
        valid = far;
    }
    var new_v = valid;
    if (in_box(c, win_lo, w.xyz)) {
        let wc = vec3<u32>(c - win_lo);
        let l = wc.x + w.x * (wc.y + w.y * wc.z);
        let bd = batch[2u * l];
        let bs = batch[2u * l + 1u];
        var b = far;
        if (bs != INF) {
            if (src_win == bs && bd == old.y) {
                // The usual case: the batch agrees with the map.
                b = old;
            } else if (bd <= P.max_dist_sq) {
                let oc = vec3<u32>(bs % w.x, (bs / w.x) % w.y, bs / (w.x * w.y)) + vec3<u32>(win_in_source);
                b = vec2<u32>(oc.x + P.source.x * (oc.y + P.source.y * oc.z), bd);
            }
        }
        if (less(valid, b) && src_win == INF) {
            atomicAdd(&ctrl[C_KEPT], 1u);
        }
        if (less(b, valid)) {
            new_v = b;
        }
    }
    atomicStore(&cur[2u * i], new_v.x);
    atomicStore(&cur[2u * i + 1u], new_v.y);
    if (less(new_v, old)) {
        push(0u, C_DOWN, i);
    } else if (less(old, new_v)) {
        push(P.region.w, C_UP, i);
    }
}

@compute @workgroup_size(1)
fn prep_seeds() {
    set_groups(A_DOWN, atomicLoad(&ctrl[C_DOWN]));
    set_groups(A_UP, atomicLoad(&ctrl[C_UP]));
    atomicAdd(&ctrl[C_STAMP], 1u);
}

// Joins `n` to the next frontier unless it already joined at `stamp`.
fn join(n: u32, stamp: u32) {
    if (atomicExchange(&mark[n], stamp) != stamp) {
        push(2u * P.region.w, C_NEXT, n);
    }
}

// Step 3: the voxels that went down seed the waves...
@compute @workgroup_size(64)
fn seed_down(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
             @builtin(local_invocation_index) lid: u32) {
    let k = flat_id(wid, nwg, lid);
    if (k >= atomicLoad(&ctrl[C_DOWN])) {
        return;
    }
    join(queues[k], atomicLoad(&ctrl[C_STAMP]));
}

// ... and so do the valid neighbours of the voxels that went up.
@compute @workgroup_size(64)
fn seed_up(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let k = flat_id(wid, nwg, lid);
    if (k >= atomicLoad(&ctrl[C_UP])) {
        return;
    }
    let stamp = atomicLoad(&ctrl[C_STAMP]);
    let c = region_coords(queues[P.region.w + k]);
    for (var j = 0u; j < P.n_offsets; j++) {
        let nc = c + P.offsets[j].xyz;
        if (!in_box(nc, vec3<i32>(0), P.region.xyz)) {
            continue;
        }
        let n = u32(nc.x) + P.region.x * (u32(nc.y) + P.region.y * u32(nc.z));
        if (atomicLoad(&cur[2u * n + 1u]) != INF) {
            join(n, stamp);
        }
    }
}

@compute @workgroup_size(1)
fn prep_next() {
    set_groups(A_NEXT, atomicLoad(&ctrl[C_NEXT]));
}

// The next frontier's pairs as they stand now.
@compute @workgroup_size(64)
fn snapshot(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
            @builtin(local_invocation_index) lid: u32) {
    let k = flat_id(wid, nwg, lid);
    if (k >= atomicLoad(&ctrl[C_NEXT])) {
        return;
    }
    let n = queues[2u * P.region.w + k];
    let v = load(n);
    front[k] = vec4<u32>(n, v.x, v.y, 0u);
}

// The next frontier becomes the current one; a new stamp for its level.
fn advance_common() -> u32 {
    let f = atomicLoad(&ctrl[C_NEXT]);
    atomicStore(&ctrl[C_FRONT], f);
    atomicStore(&ctrl[C_NEXT], 0u);
    set_groups(A_FRONT, f);
    atomicAdd(&ctrl[C_STAMP], 1u);
    if (f > 0u) {
        atomicAdd(&ctrl[C_LEVELS], 1u);
    }
    return f;
}

@compute @workgroup_size(1)
fn advance_seeds() {
    atomicStore(&ctrl[C_SEEDS], advance_common());
}

@compute @workgroup_size(1)
fn advance() {
    atomicAdd(&ctrl[C_LOWERED], advance_common());
}

// Calls for each neighbour of frontier entry `e` the waves may lower:
// only away from (or across) the entry's obstacle, within the region and
// the cutoff. Returns nothing; `round` selects what is done with it.
fn lower(e: vec4<u32>, round: u32, stamp: u32) {
    let src = source_coords(e.y);
    let cv = region_coords(e.x);
    let shift = vec3<i32>(i32(P.shift));
    let away = cv + shift - src;
    for (var j = 0u; j < P.n_offsets; j++) {
        let o = P.offsets[j].xyz;
        if (dot(o, away) < 0) {
            continue;
        }
        let nc = cv + o;
        if (!in_box(nc, vec3<i32>(0), P.region.xyz)) {
            continue;
        }
        let delta = nc + shift - src;
        let d = u32(dot(delta, delta));
        if (d > P.max_dist_sq) {
            continue;
        }
        let n = u32(nc.x) + P.region.x * (u32(nc.y) + P.region.y * u32(nc.z));
        if (round == 0u) {
            let prev = atomicMin(&cur[2u * n + 1u], d);
            if (d < prev) {
                join(n, stamp);
            }
        } else if (d == atomicLoad(&cur[2u * n + 1u])) {
            let prev = atomicMin(&cur[2u * n], e.y);
            if (e.y < prev) {
                join(n, stamp);
            }
        }
    }
}

// Round A of a level: the minimum distance.
@compute @workgroup_size(64)
fn lower_dist(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_index) lid: u32) {
    let k = flat_id(wid, nwg, lid);
    if (k >= atomicLoad(&ctrl[C_FRONT])) {
        return;
    }
    lower(front[k], 0u, atomicLoad(&ctrl[C_STAMP]));
}

// Between the rounds: voxels whose distance went down forget their obstacle.
@compute @workgroup_size(64)
fn reset_source(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                @builtin(local_invocation_index) lid: u32) {
    let k = flat_id(wid, nwg, lid);
    if (k >= atomicLoad(&ctrl[C_NEXT])) {
        return;
    }
    atomicStore(&cur[2u * queues[2u * P.region.w + k]], INF);
}

// Round B of a level: the lowest obstacle index at that distance.
@compute @workgroup_size(64)
fn lower_source(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                @builtin(local_invocation_index) lid: u32) {
    let k = flat_id(wid, nwg, lid);
    if (k >= atomicLoad(&ctrl[C_FRONT])) {
        return;
    }
    lower(front[k], 1u, atomicLoad(&ctrl[C_STAMP]));
}

var<workgroup> w_front: array<vec4<u32>, 1024>;
var<workgroup> w_count: u32;
var<workgroup> w_stamp: u32;

// Levels in one workgroup while the frontier fits in workgroup memory
// (see the top of this file). Leaves `ctrl`, `args` and, when it stops
// on a large frontier, `front` as the dispatched levels would.
@compute @workgroup_size(256)
fn lower_local(@builtin(local_invocation_index) lid: u32) {
    if (lid == 0u) {
        w_count = atomicLoad(&ctrl[C_FRONT]);
        w_stamp = atomicLoad(&ctrl[C_STAMP]);
    }
    let first = workgroupUniformLoad(&w_count);
    if (first == 0u || first > LOCAL_CAP) {
        return;
    }
    for (var k = lid; k < first; k += LOCAL_SIZE) {
        w_front[k] = front[k];
    }
    let r = P.region.w;
    loop {
        let count = workgroupUniformLoad(&w_count);
        let stamp = workgroupUniformLoad(&w_stamp);
        if (count == 0u || count > LOCAL_CAP) {
            break;
        }
        for (var k = lid; k < count; k += LOCAL_SIZE) {
            lower(w_front[k], 0u, stamp);
        }
        storageBarrier();
        workgroupBarrier();
        let lowered = atomicLoad(&ctrl[C_NEXT]);
        for (var k = lid; k < lowered; k += LOCAL_SIZE) {
            atomicStore(&cur[2u * queues[2u * r + k]], INF);
        }
        storageBarrier();
        workgroupBarrier();
        for (var k = lid; k < count; k += LOCAL_SIZE) {
            lower(w_front[k], 1u, stamp);
        }
        storageBarrier();
        workgroupBarrier();
        let next = atomicLoad(&ctrl[C_NEXT]);
        for (var k = lid; k < next; k += LOCAL_SIZE) {
            let n = queues[2u * r + k];
            let e = vec4<u32>(n, atomicLoad(&cur[2u * n]), atomicLoad(&cur[2u * n + 1u]), 0u);
            if (next <= LOCAL_CAP) {
                w_front[k] = e;
            } else {
                front[k] = e;
            }
        }
        storageBarrier();
        workgroupBarrier();
        if (lid == 0u) {
            atomicAdd(&ctrl[C_LOWERED], advance_common());
            w_count = next;
            w_stamp = atomicLoad(&ctrl[C_STAMP]);
        }
        storageBarrier();
        workgroupBarrier();
    }
}

// The region the device holds from the previous frame (`cur`, equal to
// the CPU map there) moved to this frame's region: voxels in both take
// their pair from the device, re-indexed to the new source box; the
// others keep what the host uploaded from the map.
@compute @workgroup_size(64)
fn shift(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let i = flat_id(wid, nwg, lid);
    if (i >= P.region.w || P.delta.w == 0) {
        return;
    }
    let c = region_coords(i) + P.delta.xyz;
    if (!in_box(c, vec3<i32>(0), P.region.xyz)) {
        return;
    }
    let prev = load(u32(c.x) + P.region.x * (u32(c.y) + P.region.y * u32(c.z)));
    var v = vec2<u32>(INF, INF);
    if (prev.y != INF) {
        let sc = source_coords(prev.x) - P.delta.xyz;
        if (in_box(sc, vec3<i32>(0), P.source.xyz)) {
            v = vec2<u32>(u32(sc.x) + P.source.x * (u32(sc.y) + P.source.y * u32(sc.z)), prev.y);
        }
    }
    old_v[i] = v;
}

// Block of the region holding region voxel `c`, and the voxel's offset in it.
fn block_of(c: vec3<i32>) -> vec2<u32> {
    let g = vec3<u32>(c) + P.o8.xyz;
    let b = g / 8u;
    let o = g % 8u;
    return vec2<u32>(b.x + P.blocks.x * (b.y + P.blocks.y * b.z), o.x + 8u * (o.y + 8u * o.z));
}

// Marks the blocks holding a voxel whose pair changed.
@compute @workgroup_size(64)
fn diff(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_id(wid, nwg, lid);
    if (i >= P.region.w) {
        return;
    }
    let o = old_v[i];
    if (any(o != load(i))) {
        atomicStore(&blk[block_of(region_coords(i)).x], 1u);
    }
}

// Lists the changed blocks.
@compute @workgroup_size(64)
fn compact(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let b = flat_id(wid, nwg, lid);
    if (b >= P.blocks.w || atomicLoad(&blk[b]) == 0u) {
        return;
    }
    let slot = atomicAdd(&ctrl[C_DIRTY], 1u);
    atomicStore(&blk[P.blocks.w + slot], b);
}

@compute @workgroup_size(1)
fn prep_gather() {
    set_groups(A_GATHER, atomicLoad(&ctrl[C_DIRTY]) * 512u);
}

// The new pair of every voxel of the changed blocks, for the host to write
// into the CPU map (it has the old ones there); voxels outside the region
// get far pairs.
@compute @workgroup_size(64)
fn gather(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let k = flat_id(wid, nwg, lid);
    if (k >= atomicLoad(&ctrl[C_DIRTY]) * 512u) {
        return;
    }
    let b = atomicLoad(&blk[P.blocks.w + k / 512u]);
    let off = k % 512u;
    let bc = vec3<u32>(b % P.blocks.x, (b / P.blocks.x) % P.blocks.y, b / (P.blocks.x * P.blocks.y));
    let g = bc * 8u + vec3<u32>(off % 8u, (off / 8u) % 8u, off / 64u);
    let c = vec3<i32>(g) - vec3<i32>(P.o8.xyz);
    var e = vec2<u32>(INF, INF);
    if (in_box(c, vec3<i32>(0), P.region.xyz)) {
        let i = u32(c.x) + P.region.x * (u32(c.y) + P.region.y * u32(c.z));
        e = load(i);
    }
    pairs[k] = e;
}

// The newly covered voxels' pairs, read from the map by the host, into
// place (`shift` fills the rest).
@compute @workgroup_size(64)
fn scatter(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let k = flat_id(wid, nwg, lid);
    if (k >= P.fresh.x) {
        return;
    }
    let e = fresh[k];
    old_v[e.x] = e.yz;
}
