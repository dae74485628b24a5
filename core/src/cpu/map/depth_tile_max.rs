// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/map/depth_tile_max.wgsl`.

use crate::cpu::shared::{NO_DEPTH_TILE, is_valid_f32};
use crate::kernels::depth_tile_max::DepthTileMaxParams;

/// Every tile's largest valid depth (or [`NO_DEPTH_TILE`]), as the kernel's invocations write it.
pub fn depth_tile_max(params: &DepthTileMaxParams, depth_m: &[f32], tile_max_m: &mut [f32]) {
    let p = params;
    for tile in 0..p.tiles_x * p.tiles_y {
        let (x0, y0) = ((tile % p.tiles_x) * p.tile_px, (tile / p.tiles_x) * p.tile_px);
        let (x1, y1) = ((x0 + p.tile_px).min(p.width_px), (y0 + p.tile_px).min(p.height_px));
        let mut deepest = NO_DEPTH_TILE;
        for y in y0..y1 {
            for x in x0..x1 {
                let d = depth_m[(y * p.width_px + x) as usize];
                if is_valid_f32(d) {
                    deepest = deepest.max(d);
                }
            }
        }
        tile_max_m[tile as usize] = deepest;
    }
}
