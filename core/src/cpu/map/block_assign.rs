// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/map/block_assign.wgsl`. Slots run in order, so pool indices
//! follow slot order; the GPU hands them out in any order: compare by key.

use crate::cpu::shared::{EMPTY_KEY, MAP_COUNTER_BLOCKS_USED, MAP_COUNTER_POOL_FULL, NO_BLOCK};
use crate::kernels::block_assign::BlockAssignParams;

/// Gives every key without a block the next pool block, as the kernel's invocations do.
pub fn block_assign(params: &BlockAssignParams, block_table: &mut [u32], block_coords: &mut [u32], map_counters: &mut [u32]) {
    let d = &params.volume;
    for s in 0..d.hash_slots as usize {
        if block_table[2 * s] == EMPTY_KEY || block_table[2 * s + 1] != NO_BLOCK {
            continue;
        }
        let block = map_counters[MAP_COUNTER_BLOCKS_USED];
        if block >= d.pool_blocks {
            map_counters[MAP_COUNTER_POOL_FULL] += 1;
            continue;
        }
        map_counters[MAP_COUNTER_BLOCKS_USED] += 1;
        block_table[2 * s + 1] = block;
        block_coords[block as usize] = block_table[2 * s];
    }
}
