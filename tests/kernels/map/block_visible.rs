// SPDX-License-Identifier: MIT
//! `block_visible`: the blocks a real frame allocated, seen from the pose they were fused at,
//! from a pose turned half away, from behind and from a pose backed away so that the frame's
//! surface hides blocks: the GPU lists exactly the twin's set (in any order), each once; blocks
//! past the used count are never listed; a turned-away camera sees fewer; a disabled pose lists
//! nothing; blocks on the free list are skipped; a frame without depth lists nothing. What the
//! depth tiles drop changes no voxel: integrating every block in the frustum and integrating
//! the listed ones give the same map, word for word.

use std::collections::BTreeSet;

use glam::{DQuat, DVec3};
use webfusion_core::cpu::{self, shared::{MAP_COUNTER_VISIBLE, MAP_COUNTERS, NO_DEPTH_TILE}};
use webfusion_core::kernels::GpuIntrinsics;
use webfusion_core::kernels::block_integrate::BlockIntegrateParams;
use webfusion_core::kernels::block_visible::{BlockVisibleParams, CameraPose};
use webfusion_core::{PinholeIntrinsics, Se3};
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

use super::scene::{POOL_BLOCKS, camera_pose, cpu_map, depth_tiles, frame, poses, sparse_desc, visible_params};

/// The twin's visible list.
fn twin_list(p: &BlockVisibleParams, pose: &CameraPose, coords: &[u32], counters: &[u32], tile_max_m: &[f32]) -> Vec<u32> {
    let (mut c_counters, mut c_list) = (counters.to_vec(), vec![0u32; p.volume.pool_blocks as usize]);
    cpu::block_visible(p, pose, coords, &mut c_counters, &mut c_list, tile_max_m);
    c_list.truncate(c_counters[MAP_COUNTER_VISIBLE] as usize);
    c_list
}

/// The map both poses of the real frame allocate, with the visibility parameters and the
/// frame's depth tiles.
struct Scene {
    desc: webfusion_core::tsdf::VolumeDesc,
    k: PinholeIntrinsics,
    depth: &'static [f32],
    coords: Vec<u32>,
    counters: Vec<u32>,
    p: BlockVisibleParams,
    tile_max_m: Vec<f32>,
}

fn scene() -> Scene {
    let desc = sparse_desc(POOL_BLOCKS);
    let (k, depth) = frame();
    let (_, coords, mut counters) = cpu_map(&desc, &poses());
    counters[MAP_COUNTER_VISIBLE] = 0;
    let p = visible_params(desc, k);
    let tile_max_m = depth_tiles(&k, depth);
    Scene { desc, k, depth, coords, counters, p, tile_max_m }
}

