// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/map/block_swap_in.wgsl`. Entries run in order, so pool
//! blocks follow entry order; the GPU hands them out in any order: compare by key.

use crate::cpu::shared::{
    BLOCK_VOXELS, MAP_COUNTER_POOL_FULL, MAP_COUNTER_SWAP_IN_REFUSED, NO_BLOCK, SWAPPED_BLOCK,
    block_of_key, find_slot, take_pool_block,
};
use crate::kernels::block_swap_in::BlockSwapInParams;

/// Brings the transfer list's blocks back into the pool, as the kernel's invocations do.
#[expect(clippy::too_many_arguments, reason = "the kernel's bindings, in order")]
pub fn block_swap_in(params: &BlockSwapInParams, block_table: &mut [u32], block_coords: &mut [u32], tsdf_volume: &mut [u32], color_volume: &mut [u32], surface_bricks: &mut [u32], map_counters: &mut [u32], free_blocks: &[u32], swap_transfer: &[u32]) {
    let d = &params.volume;
    let c = params.capacity as usize;
    let n = BLOCK_VOXELS as usize;
    for entry in 0..params.count.min(params.capacity) as usize {
        let key = swap_transfer[entry];
        let Some(slot) = find_slot(block_table, d, block_of_key(key)) else { continue };
        if block_table[2 * slot + 1] != SWAPPED_BLOCK {
            continue;
        }
        let block = take_pool_block(map_counters, free_blocks, d.pool_blocks);
        if block == NO_BLOCK {
            map_counters[MAP_COUNTER_SWAP_IN_REFUSED] += 1;
            map_counters[MAP_COUNTER_POOL_FULL] += 1;
            continue;
        }
        let to = block as usize * n;
        let from = 2 * c + entry * n;
        tsdf_volume[to..to + n].copy_from_slice(&swap_transfer[from..from + n]);
        if params.color_enabled != 0 {
            let from = 2 * c + c * n + entry * n;
            color_volume[to..to + n].copy_from_slice(&swap_transfer[from..from + n]);
        }
        surface_bricks[block as usize] = swap_transfer[c + entry];
        block_coords[block as usize] = key;
        block_table[2 * slot + 1] = block;
    }
}
