// SPDX-License-Identifier: MIT
//! One invocation turns the visible-block count into the indirect dispatch size of
//! `block_integrate`: one workgroup per visible block, at most `max_workgroups` (the device's
//! per-dimension limit; the integration's workgroups stride over the list, so a longer list is
//! still covered). Zero visible blocks dispatch nothing.
#import map

struct BlockListArgsParams {
    // The device's limit on workgroups per dispatch dimension.
    max_workgroups: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: BlockListArgsParams;
// The map's counters (map.wgsl): reads MAP_COUNTER_VISIBLE, writes the arguments at
// MAP_COUNTER_ARGS.
@group(0) @binding(1) var<storage, read_write> map_counters: array<u32>;

@compute @workgroup_size(1, 1, 1)
fn main() {
    map_counters[MAP_COUNTER_ARGS] = min(map_counters[MAP_COUNTER_VISIBLE], params.max_workgroups);
    map_counters[MAP_COUNTER_ARGS + 1u] = 1u;
    map_counters[MAP_COUNTER_ARGS + 2u] = 1u;
}
