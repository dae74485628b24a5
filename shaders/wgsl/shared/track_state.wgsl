// SPDX-License-Identifier: MIT
// The GPU tracker's state, one `TrackState` in a storage buffer that lives across frames: the
// pose each frame is fused and predicted at, the ICP estimate, the reference (the last fused
// frame, whose prediction and intensity the next frame is tracked against), the constant-velocity
// motion, per-level statistics and the frame's outcome. `track_begin`, `track_solve` and
// `track_finish` write it; `track_reduce` reads it; the mapper and predictor read its `pose`
// (offset 0) as a CameraPose; the host reads the whole struct back once per frame, late.
// Mirrors `TrackState` in core/src/kernels (generated) and core/src/fusion/track.rs.
#import camera
#import camera_pose

// Pyramid levels the state has room for (the preprocessor builds at most 4).
const TRACK_MAX_LEVELS: u32 = 4u;

// `TrackState.outcome`, mirrored by core::fusion::TrackingState.
const OUTCOME_INITIALISED: u32 = 0u;
const OUTCOME_TRACKED: u32 = 1u;
const OUTCOME_RECOVERED: u32 = 2u;
const OUTCOME_LOST_TOO_FEW_INLIERS: u32 = 3u;
const OUTCOME_LOST_ILL_CONDITIONED: u32 = 4u;
const OUTCOME_LOST_IMPLAUSIBLE_JUMP: u32 = 5u;

// Stands for an infinite condition number (a system that is not positive definite).
const CONDITION_SINGULAR: f32 = 1e30;

struct TrackLevelStats {
    // Gauss-Newton iterations run at this level.
    iterations: u32,
    // Point-to-plane pairs of the last iteration.
    inliers: u32,
    // Photometric pairs of the last iteration.
    rgb_pairs: u32,
    // RMS point-to-plane residual of the last iteration, metres.
    rms_residual_m: f32,
    // Largest over smallest eigenvalue of the last iteration's scaled JᵀJ (see track_solve).
    condition: f32,
    // Bound on how far the last update moved any point within the reference depth, metres.
    last_update_m: f32,
    // Largest over smallest eigenvalue of the last iteration's translation block of JᵀJ.
    translation_condition: f32,
    _pad0: u32,
}

struct TrackState {
    // The frame's pose (the last good one when lost) and whether it is fused and predicted.
    pose: CameraPose,
    // The ICP estimate of the current frame, camera to world.
    estimate: mat4x4<f32>,
    // The last fused frame's pose, or where a relocalisation reseeded the tracker: the
    // prediction was rendered there and the next frame's jump is measured from there.
    reference: mat4x4<f32>,
    // The last fused frame's pose: where the previous intensity (`keep_previous`) was taken
    // (a reseed moves the reference, not this).
    previous_view: mat4x4<f32>,
    // The last tracked inter-frame motion, estimate · reference⁻¹ (identity after a loss).
    motion: mat4x4<f32>,
    // An initial estimate set by the host or another tracker (used when `has_guess` is 1).
    guess: mat4x4<f32>,
    // 1: start the next frame from `guess` instead of the reference or the motion model.
    has_guess: u32,
    // 1: the reference was set by a relocalisation (`IcpTracker::reseed`): the next frame's
    // jump is held to the reseed correction limits.
    reseeded: u32,
    // Frames begun since the last reset.
    frames: u32,
    // Frames fused into the model (0: the next frame initialises the world frame).
    fused_frames: u32,
    // Consecutive lost frames.
    lost_streak: u32,
    // OUTCOME_* of the last frame.
    outcome: u32,
    // Bit l: level l converged (or its system failed); its remaining iterations are skipped.
    done_levels: u32,
    // Translation of the estimate against the reference, metres (jump check).
    jump_translation_m: f32,
    // Rotation of the estimate against the reference, radians (jump check).
    jump_rotation_rad: f32,
    // Per pyramid level (0 = full resolution).
    levels: array<TrackLevelStats, 4>,
}

// The indirect dispatch arguments of `track_reduce` per level: 0 workgroups once the level is
// done, so a converged level costs nothing.
struct TrackDispatch {
    reduce: array<vec4<u32>, 4>,
}

struct TrackParams {
    // Intrinsics of this level (current frame and prediction alike).
    intrinsics: Intrinsics,
    // Pyramid level these parameters are for.
    level: u32,
    // Threads of this level's `track_reduce` dispatch (the pixel stride).
    thread_count: u32,
    // Workgroups of this level's `track_reduce` dispatch (partial sums `track_solve` adds).
    reduce_workgroups: u32,
    // Levels the tracker uses.
    n_levels: u32,
    // Largest point distance of a correspondence, metres.
    dist_thresh_m: f32,
    // Smallest cosine between the two normals of a correspondence.
    cos_angle_thresh: f32,
    // Residuals beyond this get Huber weight delta / |r| (0: off), metres.
    huber_delta_m: f32,
    // Non-zero: weight each geometric pair by (σ(1 m) / σ(z))², the Kinect axial noise model,
    // and each photometric row by (σ(z) / σ(z, θ))², its incidence term.
    noise_weighting: u32,
    // Weight of the photometric rows against the geometric ones (0: depth only).
    rgb_weight: f32,
    // Largest accepted intensity residual.
    rgb_max_residual: f32,
    // Largest depth disagreement of a photometric pair (visibility), metres.
    rgb_max_depth_diff_m: f32,
    // A level converges once an update moves no point within `reference_depth_m` more than
    // this, metres.
    converged_update_m: f32,
    // Depth at which the update's rotation is turned into a displacement, metres.
    reference_depth_m: f32,
    // Smallest number of level-0 pairs of a tracked frame.
    min_inliers: u32,
    // Largest condition number of a scaled system whose step is taken; a level-0 system above
    // it loses the frame.
    max_condition: f32,
    // Likewise for the condition number of the translation block.
    max_translation_condition: f32,
    // Largest plausible inter-frame translation, metres.
    max_jump_m: f32,
    // Largest plausible inter-frame rotation, radians.
    max_jump_rad: f32,
    // After a reseed (relocalisation): the largest correction ICP may make to the reseeded
    // pose, metres, and radians.
    max_reseed_correction_m: f32,
    max_reseed_correction_rad: f32,
    _pad0: u32,
    _pad1: u32,
    // Non-zero: start each frame from motion · reference (constant velocity).
    constant_velocity: u32,
    // Length that scales the rotation columns of JᵀJ for the condition number, metres.
    rotation_scale_m: f32,
    // Workgroups of each level's `track_reduce` dispatches (x: level 0 .. w: level 3), which
    // `track_begin` sets up for the frame.
    level_workgroups: vec4<u32>,
}
