// SPDX-License-Identifier: MIT
//! Decides a frame's outcome (one invocation), with the semantics of KinectFusion's checks: the
//! first frame initialises the world frame at the estimate; any other frame is lost when the
//! finest level paired fewer than `min_inliers` points, when its scaled system's condition
//! numbers exceed `max_condition` or `max_translation_condition` (the geometry leaves a
//! direction unconstrained), or when the
//! estimate moved more than `max_jump_m` / `max_jump_rad` from the reference (after a reseed,
//! more than `max_reseed_correction_m` / `_rad` from the reseeded pose). A tracked frame
//! (tracked, or recovered after losses) becomes the reference, its pose is published active
//! (fused and predicted) and the motion model learns estimate · reference⁻¹; a lost frame keeps
//! the last good pose, published inactive, and resets the motion model.
#import camera
#import rigid
#import track_state

// Level-0 parameters (the checks are on the finest level).
@group(0) @binding(0) var<uniform> params: TrackParams;
// The tracker's state.
@group(0) @binding(1) var<storage, read_write> state: TrackState;

const IDENTITY: mat4x4<f32> = mat4x4<f32>(vec4<f32>(1.0, 0.0, 0.0, 0.0), vec4<f32>(0.0, 1.0, 0.0, 0.0), vec4<f32>(0.0, 0.0, 1.0, 0.0), vec4<f32>(0.0, 0.0, 0.0, 1.0));

@compute @workgroup_size(1, 1, 1)
fn main() {
    let estimate = state.estimate;
    var outcome = OUTCOME_INITIALISED;
    if state.fused_frames != 0u {
        let finest = state.levels[0];
        // After a reseed ICP confirms a relocalisation: it may refine it, not move it.
        let reseeded = state.reseeded != 0u;
        let max_jump_m = select(params.max_jump_m, params.max_reseed_correction_m, reseeded);
        let max_jump_rad = select(params.max_jump_rad, params.max_reseed_correction_rad, reseeded);
        let relative = rigid_inverse(estimate) * state.reference;
        state.jump_translation_m = length(relative[3].xyz);
        state.jump_rotation_rad = rotation_angle_rad(relative);
        if finest.inliers < params.min_inliers {
            outcome = OUTCOME_LOST_TOO_FEW_INLIERS;
        } else if !(finest.condition <= params.max_condition) || !(finest.translation_condition <= params.max_translation_condition) {
            outcome = OUTCOME_LOST_ILL_CONDITIONED;
        } else if state.jump_translation_m > max_jump_m || state.jump_rotation_rad > max_jump_rad {
            outcome = OUTCOME_LOST_IMPLAUSIBLE_JUMP;
        } else if state.lost_streak > 0u {
            outcome = OUTCOME_RECOVERED;
        } else {
            outcome = OUTCOME_TRACKED;
        }
    }
    state.outcome = outcome;
    state.reseeded = 0u;
    state.frames += 1u;
    let lost = outcome >= OUTCOME_LOST_TOO_FEW_INLIERS;
    if lost {
        state.lost_streak += 1u;
        state.motion = IDENTITY;
        state.pose = camera_pose(state.reference, 0u);
    } else {
        if outcome == OUTCOME_INITIALISED {
            state.motion = IDENTITY;
        } else {
            state.motion = estimate * rigid_inverse(state.reference);
        }
        state.reference = estimate;
        state.previous_view = estimate;
        state.pose = camera_pose(estimate, 1u);
        state.fused_frames += 1u;
        state.lost_streak = 0u;
    }
}
