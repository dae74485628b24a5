// SPDX-License-Identifier: MIT
//! Each invocation looks at one slot of a sparse map's hash table and, when it holds a key
//! without a block (inserted by `block_alloc` since the last assignment, or refused a block
//! before because the pool was full), takes a pool block for it (`take_pool_block`: the free
//! list first, then the next block of the bump allocation). When the pool is exhausted it
//! counts the refusal in MAP_COUNTER_POOL_FULL; the key stays in the table without a block, so
//! it reads as unobserved and never aliases another block's voxels. A key swapped out to the
//! host (SWAPPED_BLOCK) is left alone: `block_swap_in` brings its own voxels back. The new
//! block's key is recorded in `block_coords` (its voxels are clear: never written since the map
//! was reset, or cleared when swapped out: a new block is unobserved).
#import map
#import map_pool

struct BlockAssignParams {
    // The sparse map.
    volume: VolumeDesc,
}

@group(0) @binding(0) var<uniform> params: BlockAssignParams;
// The hash table: (key, pool index) per slot.
@group(0) @binding(1) var<storage, read_write> block_table: array<u32>;
// The key of each pool block in use.
@group(0) @binding(2) var<storage, read_write> block_coords: array<u32>;
// The map's counters (map.wgsl).
@group(0) @binding(3) var<storage, read_write> map_counters: array<atomic<u32>>;
// The free list (MAP_COUNTER_FREE blocks).
@group(0) @binding(4) var<storage, read> free_blocks: array<u32>;

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let d = params.volume;
    let s = gid.x;
    if s >= d.hash_slots {
        return;
    }
    if block_table[2u * s] == EMPTY_KEY || block_table[2u * s + 1u] != NO_BLOCK {
        return;
    }
    let block = take_pool_block(d.pool_blocks);
    if block == NO_BLOCK {
        atomicAdd(&map_counters[MAP_COUNTER_POOL_FULL], 1u);
        return;
    }
    block_table[2u * s + 1u] = block;
    block_coords[block] = block_table[2u * s];
}
