// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_rectify.wgsl`.

use crate::kernels::plane_rectify::PlaneRectifyParams;
use crate::planes::NO_LABEL;

/// Fills every texel as the kernel's invocations do.
pub fn plane_rectify(params: &PlaneRectifyParams, labels: &[u32], colour_rgba8: &[u32], texels_rgba8: &mut [u32]) {
    let p = params;
    for y in 0..p.height {
        for x in 0..p.width {
            let t = (y * p.width + x) as usize;
            texels_rgba8[t] = 0;
            let s_u = p.min_u_m + (x as f32 + 0.5) / p.px_per_m;
            let s_v = p.min_v_m + (y as f32 + 0.5) / p.px_per_m;
            let q = [p.origin_x + s_u * p.u_x + s_v * p.v_x, p.origin_y + s_u * p.u_y + s_v * p.v_y, p.origin_z + s_u * p.u_z + s_v * p.v_z];
            if !(q[2] > 1e-6) {
                continue;
            }
            let u = (q[0] / q[2] * p.fx_px + p.cx_px + 0.5).floor();
            let v = (q[1] / q[2] * p.fy_px + p.cy_px + 0.5).floor();
            if !(u >= 0.0 && v >= 0.0 && u < p.image_width_px as f32 && v < p.image_height_px as f32) {
                continue;
            }
            let px = v as usize * p.image_width_px as usize + u as usize;
            if labels[px] == p.label && p.label != NO_LABEL {
                texels_rgba8[t] = (colour_rgba8[px] & 0x00ff_ffff) | 0xff00_0000;
            }
        }
    }
}
