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
// corrections (a projection's hits, the uncertain voxels it decided, as
// codes of their own) replace those voxels' codes; they come grouped by
// block, so the fusion reads them in the same dispatch.

const UNOBSERVED_BITS: u32 = 0xff800000u;

struct Params {
    // Volume dims, and its voxel count.
    dims: vec4<u32>,
    // Volume origin within its first block (0..7 per axis).
    o8: vec4<u32>,
    // The volume's blocks per axis, and their count.
    blocks: vec4<u32>,
    // Log-odds added on a hit, on a miss; lower and upper clamps.
    lo: vec4<f32>,
    // The occupied threshold's key (see `key`).
    occupied: vec4<u32>,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read> codes: array<u32>;
// The corrections: [b] and [b + 1] bound block b's, which follow the
// blocks' bounds, each its voxel's offset in the block + 512 * its code.
@group(0) @binding(2) var<storage, read> fixes: array<u32>;
// Pool slot of each volume block (x fastest).
@group(0) @binding(3) var<storage, read> slots: array<u32>;
// 512 words per slot, voxels in block order (x fastest).
@group(0) @binding(4) var<storage, read_write> pool: array<u32>;
// Per volume block: its observations (bits 0-9), state changes (10-19),
// and whether a value changed (bit 20).
@group(0) @binding(5) var<storage, read_write> counts: array<atomic<u32>>;

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

// One workgroup per volume block, an invocation per row of eight voxels
// along x (which reads one or two code words, none where the row is
// unobserved): the row's observed voxels fused, and what they did added to
// the block's counts. No barrier: lavapipe runs a workgroup with one as
// coroutines, several times slower.
@compute @workgroup_size(64)
fn fuse(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let b = wid.x + wid.y * nwg.x;
    if (b >= P.blocks.w) {
        return;
    }
    let bc = vec3<u32>(b % P.blocks.x, (b / P.blocks.x) % P.blocks.y, b / (P.blocks.x * P.blocks.y));
    // The row's y and z in the volume, negative (wrapped) before its origin.
    let cy = bc.y * 8u + (lid % 8u) - P.o8.y;
    let cz = bc.z * 8u + (lid / 8u) - P.o8.z;
    if (cy >= P.dims.y || cz >= P.dims.z) {
        return;
    }
    let slot = slots[b] * 512u;
    let x0 = bc.x * 8u;
    // The row's corrections: which of its eight voxels have one (two bits
    // each), and their codes.
    var fixed = 0u;
    var fixed_codes = 0u;
    for (var k = fixes[b]; k < fixes[b + 1u]; k++) {
        let e = fixes[k];
        if (((e & 511u) >> 3u) == lid) {
            let s = 2u * (e & 7u);
            fixed |= 3u << s;
            fixed_codes |= (e >> 9u) << s;
        }
    }
    // The code word last read: a row's eight voxels lie in one or two.
    var held = 0xffffffffu;
    var word_codes = 0u;
    var observed = 0u;
    var flipped = 0u;
    var rewritten = 0u;
    for (var x = 0u; x < 8u; x++) {
        let cx = x0 + x - P.o8.x;
        if (cx >= P.dims.x) {
            continue;
        }
        let i = cx + P.dims.x * (cy + P.dims.y * cz);
        var code: u32;
        if (((fixed >> (2u * x)) & 3u) != 0u) {
            code = (fixed_codes >> (2u * x)) & 3u;
        } else {
            if ((i >> 4u) != held) {
                held = i >> 4u;
                word_codes = codes[held];
            }
            code = (word_codes >> (2u * (i & 15u))) & 3u;
        }
        if (code == 0u) {
            continue;
        }
        let off = x + 8u * lid;
        let old = pool[slot + off];
        let prior = select(bitcast<f32>(old ^ UNOBSERVED_BITS), 0.0, old == 0u);
        var value: f32;
        if ((code & 2u) != 0u) {
            value = min(prior + P.lo.x, P.lo.w);
        } else {
            value = max(prior + P.lo.y, P.lo.z);
        }
        let word = bitcast<u32>(value) ^ UNOBSERVED_BITS;
        observed += 1u;
        flipped += select(0u, 1u, state(old) != state(word));
        if (word != old) {
            pool[slot + off] = word;
            rewritten = 1u;
        }
    }
    // A block's observations and state changes are at most 512 each: the
    // two sums never carry into the next field or the flag.
    if (observed != 0u) {
        atomicAdd(&counts[b], observed | (flipped << 10u));
    }
    if (rewritten != 0u) {
        atomicOr(&counts[b], 1u << 20u);
    }
}
