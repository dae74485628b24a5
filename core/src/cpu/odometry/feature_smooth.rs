// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/feature_smooth.wgsl`.

use crate::kernels::feature_smooth::FeatureSmoothParams;

fn binomial5(k: i32) -> f32 {
    match k.abs() {
        0 => 6.0,
        1 => 4.0,
        _ => 1.0,
    }
}

/// Smooths every pixel along `params.axis` as the kernel's invocations do.
pub fn feature_smooth(params: &FeatureSmoothParams, intensity: &[f32], smoothed: &mut [f32]) {
    let (w, h) = (params.width_px as i32, params.height_px as i32);
    let step = if params.axis == 1 { (0, 1) } else { (1, 0) };
    for gy in 0..h {
        for gx in 0..w {
            let mut sum = 0.0f32;
            for k in -2..=2 {
                let x = (gx + k * step.0).clamp(0, w - 1);
                let y = (gy + k * step.1).clamp(0, h - 1);
                sum += binomial5(k) * intensity[(y * w + x) as usize];
            }
            smoothed[(gy * w + gx) as usize] = sum * (1.0 / 16.0);
        }
    }
}

/// The 5×5 binomial smoothing of a `width_px` × `height_px` image: the kernel along x, then
/// along y on its output (what the GPU pipeline dispatches).
pub fn smooth_image(width_px: u32, height_px: u32, intensity: &[f32]) -> Vec<f32> {
    let along = |axis: u32, input: &[f32]| {
        let mut out = vec![0.0; input.len()];
        feature_smooth(&FeatureSmoothParams { width_px, height_px, axis, ..Default::default() }, input, &mut out);
        out
    };
    along(1, &along(0, intensity))
}
