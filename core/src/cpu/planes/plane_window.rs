// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_window.wgsl`.

use crate::kernels::plane_window::PlaneWindowParams;
use crate::planes::MAX_PLANES;

/// Gathers every pixel's mask along the axis as the kernel's invocations do.
pub fn plane_window(params: &PlaneWindowParams, labels: &[u32], plane_count: &[u32], masks_in: &[[u32; 2]], masks_out: &mut [[u32; 2]]) {
    let (w, h) = (params.width_px as i64, params.height_px as i64);
    let r = i64::from(params.reach_px);
    let count = plane_count[0].min(MAX_PLANES as u32);
    for y in 0..h {
        for x in 0..w {
            let mut mask = [0u32; 2];
            if params.axis == 0 {
                for u in (x - r).max(0)..=(x + r).min(w - 1) {
                    let m = labels[(y * w + u) as usize];
                    if m < count {
                        mask[(m / 32) as usize] |= 1 << (m % 32);
                    }
                }
            } else {
                for v in (y - r).max(0)..=(y + r).min(h - 1) {
                    let other = masks_in[(v * w + x) as usize];
                    mask = [mask[0] | other[0], mask[1] | other[1]];
                }
            }
            masks_out[(y * w + x) as usize] = mask;
        }
    }
}
