// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/map/block_assign.wgsl`. Slots run in order, so pool indices
//! follow slot order (after the free list's, popped from its top); the GPU hands them out in any order: compare by key.

use crate::cpu::shared::{EMPTY_KEY, MAP_COUNTER_POOL_FULL, NO_BLOCK, take_pool_block};
use crate::kernels::block_assign::BlockAssignParams;

/// Gives every key without a block the next pool block, as the kernel's invocations do.
pub fn block_assign(params: &BlockAssignParams, block_table: &mut [u32], block_coords: &mut [u32], map_counters: &mut [u32], free_blocks: &[u32]) {
    let d = &params.volume;
    for s in 0..d.hash_slots as usize {
        if block_table[2 * s] == EMPTY_KEY || block_table[2 * s + 1] != NO_BLOCK {
            continue;
        }
        let block = take_pool_block(map_counters, free_blocks, d.pool_blocks);
        if block == NO_BLOCK {
            map_counters[MAP_COUNTER_POOL_FULL] += 1;
            continue;
        }
        block_table[2 * s + 1] = block;
        block_coords[block as usize] = block_table[2 * s];
    }
}
