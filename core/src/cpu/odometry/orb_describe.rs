// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/orb_describe.wgsl`.

use crate::cpu::shared::{DESCRIPTOR_WORDS, INVALID_VEC4};
use crate::kernels::orb_describe::OrbDescribeParams;

fn sample_smoothed(params: &OrbDescribeParams, smoothed: &[f32], x: f32, y: f32) -> f32 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let w = params.width_px as usize;
    let i = y0 as usize * w + x0 as usize;
    let top = smoothed[i] * (1.0 - fx) + smoothed[i + 1] * fx;
    let bottom = smoothed[i + w] * (1.0 - fx) + smoothed[i + w + 1] * fx;
    top * (1.0 - fy) + bottom * fy
}

/// Describes every slot of the level as the kernel's invocations do.
pub fn orb_describe(params: &OrbDescribeParams, smoothed: &[f32], keypoints: &[[f32; 4]], pattern: &[[f32; 4]], descriptors: &mut [u32], features: &mut [[f32; 4]]) {
    let w = params.width_px as usize;
    for slot in params.slot_offset as usize..(params.slot_offset + params.slot_count) as usize {
        let kp = keypoints[slot];
        let words = &mut descriptors[slot * DESCRIPTOR_WORDS..(slot + 1) * DESCRIPTOR_WORDS];
        if !(kp[3] > 0.0) {
            words.fill(0);
            features[slot] = INVALID_VEC4;
            continue;
        }
        let (x, y) = (kp[0] as i32, kp[1] as i32);
        let r = params.patch_radius_px as i32;
        let (mut m10, mut m01) = (0.0f32, 0.0f32);
        for dy in -r..=r {
            let row = (y + dy) as usize * w;
            for dx in -r..=r {
                if dx * dx + dy * dy > r * r {
                    continue;
                }
                let value = smoothed[row + (x + dx) as usize];
                m10 += dx as f32 * value;
                m01 += dy as f32 * value;
            }
        }
        let theta = if m10 != 0.0 || m01 != 0.0 { m01.atan2(m10) } else { 0.0 };
        let (s, c) = theta.sin_cos();
        for (word, out) in words.iter_mut().enumerate() {
            let mut bits = 0u32;
            for b in 0..32 {
                let pair = pattern[word * 32 + b];
                let ia = sample_smoothed(params, smoothed, kp[0] + c * pair[0] - s * pair[1], kp[1] + s * pair[0] + c * pair[1]);
                let ib = sample_smoothed(params, smoothed, kp[0] + c * pair[2] - s * pair[3], kp[1] + s * pair[2] + c * pair[3]);
                if ia < ib {
                    bits |= 1 << b;
                }
            }
            *out = bits;
        }
        let scale = (1u32 << kp[2] as u32) as f32;
        features[slot] = [(kp[0] + 0.5) * scale - 0.5, (kp[1] + 0.5) * scale - 0.5, theta, kp[2]];
    }
}
