// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/view/label_colormap.wgsl`.

use crate::cpu::shared::{pack_rgba8, plane_colour};
use crate::kernels::label_colormap::LabelColormapParams;

/// Colours every pixel into `rgba8` (rows `row_stride_px` apart; padding left as it is), as
/// the kernel's invocations do.
pub fn label_colormap(params: &LabelColormapParams, labels: &[u32], color: &[[f32; 4]], rgba8: &mut [u32]) {
    let (w, h, stride) = (params.width_px as usize, params.height_px as usize, params.row_stride_px as usize);
    for y in 0..h {
        for x in 0..w {
            let ix = y * w + x;
            let c = [color[ix][0], color[ix][1], color[ix][2]];
            let grey = 0.4 * (c[0] * 0.299 + c[1] * 0.587 + c[2] * 0.114);
            let mut out = [grey; 3];
            if labels[ix] < params.label_count {
                let p = plane_colour(labels[ix]);
                out = std::array::from_fn(|i| 0.6 * p[i] + 0.4 * c[i]);
            }
            rgba8[y * stride + x] = pack_rgba8([out[0], out[1], out[2], 1.0]);
        }
    }
}
