// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/bilateral_filter.wgsl`.

use crate::cpu::shared::{invalid_f32, is_valid_f32};
use crate::kernels::bilateral_filter::BilateralFilterParams;

/// Filters every pixel as one invocation of the kernel does.
pub fn bilateral_filter(params: &BilateralFilterParams, depth_in_m: &[f32], depth_out_m: &mut [f32]) {
    let width = params.width_px as i32;
    let height = params.height_px as i32;
    let radius = params.radius_px as i32;
    let k_space = -0.5 / (params.sigma_space_px * params.sigma_space_px);
    let k_range = -0.5 / (params.sigma_range_m * params.sigma_range_m);
    for gy in 0..height {
        for gx in 0..width {
            let pixel_ix = (gy * width + gx) as usize;
            let centre_m = depth_in_m[pixel_ix];
            if !is_valid_f32(centre_m) {
                depth_out_m[pixel_ix] = invalid_f32();
                continue;
            }
            let mut sum_w = 0.0f32;
            let mut sum_wd = 0.0f32;
            let (x_lo, x_hi) = ((gx - radius).max(0), (gx + radius).min(width - 1));
            let (y_lo, y_hi) = ((gy - radius).max(0), (gy + radius).min(height - 1));
            for y in y_lo..=y_hi {
                let dy = y - gy;
                for x in x_lo..=x_hi {
                    let dx = x - gx;
                    let d_m = depth_in_m[(y * width + x) as usize];
                    if !is_valid_f32(d_m) {
                        continue;
                    }
                    let diff_m = d_m - centre_m;
                    let w = ((dx * dx + dy * dy) as f32 * k_space + diff_m * diff_m * k_range).exp();
                    sum_w += w;
                    sum_wd += w * d_m;
                }
            }
            depth_out_m[pixel_ix] = sum_wd / sum_w;
        }
    }
}
