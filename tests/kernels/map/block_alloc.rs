// SPDX-License-Identifier: MIT
//! `block_alloc`: on a real Kinect frame at two poses, the GPU inserts exactly the block keys
//! the CPU twin does (compared as sets: the slots depend on invocation order), each once, every
//! key findable by the lookup the reading kernels use, also for bands widened by the noise model
//! up to their 16-voxel cap; every voxel the integration can bring
//! below a TSDF of 1 lies in an allocated block; a table too small for the frame fills up and
//! counts the refused insertions without losing or duplicating a key; a disabled pose inserts
//! nothing.

use std::collections::BTreeSet;

use webfusion_core::cpu::{self, shared::{MAP_COUNTER_HASH_FULL, MAP_COUNTER_OUT_OF_RANGE, block_of_key, find_block}};
use webfusion_core::kernels::block_alloc::BlockAllocParams;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

use super::scene::{POOL_BLOCKS, alloc_params, camera_pose, empty_table, frame, keys, poses, sparse_desc};

/// GPU (table, counters) after allocating the frame at `pose` into `table`.
fn run(p: &BlockAllocParams, pose: &webfusion_core::kernels::block_alloc::CameraPose, depth: &[f32], table: &[u32], counters: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let k = p.intrinsics;
    let slots = [Slot::In(bytemuck::bytes_of(pose)), Slot::In(bytemuck::cast_slice(depth)), Slot::InOut(bytemuck::cast_slice(table)), Slot::InOut(bytemuck::cast_slice(counters))];
    let out = run_kernel_slots(&gpu, &gpu.kernels.block_alloc, p, &slots, [k.width_px, k.height_px, 1]);
    finish(&gpu);
    (cast(&out[0]), cast(&out[1]))
}

/// Whether two tables hold the same keys, each once.
fn same_keys(gpu: &[u32], cpu: &[u32]) -> Result<usize, String> {
    let all: Vec<u32> = gpu.chunks(2).map(|s| s[0]).filter(|&k| k != webfusion_core::cpu::shared::EMPTY_KEY).collect();
    let set: BTreeSet<u32> = all.iter().copied().collect();
    if set.len() != all.len() {
        return Err(format!("{} keys inserted twice", all.len() - set.len()));
    }
    let want = keys(cpu);
    if set != want {
        return Err(format!("{} keys missing, {} extra", want.difference(&set).count(), set.difference(&want).count()));
    }
    Ok(set.len())
}

/// The real frame allocated at each of the poses in turn into one table, on the GPU and by the
/// twin: per pose, the GPU's (table, counters), the twin's table and the number of keys (the
/// GPU's keys checked to be the twin's, each once).
fn allocate_at_the_poses(desc: &webfusion_core::tsdf::VolumeDesc) -> Vec<(Vec<u32>, Vec<u32>, Vec<u32>, usize)> {
    let (k, depth) = frame();
    let (mut g_table, mut g_counters) = empty_table(desc);
    let (mut c_table, mut c_counters) = empty_table(desc);
    let mut out = Vec::new();
    for (i, pose) in poses().iter().enumerate() {
        let p = alloc_params(*desc, k);
        (g_table, g_counters) = run(&p, &camera_pose(pose), depth, &g_table, &g_counters);
        cpu::block_alloc(&p, &camera_pose(pose), depth, &mut c_table, &mut c_counters);
        let n = same_keys(&g_table, &c_table).unwrap_or_else(|e| panic!("pose {i}: {e}"));
        out.push((g_table.clone(), g_counters.clone(), c_table.clone(), n));
    }
    out
}

