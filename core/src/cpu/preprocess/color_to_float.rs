// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/color_to_float.wgsl`.

use crate::kernels::color_to_float::ColorToFloatParams;

fn byte_at(rgb8: &[u32], byte_ix: u32) -> u32 {
    (rgb8[(byte_ix / 4) as usize] >> ((byte_ix & 3) * 8)) & 0xff
}

/// Converts every pixel as one invocation of the kernel does.
pub fn color_to_float(params: &ColorToFloatParams, rgb8: &[u32], color: &mut [[f32; 4]], intensity: &mut [f32]) {
    for gy in 0..params.height_px {
        for gx in 0..params.width_px {
            let ix = gy * params.width_px + gx;
            let r = byte_at(rgb8, 3 * ix) as f32 / 255.0;
            let g = byte_at(rgb8, 3 * ix + 1) as f32 / 255.0;
            let b = byte_at(rgb8, 3 * ix + 2) as f32 / 255.0;
            color[ix as usize] = [r, g, b, 1.0];
            intensity[ix as usize] = 0.299 * r + 0.587 * g + 0.114 * b;
        }
    }
}
