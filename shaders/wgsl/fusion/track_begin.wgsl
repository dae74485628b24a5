// SPDX-License-Identifier: MIT
//! Starts tracking a frame (one invocation): the estimate becomes the host's or another
//! tracker's guess if one was set, else motion · reference with the constant-velocity model,
//! else the reference (the last fused pose); the per-level statistics are cleared; and every
//! level's `track_reduce` dispatch gets its `level_workgroups`, or none when the model
//! is still empty (the first frame only initialises the world frame).
#import camera
#import track_state

@group(0) @binding(0) var<uniform> params: TrackParams;
// The tracker's state.
@group(0) @binding(1) var<storage, read_write> state: TrackState;
// Out: `track_reduce`'s indirect dispatch arguments, per level.
@group(0) @binding(2) var<storage, read_write> dispatch: TrackDispatch;

@compute @workgroup_size(1, 1, 1)
fn main() {
    let initialising = state.fused_frames == 0u;
    if state.has_guess != 0u {
        state.estimate = state.guess;
    } else if params.constant_velocity != 0u && !initialising {
        state.estimate = state.motion * state.reference;
    } else {
        state.estimate = state.reference;
    }
    state.has_guess = 0u;
    state.done_levels = 0u;
    if initialising {
        state.done_levels = (1u << TRACK_MAX_LEVELS) - 1u;
    }
    state.jump_translation_m = 0.0;
    state.jump_rotation_rad = 0.0;
    for (var l = 0u; l < TRACK_MAX_LEVELS; l++) {
        state.levels[l] = TrackLevelStats(0u, 0u, 0u, 0.0, 0.0, 0.0, 0.0, 0u);
        var workgroups = params.level_workgroups[l];
        if initialising || l >= params.n_levels {
            workgroups = 0u;
        }
        dispatch.reduce[l] = vec4<u32>(workgroups, 1u, 1u, 0u);
    }
}