#[test]
fn the_gpu_inserts_the_twins_keys_each_once() {
    let desc = sparse_desc(POOL_BLOCKS);
    for (i, (g_table, g_counters, c_table, n)) in allocate_at_the_poses(&desc).into_iter().enumerate() {
        eprintln!("pose {i}: {n} blocks allocated");
        assert!(n > 200 && n < POOL_BLOCKS as usize / 4, "a frame allocates a few hundred 16 cm blocks ({n})");
        assert_eq!(g_counters[MAP_COUNTER_HASH_FULL], 0, "the table has room");
        assert_eq!(g_counters[MAP_COUNTER_OUT_OF_RANGE], 0, "the frame lies in the box");
        for key in keys(&g_table) {
            let mut found = g_table.clone();
            // Lookups find every key (the value is still NO_BLOCK before assignment: mark it).
            for s in found.chunks_mut(2) {
                if s[0] == key {
                    s[1] = 7;
                }
            }
            assert_eq!(find_block(&found, &desc, block_of_key(key)), 7, "key {key:#x} is found by probing from its hash");
        }
        // Negative controls: a dropped key and a duplicated one are caught.
        let mut dropped = g_table.clone();
        let slot = dropped.chunks(2).position(|s| s[0] != webfusion_core::cpu::shared::EMPTY_KEY).expect("a key");
        let key = dropped[2 * slot];
        dropped[2 * slot] = webfusion_core::cpu::shared::EMPTY_KEY;
        assert!(same_keys(&dropped, &c_table).is_err(), "a missing key is caught");
        let empty = dropped.chunks(2).enumerate().filter(|(s, _)| *s != slot).find(|(_, e)| e[0] == webfusion_core::cpu::shared::EMPTY_KEY).map(|(s, _)| s).expect("an empty slot");
        let mut twice = g_table.clone();
        twice[2 * empty] = key;
        assert!(same_keys(&twice, &c_table).is_err(), "a key inserted twice is caught");
    }
}

#[test]
fn the_gpu_walks_bands_wider_than_mu_as_the_twin_does() {
    // 8σ of the Kinect model: bands up to 16 voxels (2 blocks) either side on the far wall.
    let desc = webfusion_core::tsdf::VolumeDesc { noise_band_sigmas: 8.0, ..sparse_desc(POOL_BLOCKS) };
    let (k, depth) = frame();
    let (mut default_table, mut default_counters) = empty_table(&sparse_desc(POOL_BLOCKS));
    for (i, ((_, g_counters, _, n), pose)) in allocate_at_the_poses(&desc).into_iter().zip(poses()).enumerate() {
        cpu::block_alloc(&alloc_params(sparse_desc(POOL_BLOCKS), k), &camera_pose(&pose), depth, &mut default_table, &mut default_counters);
        let default_n = keys(&default_table).len();
        eprintln!("pose {i}: {n} blocks with the 8σ band, {default_n} with the default");
        assert!(n > default_n, "the wider band allocates more blocks ({n} vs {default_n})");
        assert_eq!((g_counters[MAP_COUNTER_HASH_FULL], g_counters[MAP_COUNTER_OUT_OF_RANGE]), (0, 0), "room in the table, the frame in the box");
    }
}

