// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/view/normal_colormap.wgsl`.

use crate::cpu::shared::normal_colour;
use crate::kernels::normal_colormap::NormalColormapParams;

/// Colours every normal into `rgba8` (rows `row_stride_px` apart; padding left as it is), as
/// the kernel's invocations do.
pub fn normal_colormap(params: &NormalColormapParams, normals: &[[f32; 4]], rgba8: &mut [u32]) {
    let (w, h, stride) = (params.width_px as usize, params.height_px as usize, params.row_stride_px as usize);
    for y in 0..h {
        for x in 0..w {
            rgba8[y * stride + x] = normal_colour(normals[y * w + x]);
        }
    }
}
