// Fusion (paper §IV-A) on the device, dispatched by fuse.rs: the frame's
// observation codes, where ray casting or the projection left them, added
// to the log-odds of the window's blocks, which the device keeps resident
// in a pool. What edtmap_core::LogOdds::update does, in the same f32
// additions and clamps (correctly rounded on every Vulkan, Metal and DX12
// device), so the values are the CPU's bit for bit.
//
// A pool word is the log-odds' f32 bits XOR UNOBSERVED_BITS: 0 is a voxel
// never observed (-inf), so that a block the map lacks is cleared on the
// device, not uploaded. States are decided on the bits (an order-preserving
// map of f32 to u32), not by float comparisons, which a device may flush.
//
// Codes, two bits per voxel, sixteen to a word: bit 1 a hit, else bit 0 a
// miss (ray casting sets both on a voxel hit and missed: a hit). The host's
// corrections (a projection's hits, the uncertain voxels it decided) set
// their voxels' two bits first.

const UNOBSERVED_BITS: u32 = 0xff800000u;

struct Params {
    // Volume dims, and its voxel count.
    dims: vec4<u32>,
    // Volume origin within its first block (0..7 per axis), and the number
    // of corrections.
    o8: vec4<u32>,
    // The volume's blocks per axis, and their count.
    blocks: vec4<u32>,
    // Log-odds added on a hit, on a miss; lower and upper clamps.
    lo: vec4<f32>,
    // The occupied threshold's key (see `key`).
    occupied: vec4<u32>,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read_write> codes: array<atomic<u32>>;
// Per correction: voxel index * 4 + its code.
@group(0) @binding(2) var<storage, read> corrections: array<u32>;
// Pool slot of each volume block (x fastest).
@group(0) @binding(3) var<storage, read> slots: array<u32>;
// 512 words per slot, voxels in block order (x fastest).
@group(0) @binding(4) var<storage, read_write> pool: array<u32>;
// Per observed block: its index, observations, state changes, and whether
// a value changed.
@group(0) @binding(5) var<storage, read_write> list: array<vec2<u32>>;
// [0]: how many blocks are listed.
@group(0) @binding(6) var<storage, read_write> ctrl: array<atomic<u32>>;

// One invocation per correction.
@compute @workgroup_size(64)
fn correct(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let k = (wid.x + wid.y * nwg.x) * 64u + lid;
    if (k >= P.o8.w) {
        return;
    }
    let e = corrections[k];
    let i = e >> 2u;
    let shift = 2u * (i & 15u);
    // Each voxel is corrected once; the two atomics leave the word's other
    // voxels alone, whatever order the invocations take.
    atomicAnd(&codes[i >> 4u], ~(3u << shift));
    atomicOr(&codes[i >> 4u], (e & 3u) << shift);
}

// f32 bits mapped to u32 so that unsigned order is the floats' order.
fn key(bits: u32) -> u32 {
    return select(bits | 0x80000000u, ~bits, (bits & 0x80000000u) != 0u);
}

// 0 unknown, 1 free, 2 occupied (edtmap_core::LogOdds::state).
fn state(word: u32) -> u32 {
    if (word == 0u) {
        return 0u;
    }
    return select(1u, 2u, key(word ^ UNOBSERVED_BITS) > P.occupied.x);
}

var<workgroup> observed: atomic<u32>;
var<workgroup> flipped: atomic<u32>;
var<workgroup> rewritten: atomic<u32>;

// One workgroup per volume block: its observed voxels fused, the block
// listed with its counts if any was observed.
@compute @workgroup_size(64)
fn fuse(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let b = wid.x + wid.y * nwg.x;
    if (b >= P.blocks.w) {
        return;
    }
    if (lid == 0u) {
        atomicStore(&observed, 0u);
        atomicStore(&flipped, 0u);
        atomicStore(&rewritten, 0u);
    }
    workgroupBarrier();
    let bc = vec3<u32>(b % P.blocks.x, (b / P.blocks.x) % P.blocks.y, b / (P.blocks.x * P.blocks.y));
    let slot = slots[b] * 512u;
    for (var k = 0u; k < 8u; k++) {
        let off = lid + 64u * k;
        let w = vec3<u32>(off % 8u, (off / 8u) % 8u, off / 64u);
        // Volume coordinates, negative (wrapped) before the volume's origin.
        let c = bc * 8u + w - P.o8.xyz;
        if (any(c >= P.dims.xyz)) {
            continue;
        }
        let i = c.x + P.dims.x * (c.y + P.dims.y * c.z);
        let code = (atomicLoad(&codes[i >> 4u]) >> (2u * (i & 15u))) & 3u;
        if (code == 0u) {
            continue;
        }
        let old = pool[slot + off];
        let prior = select(bitcast<f32>(old ^ UNOBSERVED_BITS), 0.0, old == 0u);
        var value: f32;
        if ((code & 2u) != 0u) {
            value = min(prior + P.lo.x, P.lo.w);
        } else {
            value = max(prior + P.lo.y, P.lo.z);
        }
        let word = bitcast<u32>(value) ^ UNOBSERVED_BITS;
        atomicAdd(&observed, 1u);
        if (state(old) != state(word)) {
            atomicAdd(&flipped, 1u);
        }
        if (word != old) {
            pool[slot + off] = word;
            atomicStore(&rewritten, 1u);
        }
    }
    workgroupBarrier();
    let n = atomicLoad(&observed);
    if (lid == 0u && n != 0u) {
        let at = atomicAdd(&ctrl[0], 1u);
        list[at] = vec2<u32>(b, n | (atomicLoad(&flipped) << 10u) | (atomicLoad(&rewritten) << 20u));
    }
}