#[test]
fn every_voxel_the_band_can_reach_has_a_block() {
    use webfusion_core::cpu::shared::{BRICK_SHIFT, block_key, is_valid_f32, transform_point, truncation_band_m, voxel_centre_in_world};
    // The default band (μ = 8 cm here, widened to 3σ of the Kinect model beyond 4.2 m) and one
    // of 8σ, wider than μ beyond 2.6 m (this desk frame's far wall).
    for sigmas in [webfusion_core::tsdf::DEFAULT_NOISE_BAND_SIGMAS, 8.0] {
        let desc = webfusion_core::tsdf::VolumeDesc { noise_band_sigmas: sigmas, ..sparse_desc(POOL_BLOCKS) };
        let (k, depth) = frame();
        let (mut table, mut counters) = empty_table(&desc);
        let pose = camera_pose(&poses()[1]);
        cpu::block_alloc(&alloc_params(desc, k), &pose, depth, &mut table, &mut counters);
        let allocated = keys(&table);
        // Every voxel centre in a pixel ray's band (|sdf| <= 0.95 b along the ray through that
        // pixel's centre, b the band at its depth) must lie in an allocated block: sample each
        // pixel's band densely and look its blocks up.
        let (mut checked, mut widened) = (0, 0);
        for v in (0..k.height_px).step_by(7) {
            for u in (0..k.width_px).step_by(7) {
                let z = depth[(v * k.width_px + u) as usize];
                if !is_valid_f32(z) {
                    continue;
                }
                let band_m = truncation_band_m(&desc, z);
                widened += usize::from(band_m > desc.truncation_m);
                for step in -16..=16 {
                    let zs = z + band_m * 0.95 * step as f32 / 16.0;
                    let p_cam = [(u as f32 - k.cx_px) * zs / k.fx_px, (v as f32 - k.cy_px) * zs / k.fy_px, zs];
                    let p = transform_point(&pose.world_from_camera, p_cam);
                    let origin = voxel_centre_in_world(&desc, 0, 0, 0).map(|c| c - 0.5 * desc.voxel_size_m);
                    let g: [u32; 3] = std::array::from_fn(|i| ((p[i] - origin[i]) / desc.voxel_size_m) as u32);
                    assert!(allocated.contains(&block_key(g.map(|c| c >> BRICK_SHIFT))), "band of {sigmas} σ: pixel ({u}, {v}) at {zs} m: its block was not allocated");
                    checked += 1;
                }
            }
        }
        eprintln!("band of {sigmas} σ: {} blocks, {checked} band points checked, {widened} pixels with a band wider than μ", allocated.len());
        assert!(checked > 100_000, "band points checked ({checked})");
        assert!(sigmas < 8.0 || widened > 20, "the 8σ band is wider than μ at the far wall's pixels ({widened})");
    }
}

#[test]
fn a_full_table_counts_refusals_and_keeps_its_keys() {
    let mut desc = sparse_desc(POOL_BLOCKS);
    desc.hash_slots = 256;
    let (k, depth) = frame();
    let (table, counters) = empty_table(&desc);
    let p = alloc_params(desc, k);
    let pose = camera_pose(&poses()[0]);
    let (g_table, g_counters) = run(&p, &pose, depth, &table, &counters);
    let (mut c_table, mut c_counters) = (table, counters);
    cpu::block_alloc(&p, &pose, depth, &mut c_table, &mut c_counters);
    let full = keys(&sparse_full_keys(&desc));
    let (g_keys, c_keys) = (keys(&g_table), keys(&c_table));
    assert_eq!(g_keys.len(), 256, "the GPU filled every slot");
    assert_eq!(c_keys.len(), 256, "so did the twin");
    assert!(g_keys.is_subset(&full) && c_keys.is_subset(&full), "only keys of the frame were inserted");
    assert!(g_counters[MAP_COUNTER_HASH_FULL] > 0 && c_counters[MAP_COUNTER_HASH_FULL] > 0, "refusals are counted ({} GPU, {} CPU)", g_counters[MAP_COUNTER_HASH_FULL], c_counters[MAP_COUNTER_HASH_FULL]);
}

/// Every key the frame at the identity inserts into a table large enough.
fn sparse_full_keys(small: &webfusion_core::tsdf::VolumeDesc) -> Vec<u32> {
    let desc = webfusion_core::tsdf::VolumeDesc { hash_slots: 1 << 16, ..*small };
    let (k, depth) = frame();
    let (mut table, mut counters) = empty_table(&desc);
    cpu::block_alloc(&alloc_params(desc, k), &camera_pose(&poses()[0]), depth, &mut table, &mut counters);
    table
}

#[test]
fn a_disabled_pose_inserts_nothing() {
    let desc = sparse_desc(POOL_BLOCKS);
    let (k, depth) = frame();
    let (table, counters) = empty_table(&desc);
    let pose = webfusion_core::fusion::predictor::camera_pose(None);
    let (g_table, g_counters) = run(&alloc_params(desc, k), &pose, depth, &table, &counters);
    assert!(g_table == table && g_counters == counters, "nothing was written");
}
