// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/view/depth_colormap.wgsl`.

use crate::cpu::shared::depth_colour;
use crate::kernels::depth_colormap::DepthColormapParams;

/// Colours every pixel of `depth_raw` (one u16 per pixel) into `rgba8` (rows
/// `row_stride_px` apart; padding left as it is), as the kernel's invocations do.
pub fn depth_colormap(params: &DepthColormapParams, depth_raw: &[u16], rgba8: &mut [u32]) {
    let (w, h, stride) = (params.width_px as usize, params.height_px as usize, params.row_stride_px as usize);
    for y in 0..h {
        for x in 0..w {
            let raw = depth_raw[y * w + x];
            rgba8[y * stride + x] = depth_colour(f32::from(raw) * params.metres_per_unit, params.max_depth_m);
        }
    }
}
