// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/map/block_swap_out.wgsl`. Pool blocks run in order, so the
//! transfer list follows pool order; the GPU fills it in any order: compare by key.

use crate::cpu::shared::{
    BLOCK_VOXELS, BRICK_SHIFT, EMPTY_KEY, MAP_COUNTER_BLOCKS_USED, MAP_COUNTER_FREE,
    MAP_COUNTER_SWAPPED_OUT, SWAPPED_BLOCK, block_of_key, find_slot, voxel_anchor,
};
use crate::kernels::block_swap_out::{BlockSwapOutParams, CameraPose};
use crate::tsdf::VolumeDesc;

/// The region a swapping map keeps resident around a camera (and the host swaps back in, with
/// tighter bounds): within `near_m` of the camera centre, or within `range_m` and inside the cone
/// of half-angle acos(`cos_half_angle`) about the optical axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewRegion {
    /// Radius always inside, metres.
    pub near_m: f32,
    /// Farthest distance inside the cone, metres.
    pub range_m: f32,
    /// Cosine of the cone's half-angle.
    pub cos_half_angle: f32,
}

impl ViewRegion {
    /// Twin of `in_kept_region()`: whether a block whose centre is `v` from the camera centre
    /// (world metres; `axis` the unit optical axis) lies in the region, each test widened by
    /// `radius_m`.
    pub fn contains(&self, v: [f32; 3], axis: [f32; 3], radius_m: f32) -> bool {
        let dist = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if dist <= self.near_m + radius_m {
            return true;
        }
        dist <= self.range_m + radius_m && v[0] * axis[0] + v[1] * axis[1] + v[2] * axis[2] + radius_m >= dist * self.cos_half_angle
    }
}

/// World position of the centre of the block at block coordinates `b`, and its half-diagonal,
/// metres (as the kernel computes them).
pub fn block_centre(d: &VolumeDesc, b: [u32; 3]) -> ([f32; 3], f32) {
    let half = 0.5 * (1u32 << BRICK_SHIFT) as f32;
    let anchor = voxel_anchor(d);
    let origin = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
    let centre = std::array::from_fn(|i| origin[i] + (((b[i] << BRICK_SHIFT) as i32 - anchor[i] as i32) as f32 + half) * d.voxel_size_m);
    (centre, 0.5 * 3f32.sqrt() * (1u32 << BRICK_SHIFT) as f32 * d.voxel_size_m)
}

/// Moves the blocks outside the kept region to the transfer list, as the kernel's invocations
/// do (transfer layout in the kernel's doc).
#[expect(clippy::too_many_arguments, reason = "the kernel's bindings, in order")]
pub fn block_swap_out(params: &BlockSwapOutParams, pose: &CameraPose, block_table: &mut [u32], block_coords: &mut [u32], tsdf_volume: &mut [u32], color_volume: &mut [u32], surface_bricks: &mut [u32], map_counters: &mut [u32], free_blocks: &mut [u32], swap_transfer: &mut [u32]) {
    if params.capacity == 0 || pose.enabled == 0 {
        return;
    }
    let d = &params.volume;
    let region = ViewRegion { near_m: params.keep_near_m, range_m: params.keep_range_m, cos_half_angle: params.keep_cos_half_angle };
    let m = &pose.world_from_camera;
    let (camera, axis) = ([m[3][0], m[3][1], m[3][2]], [m[2][0], m[2][1], m[2][2]]);
    let c = params.capacity as usize;
    let n = BLOCK_VOXELS as usize;
    for block in 0..map_counters[MAP_COUNTER_BLOCKS_USED] as usize {
        let key = block_coords[block];
        if key == EMPTY_KEY {
            continue;
        }
        let b = block_of_key(key);
        let (centre, radius_m) = block_centre(d, b);
        if region.contains(std::array::from_fn(|i| centre[i] - camera[i]), axis, radius_m) {
            continue;
        }
        let entry = map_counters[MAP_COUNTER_SWAPPED_OUT] as usize;
        if entry >= c {
            continue;
        }
        map_counters[MAP_COUNTER_SWAPPED_OUT] += 1;
        swap_transfer[entry] = key;
        swap_transfer[c + entry] = surface_bricks[block];
        surface_bricks[block] = 0;
        let to = 2 * c + entry * n;
        swap_transfer[to..to + n].copy_from_slice(&tsdf_volume[block * n..(block + 1) * n]);
        tsdf_volume[block * n..(block + 1) * n].fill(0);
        if params.color_enabled != 0 {
            let to = 2 * c + c * n + entry * n;
            swap_transfer[to..to + n].copy_from_slice(&color_volume[block * n..(block + 1) * n]);
            color_volume[block * n..(block + 1) * n].fill(0);
        }
        block_coords[block] = EMPTY_KEY;
        if let Some(slot) = find_slot(block_table, d, b) {
            block_table[2 * slot + 1] = SWAPPED_BLOCK;
        }
        free_blocks[map_counters[MAP_COUNTER_FREE] as usize] = block as u32;
        map_counters[MAP_COUNTER_FREE] += 1;
    }
}
