// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/surface_normals.wgsl`.

use crate::cpu::shared::{INVALID_VEC4, cross3, dot3, is_valid_f32};
use crate::kernels::surface_normals::{CameraPose, SurfaceNormalsParams};

/// Computes every pixel's normal as the kernel's invocations do.
pub fn surface_normals(params: &SurfaceNormalsParams, pose: &CameraPose, vertex_in_world: &[[f32; 4]], normal_in_world: &mut [[f32; 4]]) {
    if pose.enabled == 0 {
        return;
    }
    let (w, h) = (params.width_px as usize, params.height_px as usize);
    let centre = [pose.world_from_camera[3][0], pose.world_from_camera[3][1], pose.world_from_camera[3][2]];
    for y in 0..h {
        for x in 0..w {
            let ix = y * w + x;
            if x == 0 || y == 0 || x + 1 >= w || y + 1 >= h {
                normal_in_world[ix] = INVALID_VEC4;
                continue;
            }
            let [v, xp, xm, yp, ym] = [ix, ix + 1, ix - 1, ix + w, ix - w].map(|i| vertex_in_world[i]);
            if [v, xp, xm, yp, ym].iter().any(|p| !is_valid_f32(p[0])) {
                normal_in_world[ix] = INVALID_VEC4;
                continue;
            }
            let c = cross3([xp[0] - xm[0], xp[1] - xm[1], xp[2] - xm[2]], [yp[0] - ym[0], yp[1] - ym[1], yp[2] - ym[2]]);
            let len_sq = dot3(c, c);
            if !(len_sq > params.min_cross_norm_sq) {
                normal_in_world[ix] = INVALID_VEC4;
                continue;
            }
            let inv = 1.0 / len_sq.sqrt();
            let mut n = c.map(|v| v * inv);
            if dot3(n, [v[0] - centre[0], v[1] - centre[1], v[2] - centre[2]]) > 0.0 {
                n = n.map(|v| -v);
            }
            normal_in_world[ix] = [n[0], n[1], n[2], 0.0];
        }
    }
}
