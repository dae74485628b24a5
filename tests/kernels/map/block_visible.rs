// SPDX-License-Identifier: MIT
//! `block_visible`: the blocks a real frame allocated, seen from the pose they were fused at,
//! from a pose turned half away and from behind: the GPU lists exactly the twin's set (in any
//! order), each once; blocks past the used count are never listed; a turned-away camera sees
//! fewer; a disabled pose lists nothing; blocks on the free list are skipped.

use std::collections::BTreeSet;

use glam::{DQuat, DVec3};
use webfusion_core::cpu::{self, shared::{MAP_COUNTER_VISIBLE, MAP_COUNTERS}};
use webfusion_core::kernels::GpuIntrinsics;
use webfusion_core::kernels::block_visible::{BlockVisibleParams, CameraPose};
use webfusion_core::Se3;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

use super::scene::{POOL_BLOCKS, camera_pose, cpu_map, frame, poses, sparse_desc};

/// (GPU, CPU) visible sets.
fn run(p: &BlockVisibleParams, pose: &CameraPose, coords: &[u32], counters: &[u32]) -> (Vec<u32>, BTreeSet<u32>) {
    let gpu = gpu();
    let n = p.volume.pool_blocks as usize;
    let slots = [Slot::In(bytemuck::bytes_of(pose)), Slot::In(bytemuck::cast_slice(coords)), Slot::InOut(bytemuck::cast_slice(counters)), Slot::Out(4 * n)];
    let out = run_kernel_slots(&gpu, &gpu.kernels.block_visible, p, &slots, [p.volume.pool_blocks, 1, 1]);
    finish(&gpu);
    let (g_counters, g_list): (Vec<u32>, Vec<u32>) = (cast(&out[0]), cast(&out[1]));
    let (mut c_counters, mut c_list) = (counters.to_vec(), vec![0u32; n]);
    cpu::block_visible(p, pose, coords, &mut c_counters, &mut c_list);
    let c: BTreeSet<u32> = c_list[..c_counters[MAP_COUNTER_VISIBLE] as usize].iter().copied().collect();
    (g_list[..g_counters[MAP_COUNTER_VISIBLE] as usize].to_vec(), c)
}

/// The listed blocks as a set, if none is listed twice.
fn as_set(list: &[u32]) -> Result<BTreeSet<u32>, String> {
    let set: BTreeSet<u32> = list.iter().copied().collect();
    if set.len() != list.len() {
        return Err(format!("{} blocks listed twice", list.len() - set.len()));
    }
    Ok(set)
}

#[test]
fn the_gpu_lists_the_twins_blocks() {
    let desc = sparse_desc(POOL_BLOCKS);
    let (k, _) = frame();
    let (_, coords, mut counters) = cpu_map(&desc, &poses());
    counters[MAP_COUNTER_VISIBLE] = 0;
    let used = counters[0];
    let p = BlockVisibleParams { volume: desc, intrinsics: GpuIntrinsics::from(k), max_depth_m: 5.0, ..Default::default() };
    let turned = Se3::new(DQuat::from_rotation_y(0.6), DVec3::new(0.1, 0.0, -0.2));
    let behind = Se3::new(DQuat::from_rotation_y(std::f64::consts::PI), DVec3::ZERO);
    let mut seen = Vec::new();
    for (what, pose) in [("fused pose", poses()[1]), ("turned", turned), ("behind", behind)] {
        let (g, c) = run(&p, &camera_pose(&pose), &coords, &counters);
        let g = as_set(&g).unwrap_or_else(|e| panic!("{what}: {e}"));
        assert_eq!(g, c, "{what}: GPU vs twin");
        assert!(g.iter().all(|&b| b < used), "{what}: only used blocks are listed");
        eprintln!("{what}: {} of {used} blocks visible", g.len());
        seen.push(g.len());
    }
    assert!(seen[0] as u32 > used * 9 / 10, "nearly every block fused from here is visible from here ({} of {used})", seen[0]);
    assert!(seen[1] < seen[0], "a turned camera sees fewer blocks");
    assert_eq!(seen[2], 0, "a camera facing away sees none");
    // Negative control: a block listed twice is caught.
    assert!(as_set(&[3, 5, 3]).is_err(), "a duplicate is caught");
    let (disabled, _) = run(&p, &webfusion_core::fusion::predictor::camera_pose(None), &coords, &counters);
    assert!(disabled.is_empty(), "a disabled pose lists nothing");
    let mut none_used = counters.clone();
    none_used[0] = 0;
    let (g, _) = run(&p, &camera_pose(&poses()[1]), &coords, &none_used);
    assert!(g.is_empty(), "no used block, nothing listed");
    let _ = MAP_COUNTERS;
    // Blocks on the free list (swapped out: EMPTY_KEY) are never listed, where they would be
    // visible if they held their key.
    let (all, _) = run(&p, &camera_pose(&poses()[1]), &coords, &counters);
    let freed: BTreeSet<u32> = all.iter().copied().step_by(3).collect();
    let mut with_free = coords.clone();
    for &b in &freed {
        with_free[b as usize] = webfusion_core::cpu::shared::EMPTY_KEY;
    }
    let (g, c) = run(&p, &camera_pose(&poses()[1]), &with_free, &counters);
    let g = as_set(&g).expect("each block once");
    assert_eq!(g, c, "with free blocks: GPU vs twin");
    assert!(g.is_disjoint(&freed) && g.len() + freed.len() == all.len(), "exactly the free blocks drop out ({} of {})", freed.len(), all.len());
}
