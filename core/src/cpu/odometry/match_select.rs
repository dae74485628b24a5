// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/match_select.wgsl`.

use crate::cpu::odometry::estimate::{IDENTITY, RANSAC_MAX_HYPOTHESES, RANSAC_NO_COST};
use crate::cpu::shared::{NO_MATCH, is_valid_f32};
use crate::kernels::gpu_data::{FeaturePair, RigidEstimate};
use crate::kernels::match_select::MatchSelectParams;

/// Twin of `DISTANCE_BINS`.
pub const DISTANCE_BINS: u32 = 257;

fn candidate(params: &MatchSelectParams, forward: &[[u32; 4]], backward: &[[u32; 4]], current_points: &[[f32; 4]], reference_points: &[[f32; 4]], q: u32) -> bool {
    let m = forward[q as usize];
    if m[0] == NO_MATCH || m[0] >= params.slots || m[1] > params.max_distance_bits {
        return false;
    }
    if !((m[1] as f32) < params.ratio * m[2] as f32) || m[2].wrapping_sub(m[1]) < params.margin_bits {
        return false;
    }
    if params.mutual == 1 && backward[m[0] as usize][0] != q {
        return false;
    }
    is_valid_f32(current_points[q as usize][2]) && is_valid_f32(reference_points[m[0] as usize][2])
}

/// Keeps and lifts the matches as the kernel's workgroup does (its invocations' slot ranges
/// in order, which is current-slot order).
#[expect(clippy::too_many_arguments, reason = "mirrors the kernel's bindings")]
pub fn match_select(
    params: &MatchSelectParams,
    forward: &[[u32; 4]],
    backward: &[[u32; 4]],
    current_keypoints: &[[f32; 4]],
    current_points: &[[f32; 4]],
    reference_keypoints: &[[f32; 4]],
    reference_points: &[[f32; 4]],
    pairs: &mut [FeaturePair],
    estimate: &mut RigidEstimate,
) {
    let is_candidate = |q: u32| candidate(params, forward, backward, current_points, reference_points, q);
    let mut histogram = vec![0u32; DISTANCE_BINS as usize];
    let mut n = 0u32;
    for q in 0..params.slots {
        if is_candidate(q) {
            n += 1;
            histogram[forward[q as usize][1] as usize] += 1;
        }
    }
    let keep = ((n as f32 * params.keep_best_fraction).ceil() as u32).min(n);
    let (mut below, mut threshold) = (0u32, DISTANCE_BINS);
    if keep > 0 {
        for d in 0..DISTANCE_BINS {
            let here = histogram[d as usize];
            if below + here >= keep {
                threshold = d;
                break;
            }
            below += here;
        }
    }
    let quota = keep - below;
    let mut tie_rank = 0u32;
    let mut at = 0usize;
    for q in 0..params.slots {
        if !is_candidate(q) {
            continue;
        }
        let m = forward[q as usize];
        if m[1] < threshold || (m[1] == threshold && tie_rank < quota) {
            pairs[at] = FeaturePair {
                src: [current_points[q as usize][0], current_points[q as usize][1], current_points[q as usize][2], current_keypoints[q as usize][2]],
                dst: [reference_points[m[0] as usize][0], reference_points[m[0] as usize][1], reference_points[m[0] as usize][2], reference_keypoints[m[0] as usize][2]],
                slots: [q, m[0], m[1], 0],
            };
            at += 1;
        }
        if m[1] == threshold {
            tie_rank += 1;
        }
    }
    *estimate = RigidEstimate { dst_from_src: IDENTITY, pairs: at as u32, best_hypothesis: RANSAC_MAX_HYPOTHESES, noise_scale: 1.0, cost: RANSAC_NO_COST, ..Default::default() };
}
