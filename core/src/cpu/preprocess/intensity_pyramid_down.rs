// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/intensity_pyramid_down.wgsl`.

use crate::kernels::intensity_pyramid_down::IntensityPyramidDownParams;

/// Computes every coarse pixel as one invocation of the kernel does.
pub fn intensity_pyramid_down(params: &IntensityPyramidDownParams, src: &[f32], dst: &mut [f32]) {
    let w = params.src_width_px as usize;
    for gy in 0..params.dst_height_px {
        for gx in 0..params.dst_width_px {
            let x = (2 * gx).min(params.src_width_px - 2) as usize;
            let y = (2 * gy).min(params.src_height_px - 2) as usize;
            let sum = (src[y * w + x] + src[y * w + x + 1]) + (src[(y + 1) * w + x] + src[(y + 1) * w + x + 1]);
            dst[(gy * params.dst_width_px + gx) as usize] = 0.25 * sum;
        }
    }
}
