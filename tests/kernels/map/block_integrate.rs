// SPDX-License-Identifier: MIT
//! `block_integrate`: a real Kinect frame fused into a sparse map's visible blocks at two poses
//! matches the CPU twin voxel by voxel (the dense kernel's tolerances, `fusion::tsdf_integrate`),
//! and every allocated voxel holds what the dense map's twin fuses at the same world point
//! (within one TSDF LSB): the sparse map stores the same TSDF where it has blocks. Blocks not listed are untouched; a
//! disabled pose fuses nothing.

use webfusion_core::cpu::{self, shared::{BLOCK_VOXELS, BRICK_SHIFT, MAP_COUNTER_VISIBLE, block_of_key, voxel_index, voxel_tsdf, voxel_weight}};
use webfusion_core::kernels::GpuIntrinsics;
use webfusion_core::kernels::block_integrate::{BlockIntegrateParams, CameraPose};
use webfusion_core::kernels::tsdf_integrate::TsdfIntegrateParams;
use webfusion_core::tsdf::{TsdfConfig, VolumeDesc};
use webfusion_core::Se3;
use webfusion_tests::{cast, finish, gpu, run_kernel_in_place};

use super::scene::{POOL_BLOCKS, VOXEL_M, camera_pose, cpu_map, depth_tiles, frame, poses, sparse_desc, visible_params};
use crate::fusion::tsdf_integrate::compare_volumes;
use crate::preprocess::chain::real_cpu_chain;

/// The visible list and counters for `pose`, by the twin.
fn visible(desc: &VolumeDesc, pose: &CameraPose, coords: &[u32], counters: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let (k, depth) = frame();
    let tile_max_m = depth_tiles(&k, depth);
    let p = visible_params(*desc, k);
    let (mut c, mut list) = (counters.to_vec(), vec![0u32; desc.pool_blocks as usize]);
    c[MAP_COUNTER_VISIBLE] = 0;
    cpu::block_visible(&p, pose, coords, &mut c, &mut list, &tile_max_m);
    (list, c)
}

