// SPDX-License-Identifier: MIT
//! `block_list_args`: the visible count becomes one workgroup per block, capped at the device's
//! per-dimension limit, zero for an empty list; the other counters are untouched; as the twin.

use webfusion_core::cpu::{self, shared::{MAP_COUNTER_ARGS, MAP_COUNTER_VISIBLE, MAP_COUNTERS}};
use webfusion_core::kernels::block_list_args::BlockListArgsParams;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

#[test]
fn the_visible_count_sizes_the_dispatch() {
    let gpu = gpu();
    let p = BlockListArgsParams { max_workgroups: 65535, ..Default::default() };
    for (visible, want) in [(0u32, 0u32), (1, 1), (4321, 4321), (65535, 65535), (100_000, 65535)] {
        let mut counters: Vec<u32> = (0..MAP_COUNTERS as u32).map(|i| 0xdead_0000 + i).collect();
        counters[MAP_COUNTER_VISIBLE] = visible;
        let out = run_kernel_slots(&gpu, &gpu.kernels.block_list_args, &p, &[Slot::InOut(bytemuck::cast_slice(&counters))], [1, 1, 1]);
        let g: Vec<u32> = cast(&out[0]);
        let mut c = counters.clone();
        cpu::block_list_args(&p, &mut c);
        assert_eq!(g, c, "{visible} visible: GPU vs twin");
        assert_eq!(&g[MAP_COUNTER_ARGS..MAP_COUNTER_ARGS + 3], &[want, 1, 1], "{visible} visible blocks");
        assert_eq!(&g[..MAP_COUNTER_ARGS], &counters[..MAP_COUNTER_ARGS], "the counters are untouched");
    }
    finish(&gpu);
}
