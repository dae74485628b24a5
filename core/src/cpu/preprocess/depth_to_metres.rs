// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/depth_to_metres.wgsl`.

use crate::cpu::shared;
use crate::kernels::depth_to_metres::DepthToMetresParams;

/// Converts every pixel as one invocation of the kernel does.
pub fn depth_to_metres(params: &DepthToMetresParams, depth_raw: &[u32], depth_m: &mut [f32]) {
    for y in 0..params.height_px {
        for x in 0..params.width_px {
            let pixel_ix = y * params.width_px + x;
            let word = depth_raw[(pixel_ix / 2) as usize];
            let raw_units = (word >> ((pixel_ix & 1) * 16)) & 0xffff;
            depth_m[pixel_ix as usize] = shared::depth_to_metres(raw_units, params.metres_per_unit, params.min_depth_m, params.max_depth_m);
        }
    }
}
