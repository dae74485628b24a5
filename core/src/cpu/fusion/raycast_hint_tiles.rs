// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/raycast_hint_tiles.wgsl`.

use crate::cpu::fusion::raycast::depth_hint_range;
use crate::cpu::fusion::raycast_range::TILE_UNUSED;
use crate::cpu::shared::is_valid_f32;
use crate::kernels::raycast_hint_tiles::RaycastHintTilesParams;

/// Marks every tile whose pixels all have a depth hint, as the kernel's invocations do.
pub fn raycast_hint_tiles(params: &RaycastHintTilesParams, depth_hint_raw: &[u32], depth_range_tiles: &mut [u32]) {
    let k = &params.intrinsics;
    for ty in 0..params.tiles_y {
        for tx in 0..params.tiles_x {
            let (x0, y0) = (tx * params.tile_px, ty * params.tile_px);
            let (x1, y1) = ((x0 + params.tile_px).min(k.width_px), (y0 + params.tile_px).min(k.height_px));
            let all_hinted = (y0..y1).all(|y| (x0..x1).all(|x| is_valid_f32(depth_hint_range(k, params.hint_metres_per_unit, depth_hint_raw, x, y).0)));
            if all_hinted {
                depth_range_tiles[(2 * (ty * params.tiles_x + tx) + 1) as usize] = TILE_UNUSED;
            }
        }
    }
}
