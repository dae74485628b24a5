// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/track_finish.wgsl`.

use crate::cpu::shared::{IDENTITY, camera_pose, mat4_mul, rigid_inverse, rotation_angle_rad};
use crate::kernels::track_finish::{TrackParams, TrackState};

/// Twins of the `OUTCOME_*` constants of `shared/track_state.wgsl`.
pub mod outcome {
    /// The first frame: it defines the world frame.
    pub const INITIALISED: u32 = 0;
    /// Tracked.
    pub const TRACKED: u32 = 1;
    /// Tracked after one or more lost frames.
    pub const RECOVERED: u32 = 2;
    /// Lost: too few point-to-plane pairs.
    pub const LOST_TOO_FEW_INLIERS: u32 = 3;
    /// Lost: the scaled system's condition number was too large.
    pub const LOST_ILL_CONDITIONED: u32 = 4;
    /// Lost: the estimate jumped too far from the reference.
    pub const LOST_IMPLAUSIBLE_JUMP: u32 = 5;
}

/// Decides the frame's outcome as the kernel's single invocation does.
pub fn track_finish(params: &TrackParams, state: &mut TrackState) {
    let estimate = state.estimate;
    let mut out = outcome::INITIALISED;
    if state.fused_frames != 0 {
        let finest = state.levels[0];
        let reseeded = state.reseeded != 0;
        let (max_jump_m, max_jump_rad) = if reseeded { (params.max_reseed_correction_m, params.max_reseed_correction_rad) } else { (params.max_jump_m, params.max_jump_rad) };
        let relative = mat4_mul(&rigid_inverse(&estimate), &state.reference);
        let t = relative[3];
        state.jump_translation_m = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
        state.jump_rotation_rad = rotation_angle_rad(&relative);
        out = if finest.inliers < params.min_inliers {
            outcome::LOST_TOO_FEW_INLIERS
        } else if !(finest.condition <= params.max_condition) || !(finest.translation_condition <= params.max_translation_condition) {
            outcome::LOST_ILL_CONDITIONED
        } else if state.jump_translation_m > max_jump_m || state.jump_rotation_rad > max_jump_rad {
            outcome::LOST_IMPLAUSIBLE_JUMP
        } else if state.lost_streak > 0 {
            outcome::RECOVERED
        } else {
            outcome::TRACKED
        };
    }
    state.outcome = out;
    state.reseeded = 0;
    state.frames += 1;
    if out >= outcome::LOST_TOO_FEW_INLIERS {
        state.lost_streak += 1;
        state.motion = IDENTITY;
        state.pose = camera_pose(&state.reference, 0);
    } else {
        state.motion = if out == outcome::INITIALISED { IDENTITY } else { mat4_mul(&estimate, &rigid_inverse(&state.reference)) };
        state.reference = estimate;
        state.previous_view = estimate;
        state.pose = camera_pose(&estimate, 1);
        state.fused_frames += 1;
        state.lost_streak = 0;
    }
}
