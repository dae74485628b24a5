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

/// Smooths every pixel as the kernel's invocations do.
pub fn feature_smooth(params: &FeatureSmoothParams, intensity: &[f32], smoothed: &mut [f32]) {
    let (w, h) = (params.width_px as i32, params.height_px as i32);
    for gy in 0..h {
        for gx in 0..w {
            let mut sum = 0.0f32;
            for dy in -2..=2 {
                let y = (gy + dy).clamp(0, h - 1);
                let mut row = 0.0f32;
                for dx in -2..=2 {
                    let x = (gx + dx).clamp(0, w - 1);
                    row += binomial5(dx) * intensity[(y * w + x) as usize];
                }
                sum += binomial5(dy) * row;
            }
            smoothed[(gy * w + gx) as usize] = sum * (1.0 / 256.0);
        }
    }
}
