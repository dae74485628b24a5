// SPDX-License-Identifier: MIT
//! Each invocation brings one block back from the host (InfiniTAM's swapping): entry `i` of the
//! transfer list (the layout of `block_swap_out`, written by the host) names a key whose hash
//! slot holds SWAPPED_BLOCK; the invocation takes a pool block for it (`take_pool_block`: the
//! free list first), copies the entry's voxel, colour and surface-brick words into it, records
//! the key in `block_coords` and sets the slot's pool index. An entry whose key is not swapped
//! out (absent, or resident again: the host's copy is stale) is skipped. When the pool is
//! exhausted the key stays swapped out (the host keeps its voxels) and the refusal is counted
//! (MAP_COUNTER_SWAP_IN_REFUSED and MAP_COUNTER_POOL_FULL). Runs before a frame's allocation,
//! so the frame fuses into the restored voxels.
#import map_lookup
#import map_pool

struct BlockSwapInParams {
    // The sparse map.
    volume: VolumeDesc,
    // Entries the host wrote this frame.
    count: u32,
    // Entries the transfer list has room for (its layout's C).
    capacity: u32,
    // Whether the map fuses colour (colour words come with the voxels).
    color_enabled: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: BlockSwapInParams;
// The hash table: (key, pool index) per slot.
@group(0) @binding(1) var<storage, read_write> block_table: array<u32>;
// The key of each pool block (EMPTY_KEY: free).
@group(0) @binding(2) var<storage, read_write> block_coords: array<u32>;
// The pool's voxel words.
@group(0) @binding(3) var<storage, read_write> tsdf_volume: array<u32>;
// The pool's colour words (a placeholder word without colour).
@group(0) @binding(4) var<storage, read_write> color_volume: array<u32>;
// One word per pool block: non-zero once a voxel in it held a TSDF below FAR_TSDF.
@group(0) @binding(5) var<storage, read_write> surface_bricks: array<u32>;
// The map's counters (map.wgsl).
@group(0) @binding(6) var<storage, read_write> map_counters: array<atomic<u32>>;
// The free list (MAP_COUNTER_FREE blocks).
@group(0) @binding(7) var<storage, read> free_blocks: array<u32>;
// The transfer list the host filled (block_swap_out's layout).
@group(0) @binding(8) var<storage, read> swap_transfer: array<u32>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let entry = gid.x;
    if entry >= min(params.count, params.capacity) {
        return;
    }
    let d = params.volume;
    let c = params.capacity;
    let key = swap_transfer[entry];
    let b = block_of_key(key);
    let slot = find_slot(d, b, key);
    if slot == NO_SLOT || block_table[2u * slot + 1u] != SWAPPED_BLOCK {
        return;
    }
    let block = take_pool_block(d.pool_blocks);
    if block == NO_BLOCK {
        atomicAdd(&map_counters[MAP_COUNTER_SWAP_IN_REFUSED], 1u);
        atomicAdd(&map_counters[MAP_COUNTER_POOL_FULL], 1u);
        return;
    }
    let dst = block * BLOCK_VOXELS;
    let src = 2u * c + entry * BLOCK_VOXELS;
    for (var v = 0u; v < BLOCK_VOXELS; v++) {
        tsdf_volume[dst + v] = swap_transfer[src + v];
    }
    if params.color_enabled != 0u {
        let src_color = 2u * c + c * BLOCK_VOXELS + entry * BLOCK_VOXELS;
        for (var v = 0u; v < BLOCK_VOXELS; v++) {
            color_volume[dst + v] = swap_transfer[src_color + v];
        }
    }
    surface_bricks[block] = swap_transfer[c + entry];
    block_coords[block] = key;
    block_table[2u * slot + 1u] = block;
}
