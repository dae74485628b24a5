// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/map/block_integrate.wgsl`.

use crate::cpu::fusion::tsdf_integrate::integrate_voxel;
use crate::cpu::shared::{BLOCK_VOXELS, BRICK_SHIFT, MAP_COUNTER_VISIBLE, block_of_key, voxel_centre_in_world, voxel_in_block};
use crate::kernels::block_integrate::{BlockIntegrateParams, CameraPose};

/// Fuses every voxel of every listed block, as the kernel's workgroups do (each voxel is
/// touched by one invocation, so the order does not matter).
#[expect(clippy::too_many_arguments, reason = "one argument per WGSL binding, in binding order")]
pub fn block_integrate(
    params: &BlockIntegrateParams,
    pose: &CameraPose,
    depth_m: &[f32],
    color: &[[f32; 4]],
    tsdf_volume: &mut [u32],
    color_volume: &mut [u32],
    surface_bricks: &mut [u32],
    block_coords: &[u32],
    visible_blocks: &[u32],
    map_counters: &[u32],
) {
    if pose.enabled == 0 {
        return;
    }
    let d = &params.volume;
    for i in 0..map_counters[MAP_COUNTER_VISIBLE] as usize {
        let block = visible_blocks[i];
        let b = block_of_key(block_coords[block as usize]).map(|v| v << BRICK_SHIFT);
        for ly in 0..8 {
            for lx in 0..8 {
                let (x, y) = (b[0] + lx, b[1] + ly);
                for dz in 0..8 {
                    let z = b[2] + dz;
                    integrate_voxel(&params.intrinsics, params.color_enabled, d, pose, depth_m, color, tsdf_volume, color_volume, surface_bricks, voxel_centre_in_world(d, x, y, z), block * BLOCK_VOXELS + voxel_in_block(x, y, z), block);
                }
            }
        }
    }
}
