// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/vertex_map.wgsl`.

use crate::cpu::shared::{INVALID_VEC4, back_project, is_valid_f32};
use crate::kernels::vertex_map::VertexMapParams;

/// Back-projects every pixel as one invocation of the kernel does.
pub fn vertex_map(params: &VertexMapParams, depth_m: &[f32], vertex_in_camera: &mut [[f32; 4]]) {
    let k = &params.intrinsics;
    for y in 0..k.height_px {
        for x in 0..k.width_px {
            let pixel_ix = (y * k.width_px + x) as usize;
            let z_m = depth_m[pixel_ix];
            if !is_valid_f32(z_m) {
                vertex_in_camera[pixel_ix] = INVALID_VEC4;
                continue;
            }
            let p = back_project(k, x as f32, y as f32, z_m);
            vertex_in_camera[pixel_ix] = [p[0], p[1], p[2], 1.0];
        }
    }
}