/// (GPU, CPU) visible sets.
fn run(p: &BlockVisibleParams, pose: &CameraPose, coords: &[u32], counters: &[u32], tile_max_m: &[f32]) -> (Vec<u32>, BTreeSet<u32>) {
    let gpu = gpu();
    let n = p.volume.pool_blocks as usize;
    let slots = [Slot::In(bytemuck::bytes_of(pose)), Slot::In(bytemuck::cast_slice(coords)), Slot::InOut(bytemuck::cast_slice(counters)), Slot::Out(4 * n), Slot::In(bytemuck::cast_slice(tile_max_m))];
    let out = run_kernel_slots(&gpu, &gpu.kernels.block_visible, p, &slots, [p.volume.pool_blocks, 1, 1]);
    finish(&gpu);
    let (g_counters, g_list): (Vec<u32>, Vec<u32>) = (cast(&out[0]), cast(&out[1]));
    let c: BTreeSet<u32> = twin_list(p, pose, coords, counters, tile_max_m).into_iter().collect();
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
    let Scene { desc, k: _, depth: _, coords, counters, p, tile_max_m } = scene();
    let used = counters[0];
    let turned = Se3::new(DQuat::from_rotation_y(0.6), DVec3::new(0.1, 0.0, -0.2));
    let behind = Se3::new(DQuat::from_rotation_y(std::f64::consts::PI), DVec3::ZERO);
    let backed = Se3::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, -0.4));
    let mut seen = Vec::new();
    for (what, pose) in [("fused pose", poses()[1]), ("turned", turned), ("behind", behind), ("backed away", backed)] {
        let (g, c) = run(&p, &camera_pose(&pose), &coords, &counters, &tile_max_m);
        let g = as_set(&g).unwrap_or_else(|e| panic!("{what}: {e}"));
        assert_eq!(g, c, "{what}: GPU vs twin");
        assert!(g.iter().all(|&b| b < used), "{what}: only used blocks are listed");
        eprintln!("{what}: {} of {used} blocks visible", g.len());
        seen.push(g.len());
    }
    assert!(seen[0] as u32 > used * 8 / 10, "most blocks fused from here and nearby are visible from here ({} of {used})", seen[0]);
    // Every block a frame allocates lies within the truncation band of a pixel it projects
    // onto: from the pose it was allocated at, with that frame's depth, all are listed.
    let (_, own_coords, mut own_counters) = cpu_map(&desc, &poses()[..1]);
    own_counters[MAP_COUNTER_VISIBLE] = 0;
    let (g, c) = run(&p, &camera_pose(&poses()[0]), &own_coords, &own_counters, &tile_max_m);
    assert_eq!(as_set(&g).expect("each block once"), c, "own frame: GPU vs twin");
    assert_eq!(c.len() as u32, own_counters[0], "every block a frame allocates is visible from its pose with its depth");
    assert!(seen[1] < seen[0], "a turned camera sees fewer blocks");
    assert_eq!(seen[2], 0, "a camera facing away sees none");
    assert!(seen[3] < seen[0], "backed away, the frame's surface hides blocks behind it ({} of {})", seen[3], seen[0]);
    let (none, _) = run(&p, &camera_pose(&poses()[1]), &coords, &counters, &vec![NO_DEPTH_TILE; tile_max_m.len()]);
    assert!(none.is_empty(), "a frame without depth lists nothing");
    // Negative control: a block listed twice is caught.
    assert!(as_set(&[3, 5, 3]).is_err(), "a duplicate is caught");
    let (disabled, _) = run(&p, &webfusion_core::fusion::predictor::camera_pose(None), &coords, &counters, &tile_max_m);
    assert!(disabled.is_empty(), "a disabled pose lists nothing");
    let mut none_used = counters.clone();
    none_used[0] = 0;
    let (g, _) = run(&p, &camera_pose(&poses()[1]), &coords, &none_used, &tile_max_m);
    assert!(g.is_empty(), "no used block, nothing listed");
    let _ = MAP_COUNTERS;
    // Blocks on the free list (swapped out: EMPTY_KEY) are never listed, where they would be
    // visible if they held their key.
    let (all, _) = run(&p, &camera_pose(&poses()[1]), &coords, &counters, &tile_max_m);
    let freed: BTreeSet<u32> = all.iter().copied().step_by(3).collect();
    let mut with_free = coords.clone();
    for &b in &freed {
        with_free[b as usize] = webfusion_core::cpu::shared::EMPTY_KEY;
    }
    let (g, c) = run(&p, &camera_pose(&poses()[1]), &with_free, &counters, &tile_max_m);
    let g = as_set(&g).expect("each block once");
    assert_eq!(g, c, "with free blocks: GPU vs twin");
    assert!(g.is_disjoint(&freed) && g.len() + freed.len() == all.len(), "exactly the free blocks drop out ({} of {})", freed.len(), all.len());
}

