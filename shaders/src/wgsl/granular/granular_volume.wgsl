// VolumePass: the u64 sum of every stored value of a height map (the conserved volume of
// granular deformation), exactly, so that checking the volume reads back 8 bytes rather than
// the whole map. CPU reference: terrain_core::HeightMap::raw_sum.
//
// Each invocation sums every `stride`-th value from its global index as a (low, high) pair of
// u32 with carry; each workgroup adds its 256 pairs in shared memory; invocation 0 of each
// workgroup adds the group's pair to `total` with atomics, carrying out of the low word exactly
// (the `old` value of the atomic add says whether that add wrapped). `total` is zeroed by the
// caller before the dispatch.

struct VolumeParams {
    // Values in the map.
    count: u32,
    // Invocations in the whole dispatch (workgroups * WORKGROUP).
    stride: u32,
    // ceil(count / stride): values each invocation visits at most (uniform, so the barriers
    // below stay in uniform control flow).
    rounds: u32,
    _pad: u32,
}

const WORKGROUP: u32 = 256u;

@group(0) @binding(0) var<uniform> v: VolumeParams;
@group(0) @binding(1) var<storage, read> heights: array<u32>;
@group(0) @binding(2) var<storage, read_write> total: array<atomic<u32>, 2>;

var<workgroup> low: array<u32, WORKGROUP>;
var<workgroup> high: array<u32, WORKGROUP>;

@compute @workgroup_size(256, 1, 1)
fn main(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) l: u32,
) {
    var lo = 0u;
    var hi = 0u;
    for (var r = 0u; r < v.rounds; r = r + 1u) {
        // Below count + stride <= 2^32 (checked on the CPU): no wrap-around.
        let i = gid.x + r * v.stride;
        if i < v.count {
            let h = heights[i];
            lo = lo + h;
            hi = hi + select(0u, 1u, lo < h);
        }
    }
    low[l] = lo;
    high[l] = hi;
    workgroupBarrier();
    for (var s = WORKGROUP / 2u; s > 0u; s = s >> 1u) {
        if l < s {
            let other = low[l + s];
            let sum = low[l] + other;
            high[l] = high[l] + high[l + s] + select(0u, 1u, sum < other);
            low[l] = sum;
        }
        workgroupBarrier();
    }
    if l == 0u {
        let group_lo = low[0];
        let group_hi = high[0];
        let old = atomicAdd(&total[0], group_lo);
        let carry = select(0u, 1u, old > 0xffffffffu - group_lo);
        if group_hi + carry > 0u {
            atomicAdd(&total[1], group_hi + carry);
        }
    }
}
