// SPDX-License-Identifier: MIT
//! Each invocation looks at one pool block of a sparse map and, when it lies outside the region
//! the camera may see soon (InfiniTAM's swapping: blocks far from the frustum go to host memory),
//! moves it to the transfer list for the host: its key, its surface-brick word, its voxel words
//! and its colour words are copied to the next free entry (atomicAdd on
//! MAP_COUNTER_SWAPPED_OUT; at most `capacity` entries, a block past them stays for a later
//! frame), then the block is cleared and pushed onto the free list, its `block_coords` entry set
//! to EMPTY_KEY and its hash slot's pool index to SWAPPED_BLOCK (the key stays in the table: it
//! is neither allocated afresh nor read until `block_swap_in` brings it back).
//!
//! The kept region, around the camera at `pose`: within `keep_near_m` of its centre (a turn
//! brings it into view at once), or within `keep_range_m` and inside the cone of half-angle
//! acos(`keep_cos_half_angle`) about its optical axis; each test is widened by the block's
//! half-diagonal, so a block is kept when any part of it may be. Nothing moves when the pose is
//! disabled (a lost frame) or `capacity` is 0. The transfer list's order depends on the order
//! invocations run; its set does not. Pushes onto the free list happen only here, pops only in
//! other dispatches (`take_pool_block`).
//!
//! Transfer layout, for capacity C: keys [0, C), surface-brick words [C, 2C), voxel words of
//! entry i at 2C + 512 i, colour words of entry i at 2C + 512 C + 512 i (with colour).
#import camera_pose
#import map_lookup

struct BlockSwapOutParams {
    // The sparse map.
    volume: VolumeDesc,
    // Entries of the transfer list (0: swap nothing).
    capacity: u32,
    // Whether the map fuses colour (colour words move with the voxels).
    color_enabled: u32,
    // Radius around the camera centre that is always kept, metres.
    keep_near_m: f32,
    // Farthest distance from the camera centre kept inside the cone, metres.
    keep_range_m: f32,
    // Cosine of the kept cone's half-angle about the optical axis.
    keep_cos_half_angle: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: BlockSwapOutParams;
// The camera pose of this frame.
@group(0) @binding(1) var<uniform> pose: CameraPose;
// The hash table: (key, pool index) per slot.
@group(0) @binding(2) var<storage, read_write> block_table: array<u32>;
// The key of each pool block (EMPTY_KEY: free).
@group(0) @binding(3) var<storage, read_write> block_coords: array<u32>;
// The pool's voxel words.
@group(0) @binding(4) var<storage, read_write> tsdf_volume: array<u32>;
// The pool's colour words (a placeholder word without colour).
@group(0) @binding(5) var<storage, read_write> color_volume: array<u32>;
// One word per pool block: non-zero once a voxel in it held a TSDF below FAR_TSDF.
@group(0) @binding(6) var<storage, read_write> surface_bricks: array<u32>;
// The map's counters (map.wgsl).
@group(0) @binding(7) var<storage, read_write> map_counters: array<atomic<u32>>;
// The free list (MAP_COUNTER_FREE blocks; room for every pool block).
@group(0) @binding(8) var<storage, read_write> free_blocks: array<u32>;
// Out: the transfer list (layout above).
@group(0) @binding(9) var<storage, read_write> swap_transfer: array<u32>;

// Whether a block whose centre is `v` from the camera centre (world metres, `axis` the unit
// optical axis) lies in the kept region, each test widened by `radius_m`.
fn in_kept_region(v: vec3<f32>, axis: vec3<f32>, radius_m: f32) -> bool {
    let dist = length(v);
    if dist <= params.keep_near_m + radius_m {
        return true;
    }
    return dist <= params.keep_range_m + radius_m && dot(v, axis) + radius_m >= dist * params.keep_cos_half_angle;
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let block = gid.x;
    if params.capacity == 0u || pose.enabled == 0u || block >= atomicLoad(&map_counters[MAP_COUNTER_BLOCKS_USED]) {
        return;
    }
    let key = block_coords[block];
    if key == EMPTY_KEY {
        return;
    }
    let d = params.volume;
    let b = block_of_key(key);
    let edge_m = f32(1u << BRICK_SHIFT) * d.voxel_size_m;
    let centre_voxel = vec3<f32>(vec3<i32>(b << vec3<u32>(BRICK_SHIFT)) - vec3<i32>(voxel_anchor(d))) + vec3<f32>(0.5 * f32(1u << BRICK_SHIFT));
    let centre = vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m) + centre_voxel * d.voxel_size_m;
    let camera = pose.world_from_camera[3].xyz;
    let axis = pose.world_from_camera[2].xyz;
    if in_kept_region(centre - camera, axis, 0.5 * sqrt(3.0) * edge_m) {
        return;
    }
    let entry = atomicAdd(&map_counters[MAP_COUNTER_SWAPPED_OUT], 1u);
    if entry >= params.capacity {
        atomicSub(&map_counters[MAP_COUNTER_SWAPPED_OUT], 1u);
        return;
    }
    let c = params.capacity;
    swap_transfer[entry] = key;
    swap_transfer[c + entry] = surface_bricks[block];
    surface_bricks[block] = 0u;
    let src = block * BLOCK_VOXELS;
    let dst = 2u * c + entry * BLOCK_VOXELS;
    for (var v = 0u; v < BLOCK_VOXELS; v++) {
        swap_transfer[dst + v] = tsdf_volume[src + v];
        tsdf_volume[src + v] = 0u;
    }
    if params.color_enabled != 0u {
        let dst_color = 2u * c + c * BLOCK_VOXELS + entry * BLOCK_VOXELS;
        for (var v = 0u; v < BLOCK_VOXELS; v++) {
            swap_transfer[dst_color + v] = color_volume[src + v];
            color_volume[src + v] = 0u;
        }
    }
    block_coords[block] = EMPTY_KEY;
    let slot = find_slot(d, b, key);
    if slot != NO_SLOT {
        block_table[2u * slot + 1u] = SWAPPED_BLOCK;
    }
    free_blocks[atomicAdd(&map_counters[MAP_COUNTER_FREE], 1u)] = block;
}
