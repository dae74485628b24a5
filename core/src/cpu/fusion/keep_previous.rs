// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/keep_previous.wgsl`.

use crate::kernels::keep_previous::{CameraPose, KeepPreviousParams};

/// Writes (intensity, ∂I/∂x, ∂I/∂y, depth) per pixel into `previous` when the pose is enabled.
pub fn keep_previous(params: &KeepPreviousParams, pose: &CameraPose, intensity: &[f32], depth_m: &[f32], previous: &mut [[f32; 4]]) {
    if pose.enabled == 0 {
        return;
    }
    let (w, h) = (params.width_px, params.height_px);
    for y in 0..h {
        for x in 0..w {
            let ix = (y * w + x) as usize;
            let mut g = [0.0f32; 2];
            if x > 0 && y > 0 && x + 1 < w && y + 1 < h {
                g = [0.5 * (intensity[ix + 1] - intensity[ix - 1]), 0.5 * (intensity[ix + w as usize] - intensity[ix - w as usize])];
            }
            previous[ix] = [intensity[ix], g[0], g[1], depth_m[ix]];
        }
    }
}
