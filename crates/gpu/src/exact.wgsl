// Exact integration on the device, dispatched by exact.rs.
//
// The batch EDT of the source box (the region grown by the cutoff's reach)
// is left on the device by edt.wgsl: per voxel the squared distance and the
// nearest obstacle's linear index in the source box. `compare` turns
// it into each region voxel's new value and compares it with the value the
// device holds in its block pool (the host map's, kept resident between
// frames); where they differ it writes the new value into the pool and
// lists the block. exact.rs then copies the listed pool blocks out, the
// only voxel data that goes back to the host.
//
// A value is one word: FAR (no obstacle within the cutoff) or the offset
// from the voxel to its nearest obstacle, 10 bits per axis biased by 512;
// the squared distance is the offset's squared length. exact.rs encodes
// the host's values the same way when it uploads a block.

const FAR: u32 = 0u;
const NO_SITE: u32 = 0xffffffffu;

struct Params {
    // Source box dims, and the reach (region voxel c is source voxel c + reach).
    source: vec4<u32>,
    // Region dims, and its voxel count.
    region: vec4<u32>,
    // Region origin within its first block (0..7 per axis), and the
    // largest squared distance kept.
    o8: vec4<u32>,
    // The region's blocks per axis, and their count.
    blocks: vec4<u32>,
}

@group(0) @binding(0) var<uniform> P: Params;
// Per source voxel: squared distance, nearest obstacle's index.
@group(0) @binding(1) var<storage, read> pairs: array<vec2<u32>>;
// Pool slot of each region block (x fastest).
@group(0) @binding(2) var<storage, read> slots: array<u32>;
// 512 values per slot, voxels in block order (x fastest).
@group(0) @binding(3) var<storage, read_write> pool: array<u32>;
// The changed blocks, in no particular order.
@group(0) @binding(4) var<storage, read_write> list: array<u32>;
// [0]: how many blocks are listed.
@group(0) @binding(5) var<storage, read_write> ctrl: array<atomic<u32>>;

fn encode(off: vec3<i32>) -> u32 {
    let b = vec3<u32>(off + vec3<i32>(512));
    return b.x | (b.y << 10u) | (b.z << 20u);
}

var<workgroup> changed: atomic<u32>;

// One workgroup per region block: its voxels inside the region compared
// and written, the block listed if any changed.
@compute @workgroup_size(64)
fn compare(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let b = wid.x + wid.y * nwg.x;
    if (b >= P.blocks.w) {
        return;
    }
    if (lid == 0u) {
        atomicStore(&changed, 0u);
    }
    workgroupBarrier();
    let bc = vec3<u32>(b % P.blocks.x, (b / P.blocks.x) % P.blocks.y, b / (P.blocks.x * P.blocks.y));
    let slot = slots[b] * 512u;
    let r = P.region.xyz;
    for (var k = 0u; k < 8u; k++) {
        let off = lid + 64u * k;
        let w = vec3<u32>(off % 8u, (off / 8u) % 8u, off / 64u);
        // Region coordinates, negative (wrapped) before the region's origin.
        let c = bc * 8u + w - P.o8.xyz;
        if (any(c >= r)) {
            continue;
        }
        let sc = c + vec3<u32>(P.source.w);
        let s = sc.x + P.source.x * (sc.y + P.source.y * sc.z);
        let e = pairs[s];
        let d = e.x;
        let n = e.y;
        var value = FAR;
        if (n != NO_SITE && d <= P.o8.w) {
            let nc = vec3<u32>(n % P.source.x, (n / P.source.x) % P.source.y, n / (P.source.x * P.source.y));
            value = encode(vec3<i32>(nc) - vec3<i32>(sc));
        }
        if (pool[slot + off] != value) {
            pool[slot + off] = value;
            atomicStore(&changed, 1u);
        }
    }
    workgroupBarrier();
    if (lid == 0u && atomicLoad(&changed) != 0u) {
        let k = atomicAdd(&ctrl[0], 1u);
        list[k] = b;
    }
}
