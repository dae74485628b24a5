// SPDX-License-Identifier: MIT
// Taking a block from a sparse map's pool: the importing kernel declares
// `map_counters: array<atomic<u32>>` and `free_blocks: array<u32>` (the free list: blocks that
// were swapped out and cleared). Mirrors core/src/cpu/shared.rs::take_pool_block.
#import map

// A cleared pool block for a new key, or NO_BLOCK when the pool is exhausted: the top of the
// free list if it has one, else the next block of the bump allocation. Only call it from a
// dispatch that pushes nothing onto the free list: then a pop that finds the list empty (the
// count wrapped below zero or read zero) gives its decrement back, the count never exceeds the
// blocks really left, and no two invocations take the same block, however they interleave.
// A bump past the pool is given back too: the counter ends at the pool size.
fn take_pool_block(pool_blocks: u32) -> u32 {
    if atomicLoad(&map_counters[MAP_COUNTER_FREE]) != 0u {
        let free = atomicSub(&map_counters[MAP_COUNTER_FREE], 1u);
        if free >= 1u && free <= pool_blocks {
            return free_blocks[free - 1u];
        }
        atomicAdd(&map_counters[MAP_COUNTER_FREE], 1u);
    }
    let block = atomicAdd(&map_counters[MAP_COUNTER_BLOCKS_USED], 1u);
    if block >= pool_blocks {
        atomicSub(&map_counters[MAP_COUNTER_BLOCKS_USED], 1u);
        return NO_BLOCK;
    }
    return block;
}
