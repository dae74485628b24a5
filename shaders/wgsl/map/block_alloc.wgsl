// SPDX-License-Identifier: MIT
//! Each invocation allocates, in a sparse map, the blocks that one depth pixel's truncation band
//! passes through (voxel-block hashing's allocation, Nießner et al. 2013 §4.1): the segment of
//! the pixel's ray between camera depths z - b and z + b (z the measured depth, b its truncation
//! band, truncation_band_m; every voxel the integration can bring below a TSDF of 1 lies on such
//! a segment) is walked block by block
//! (a 3D DDA, Amanatides & Woo 1987: every block the segment passes through, in order), and each
//! block is inserted into the hash table unless it is there already. Insertion claims an empty slot with a compare-exchange on its key (integer atomics
//! only), probing linearly from the block's hash; `block_assign` then gives new keys their pool
//! blocks, so no invocation here ever waits for another. Which slot a key lands in depends on
//! the order invocations run: the table's contents are compared by key set, not by layout.
//! Samples outside the sparse box and keys that find no slot within MAP_MAX_PROBES are counted
//! (MAP_COUNTER_OUT_OF_RANGE, MAP_COUNTER_HASH_FULL), never written; a block found swapped out
//! to the host is counted too (MAP_COUNTER_SWAPPED_HITS: this frame is not fused there).
//! Nothing is allocated when the pose is disabled (a lost frame).
#import invalid
#import camera
#import camera_pose
#import map

struct BlockAllocParams {
    // The sparse map.
    volume: VolumeDesc,
    // Intrinsics of the depth image.
    intrinsics: Intrinsics,
}

@group(0) @binding(0) var<uniform> params: BlockAllocParams;
// The pose the depth is fused at.
@group(0) @binding(1) var<uniform> pose: CameraPose;
// Depth to fuse, metres (NaN: none).
@group(0) @binding(2) var<storage, read> depth_m: array<f32>;
// The hash table: (key, pool index) per slot.
@group(0) @binding(3) var<storage, read_write> block_table: array<atomic<u32>>;
// The map's counters (map.wgsl).
@group(0) @binding(4) var<storage, read_write> map_counters: array<atomic<u32>>;

// Most blocks one pixel's band may visit: a band of 2b (b at most MAX_BAND_VOXELS, 2 blocks) is
// L = 4 |ray| blocks long (5 at a Kinect's corners, 8 for a 120° field of view), and a walk
// along a segment L blocks long visits at most √3 L + 3 blocks: 12, and 17; twice that leaves
// room for wider cameras.
const MAP_MAX_BAND_BLOCKS: u32 = 32u;

// Inserts the key of block `b` unless it is present.
fn insert_block(d: VolumeDesc, b: vec3<u32>) {
    let key = block_key(b);
    let mask = d.hash_slots - 1u;
    var s = block_hash(b) & mask;
    for (var i = 0u; i < MAP_MAX_PROBES; i++) {
        let k = atomicLoad(&block_table[2u * s]);
        if k == key {
            if atomicLoad(&block_table[2u * s + 1u]) == SWAPPED_BLOCK {
                atomicAdd(&map_counters[MAP_COUNTER_SWAPPED_HITS], 1u);
            }
            return;
        }
        if k == EMPTY_KEY {
            let r = atomicCompareExchangeWeak(&block_table[2u * s], EMPTY_KEY, key);
            if r.exchanged || r.old_value == key {
                return;
            }
            if r.old_value == EMPTY_KEY {
                // A spurious failure of the weak exchange: try this slot again.
                continue;
            }
        }
        s = (s + 1u) & mask;
    }
    atomicAdd(&map_counters[MAP_COUNTER_HASH_FULL], 1u);
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = params.intrinsics;
    if gid.x >= k.width_px || gid.y >= k.height_px || pose.enabled == 0u {
        return;
    }
    let z = depth_m[gid.y * k.width_px + gid.x];
    if !is_valid_f32(z) {
        return;
    }
    let d = params.volume;
    let ray = back_project(k, f32(gid.x), f32(gid.y), 1.0);
    let origin = vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m);
    // The band's ends in the world.
    let band = truncation_band_m(d, z);
    let near = (pose.world_from_camera * vec4<f32>(ray * max(z - band, 0.0), 1.0)).xyz;
    let far = (pose.world_from_camera * vec4<f32>(ray * (z + band), 1.0)).xyz;
    // The band's ends in block units relative to the anchor's block (small numbers near the
    // camera: the walk keeps f32's precision), the anchor's block added to each cell visited.
    let block_m = f32(1u << BRICK_SHIFT) * d.voxel_size_m;
    let anchor_block = vec3<f32>(voxel_anchor(d) >> vec3<u32>(BRICK_SHIFT));
    let a = (near - origin) / block_m;
    let b = (far - origin) / block_m;
    let dir = b - a;
    var cell = floor(a);
    let last = floor(b);
    let step = sign(dir);
    // Ray parameter (0 at `a`, 1 at `b`) of the next block face along each axis, and between
    // faces; an axis the segment does not move along never advances.
    let moving = abs(dir) > vec3<f32>(1e-12);
    let inv = 1.0 / select(vec3<f32>(1.0), dir, moving);
    var t_next = select(vec3<f32>(1e30), (cell + max(step, vec3<f32>(0.0)) - a) * inv, moving);
    let t_delta = select(vec3<f32>(1e30), abs(inv), moving);
    let n_blocks = vec3<f32>(f32(d.dim_x >> BRICK_SHIFT), f32(d.dim_y >> BRICK_SHIFT), f32(d.dim_z >> BRICK_SHIFT));
    let visits = u32(dot(abs(last - cell), vec3<f32>(1.0))) + 1u;
    for (var i = 0u; i < min(visits, MAP_MAX_BAND_BLOCKS); i++) {
        let in_box = cell + anchor_block;
        if any(in_box < vec3<f32>(0.0)) || any(in_box >= n_blocks) {
            atomicAdd(&map_counters[MAP_COUNTER_OUT_OF_RANGE], 1u);
        } else {
            insert_block(d, vec3<u32>(in_box));
        }
        // Step across the nearest block face.
        if t_next.x <= t_next.y && t_next.x <= t_next.z {
            cell.x += step.x;
            t_next.x += t_delta.x;
        } else if t_next.y <= t_next.z {
            cell.y += step.y;
            t_next.y += t_delta.y;
        } else {
            cell.z += step.z;
            t_next.z += t_delta.z;
        }
    }
}
