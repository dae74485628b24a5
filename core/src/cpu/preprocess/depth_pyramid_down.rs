// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/depth_pyramid_down.wgsl`.

use crate::cpu::shared::{invalid_f32, is_valid_f32};
use crate::kernels::depth_pyramid_down::DepthPyramidDownParams;

/// Makes every coarse pixel as one invocation of the kernel does.
pub fn depth_pyramid_down(params: &DepthPyramidDownParams, depth_fine_m: &[f32], depth_coarse_m: &mut [f32]) {
    for gy in 0..params.dst_height_px {
        for gx in 0..params.dst_width_px {
            let mut block = [0.0f32; 4];
            let mut nearest_m = 3.0e38f32;
            let mut n_valid = 0u32;
            for i in 0..4u32 {
                let x = 2 * gx + (i & 1);
                let y = 2 * gy + (i >> 1);
                let d_m = depth_fine_m[(y * params.src_width_px + x) as usize];
                block[i as usize] = d_m;
                if is_valid_f32(d_m) {
                    nearest_m = nearest_m.min(d_m);
                    n_valid += 1;
                }
            }
            let out_ix = (gy * params.dst_width_px + gx) as usize;
            if n_valid == 0 {
                depth_coarse_m[out_ix] = invalid_f32();
                continue;
            }
            let mut sum_m = 0.0f32;
            let mut n_used = 0u32;
            for i in 0..4 {
                let d_m = block[i];
                if is_valid_f32(d_m) && d_m - nearest_m <= params.max_depth_diff_m {
                    sum_m += d_m;
                    n_used += 1;
                }
            }
            depth_coarse_m[out_ix] = sum_m / n_used as f32;
        }
    }
}
