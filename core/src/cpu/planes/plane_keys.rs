// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_keys.wgsl`.

use crate::cpu::planes::distance_histogram::NO_ASSIGNMENT;
use crate::cpu::shared::{is_valid_f32, kinect_sigma_m};
use crate::kernels::plane_keys::PlaneKeysParams;
use crate::cpu::planes::plane_sums::{CHUNK_MASK_WORDS, PLANE_SUMS_CHUNK_PX};
use crate::planes::{MAX_DISTANCE_PEAKS, NO_LABEL};

fn key_from_assignment(source: &[u32], intervals: &[[u32; 4]], interval_count: &[u32], ix: usize) -> u32 {
    let a = source[ix];
    if a == NO_ASSIGNMENT {
        return NO_LABEL;
    }
    let (k, bin) = ((a >> 16) as usize, a & 0xffff);
    for j in 0..interval_count[k] as usize {
        let iv = intervals[k * MAX_DISTANCE_PEAKS + j];
        if iv[0] <= bin && bin <= iv[1] {
            return (k * MAX_DISTANCE_PEAKS + j) as u32;
        }
    }
    NO_LABEL
}

fn key_from_label(params: &PlaneKeysParams, source: &[u32], raw_depth_m: &[f32], planes: &[[f32; 4]], x: u32, y: u32) -> u32 {
    let (w, h) = (params.width_px as i32, params.height_px as i32);
    let ix = (y * params.width_px + x) as usize;
    let l = source[ix];
    if l == NO_LABEL {
        return NO_LABEL;
    }
    let m = params.margin_px as i32;
    for dy in -m..=m {
        for dx in -m..=m {
            let (u, v) = (x as i32 + dx, y as i32 + dy);
            if u < 0 || v < 0 || u >= w || v >= h || source[(v * w + u) as usize] != l {
                return NO_LABEL;
            }
        }
    }
    if params.use_raw != 0 {
        let z = raw_depth_m[ix];
        if !is_valid_f32(z) || !(z > 0.0) {
            return NO_LABEL;
        }
        let q = [(x as f32 - params.cx_px) / params.fx_px * z, (y as f32 - params.cy_px) / params.fy_px * z, z];
        let plane = planes[l as usize];
        if (plane[0] * q[0] + plane[1] * q[1] + plane[2] * q[2] + plane[3]).abs() >= params.min_distance_m.max(3.0 * kinect_sigma_m(z)) {
            return NO_LABEL;
        }
    }
    l
}

/// Keys every pixel and sets the chunk masks' bits as the kernel's invocations do.
#[expect(clippy::too_many_arguments, reason = "one argument per WGSL binding, in binding order")]
pub fn plane_keys(params: &PlaneKeysParams, source: &[u32], intervals: &[[u32; 4]], interval_count: &[u32], raw_depth_m: &[f32], planes: &[[f32; 4]], keys: &mut [u32], chunk_masks: &mut [u32]) {
    for y in 0..params.height_px {
        for x in 0..params.width_px {
            let ix = (y * params.width_px + x) as usize;
            let key = if params.mode == 0 { key_from_assignment(source, intervals, interval_count, ix) } else { key_from_label(params, source, raw_depth_m, planes, x, y) };
            keys[ix] = key;
            if key != NO_LABEL {
                chunk_masks[(ix / PLANE_SUMS_CHUNK_PX) * CHUNK_MASK_WORDS + key as usize / 32] |= 1 << (key % 32);
            }
        }
    }
}
