// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/map/block_list_args.wgsl`.

use crate::cpu::shared::{MAP_COUNTER_ARGS, MAP_COUNTER_VISIBLE};
use crate::kernels::block_list_args::BlockListArgsParams;

/// Writes `block_integrate`'s dispatch size after the visible count.
pub fn block_list_args(params: &BlockListArgsParams, map_counters: &mut [u32]) {
    map_counters[MAP_COUNTER_ARGS] = map_counters[MAP_COUNTER_VISIBLE].min(params.max_workgroups);
    map_counters[MAP_COUNTER_ARGS + 1] = 1;
    map_counters[MAP_COUNTER_ARGS + 2] = 1;
}
