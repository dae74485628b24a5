// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/track_begin.wgsl`.

use crate::cpu::shared::mat4_mul;
use crate::kernels::track_begin::{TrackDispatch, TrackLevelStats, TrackParams, TrackState};

/// Twin of `TRACK_MAX_LEVELS`.
pub const TRACK_MAX_LEVELS: u32 = 4;

/// Starts a frame as the kernel's single invocation does.
pub fn track_begin(params: &TrackParams, state: &mut TrackState, dispatch: &mut TrackDispatch) {
    let initialising = state.fused_frames == 0;
    state.estimate = if state.has_guess != 0 {
        state.guess
    } else if params.constant_velocity != 0 && !initialising {
        mat4_mul(&state.motion, &state.reference)
    } else {
        state.reference
    };
    state.has_guess = 0;
    state.done_levels = if initialising { (1 << TRACK_MAX_LEVELS) - 1 } else { 0 };
    state.jump_translation_m = 0.0;
    state.jump_rotation_rad = 0.0;
    for l in 0..TRACK_MAX_LEVELS {
        state.levels[l as usize] = TrackLevelStats::default();
        let workgroups = if initialising || l >= params.n_levels { 0 } else { params.level_workgroups[l as usize] };
        dispatch.reduce[l as usize] = [workgroups, 1, 1, 0];
    }
}