#[test]
fn real_frame_at_two_poses_matches_the_twin_and_the_dense_map() {
    let chain = real_cpu_chain();
    let desc = sparse_desc(POOL_BLOCKS);
    let (k, depth) = frame();
    let (_, coords, counters) = cpu_map(&desc, &poses());
    let n = desc.pool_blocks as usize * BLOCK_VOXELS as usize;
    let (mut voxels, mut colors, mut bricks) = (vec![0u32; n], vec![0u32; n], vec![0u32; desc.pool_blocks as usize]);
    // The dense twin over a box that holds the frame, on the same voxel lattice.
    let dense_config = TsdfConfig::cube(256, VOXEL_M);
    let dense = dense_config.desc(dense_config.origin_for_first_camera(&Se3::IDENTITY));
    let (mut dense_voxels, mut dense_colors, mut dense_bricks) = (vec![0u32; dense.voxel_count()], vec![0u32; dense.voxel_count()], vec![0u32; dense.brick_count()]);
    let gpu = gpu();
    for (i, world_from_camera) in poses().iter().enumerate() {
        let pose = camera_pose(world_from_camera);
        let (list, counters) = visible(&desc, &pose, &coords, &counters);
        let p = BlockIntegrateParams { volume: desc, intrinsics: GpuIntrinsics::from(k), color_enabled: 1, ..Default::default() };
        let out = run_kernel_in_place(
            &gpu,
            &gpu.kernels.block_integrate,
            &p,
            &[bytemuck::bytes_of(&pose), bytemuck::cast_slice(depth), bytemuck::cast_slice(&chain.color), bytemuck::cast_slice(&voxels), bytemuck::cast_slice(&colors), bytemuck::cast_slice(&bricks), bytemuck::cast_slice(&coords), bytemuck::cast_slice(&list), bytemuck::cast_slice(&counters)],
            [counters[MAP_COUNTER_VISIBLE] * 8, 8, 1],
        );
        let (gv, gc, gb): (Vec<u32>, Vec<u32>, Vec<u32>) = (cast(&out[3]), cast(&out[4]), cast(&out[5]));
        let (mut cv, mut cc, mut cb) = (voxels.clone(), colors.clone(), bricks.clone());
        cpu::block_integrate(&p, &pose, depth, &chain.color, &mut cv, &mut cc, &mut cb, &coords, &list, &counters);
        let flips = compare_volumes((&gv, &gc), (&cv, &cc)).unwrap_or_else(|e| panic!("pose {i}: {e}"));
        let touched = cv.iter().filter(|&&w| voxel_weight(w) > 0).count();
        eprintln!("pose {i}: {} visible blocks, {touched} voxels touched, {flips} differ beyond 1 LSB", counters[MAP_COUNTER_VISIBLE]);
        assert!(touched > 50_000, "the frame touches a good part of the pool ({touched})");
        assert!(gb.iter().filter(|&&b| b != 0).count() * 10 > counters[MAP_COUNTER_VISIBLE] as usize, "surface blocks are marked");
        (voxels, colors, bricks) = (gv, gc, gb);
        // The dense twin at the same pose.
        let dp = TsdfIntegrateParams { volume: dense, intrinsics: GpuIntrinsics::from(k), color_enabled: 1, max_depth_m: 5.0, ..Default::default() };
        cpu::tsdf_integrate(&dp, &pose, depth, &chain.color, &mut dense_voxels, &mut dense_colors, &mut dense_bricks);
    }
    finish(&gpu);
    // Every allocated voxel inside the dense box holds what the dense map holds there.
    // Sparse voxel g lies at origin_s + (g - anchor + ½) voxels, dense voxel h at origin_d + (h + ½).
    let anchor = webfusion_core::cpu::shared::voxel_anchor(&desc);
    let offset: [i64; 3] = std::array::from_fn(|i| {
        let (s, d) = ([desc.origin_x_m, desc.origin_y_m, desc.origin_z_m][i], [dense.origin_x_m, dense.origin_y_m, dense.origin_z_m][i]);
        ((s - d) / VOXEL_M).round() as i64 - i64::from(anchor[i])
    });
    let (mut compared, mut differ) = (0usize, 0usize);
    let used = counters[0] as usize;
    for block in 0..used {
        let b = block_of_key(coords[block]).map(|v| i64::from(v << BRICK_SHIFT));
        for local in 0..BLOCK_VOXELS {
            let l = [local & 7, (local >> 3) & 7, local >> 6].map(i64::from);
            let g: [i64; 3] = std::array::from_fn(|i| b[i] + l[i] + offset[i]);
            if (0..3).any(|i| g[i] < 0 || g[i] >= 256) {
                continue;
            }
            let dense_word = dense_voxels[voxel_index(&dense, g[0] as u32, g[1] as u32, g[2] as u32) as usize];
            let sparse_word = voxels[block * BLOCK_VOXELS as usize + local as usize];
            compared += 1;
            // The voxel centres are computed from two origins a few metres apart in f32: the TSDF
            // may round one LSB apart, and a centre within an ulp of a pixel boundary may take
            // the neighbouring pixel (the dense kernel test's allowance, 0.1 %).
            let same = voxel_weight(dense_word) == voxel_weight(sparse_word) && (voxel_tsdf(dense_word) - voxel_tsdf(sparse_word)).abs() <= 1.0 / 32767.0 + 1e-7;
            differ += usize::from(!same);
        }
    }
    eprintln!("sparse vs dense: {compared} voxels compared, {differ} differ");
    assert!(compared > 100_000, "most allocated voxels lie in the dense box ({compared})");
    // Both frames' blocks were allocated before either was fused, and both twins apply the same
    // per-voxel update.
    assert!(differ * 1000 <= compared, "sparse and dense voxels differ beyond one LSB: {differ}");
}

#[test]
fn a_disabled_pose_fuses_nothing() {
    let desc = sparse_desc(POOL_BLOCKS);
    let (k, depth) = frame();
    let chain = real_cpu_chain();
    let (_, coords, counters) = cpu_map(&desc, &poses()[..1]);
    let (list, counters) = visible(&desc, &camera_pose(&poses()[0]), &coords, &counters);
    let n = desc.pool_blocks as usize * BLOCK_VOXELS as usize;
    let voxels = vec![0u32; n];
    let bricks = vec![0u32; desc.pool_blocks as usize];
    let gpu = gpu();
    let p = BlockIntegrateParams { volume: desc, intrinsics: GpuIntrinsics::from(k), color_enabled: 1, ..Default::default() };
    let pose = webfusion_core::fusion::predictor::camera_pose(None);
    let out = run_kernel_in_place(
        &gpu,
        &gpu.kernels.block_integrate,
        &p,
        &[bytemuck::bytes_of(&pose), bytemuck::cast_slice(depth), bytemuck::cast_slice(&chain.color), bytemuck::cast_slice(&voxels), bytemuck::cast_slice(&voxels), bytemuck::cast_slice(&bricks), bytemuck::cast_slice(&coords), bytemuck::cast_slice(&list), bytemuck::cast_slice(&counters)],
        [counters[MAP_COUNTER_VISIBLE] * 8, 8, 1],
    );
    finish(&gpu);
    assert!(out[3] == bytemuck::cast_slice::<u32, u8>(&voxels) && out[5] == bytemuck::cast_slice::<u32, u8>(&bricks), "nothing was written");
}