/// Integrates `depth` at `pose` into a copy of `voxels` over the blocks of `list` (the twins),
/// the map's blocks keyed by `coords` (`counters` its counters).
fn integrated(desc: webfusion_core::tsdf::VolumeDesc, k: PinholeIntrinsics, pose: &CameraPose, depth: &[f32], (coords, counters): (&[u32], &[u32]), list: &[u32], voxels: &[u32]) -> Vec<u32> {
    let p = BlockIntegrateParams { volume: desc, intrinsics: GpuIntrinsics::from(k), color_enabled: 0, ..Default::default() };
    let mut voxels = voxels.to_vec();
    let (mut colors, mut surface) = (vec![0u32; 1], vec![0u32; desc.pool_blocks as usize]);
    let mut c = counters.to_vec();
    c[MAP_COUNTER_VISIBLE] = list.len() as u32;
    let color = vec![[0.0f32; 4]; depth.len()];
    cpu::block_integrate(&p, pose, depth, &color, &mut voxels, &mut colors, &mut surface, coords, list, &c);
    voxels
}

#[test]
fn the_blocks_dropped_for_occlusion_take_no_update() {
    let Scene { desc, k, depth, coords, counters, p, tile_max_m } = scene();
    // Every block in the frustum: tiles deeper than any block.
    let unbounded = vec![1e4f32; tile_max_m.len()];
    // The map as fused at both poses (the twins), so the voxels hold a surface to change.
    let all: Vec<u32> = (0..counters[0]).collect();
    let mut voxels = vec![0u32; desc.pool_blocks as usize * 512];
    for pose in poses() {
        voxels = integrated(desc, k, &camera_pose(&pose), depth, (&coords, &counters), &all, &voxels);
    }
    let backed = Se3::new(DQuat::IDENTITY, DVec3::new(0.0, 0.0, -0.4));
    let turned = Se3::new(DQuat::from_rotation_y(0.3), DVec3::new(0.1, 0.05, -0.25));
    let mut dropped_total = 0;
    for (what, pose) in [("fused pose", poses()[1]), ("backed away", backed), ("turned", turned)] {
        let pose = camera_pose(&pose);
        let frustum = twin_list(&p, &pose, &coords, &counters, &unbounded);
        let listed = twin_list(&p, &pose, &coords, &counters, &tile_max_m);
        assert!(listed.iter().all(|b| frustum.contains(b)), "{what}: the depth bound only drops blocks");
        let full = integrated(desc, k, &pose, depth, (&coords, &counters), &frustum, &voxels);
        let culled = integrated(desc, k, &pose, depth, (&coords, &counters), &listed, &voxels);
        let differ = full.iter().zip(&culled).filter(|(a, b)| a != b).count();
        assert_eq!(differ, 0, "{what}: integrating the {} listed blocks, not all {} in the frustum, changed {differ} voxel words", listed.len(), frustum.len());
        let changed = full.iter().zip(&voxels).filter(|(a, b)| a != b).count();
        assert!(changed > 10_000, "{what}: the frame updates the map ({changed} voxel words)");
        eprintln!("{what}: {} of {} frustum blocks listed; {changed} voxel words updated", listed.len(), frustum.len());
        dropped_total += frustum.len() - listed.len();
    }
    assert!(dropped_total > 0, "some block is hidden behind the surface from one of the poses");
    // Negative control: dropping a block the frame does update is caught by the comparison.
    let pose = camera_pose(&poses()[1]);
    let frustum = twin_list(&p, &pose, &coords, &counters, &unbounded);
    let full = integrated(desc, k, &pose, depth, (&coords, &counters), &frustum, &voxels);
    let updated = frustum.iter().copied().find(|&b| (b as usize * 512..(b as usize + 1) * 512).any(|i| full[i] != voxels[i])).expect("a block the frame updates");
    let fewer: Vec<u32> = frustum.iter().copied().filter(|&b| b != updated).collect();
    let short = integrated(desc, k, &pose, depth, (&coords, &counters), &fewer, &voxels);
    assert!(full.iter().zip(&short).any(|(a, b)| a != b), "leaving out an updated block shows in the voxels");
}
