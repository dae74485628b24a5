// SPDX-License-Identifier: MIT
//! Hands the feature estimate to the dense tracker inside the frame's own submission (one
//! invocation, recorded after `ransac_refine` and before `track_begin`): when RANSAC accepted
//! the frame's motion against the last tracked frame with at least `min_inliers` inliers, the
//! tracker's guess becomes that frame's pose composed with it, reference · dst_from_src, and
//! `has_guess` is set, so `track_begin` starts ICP there instead of at its motion model;
//! otherwise the state is left alone (the motion model, or a guess the host set). The
//! tracker's `reference` is the last tracked frame's pose exactly when the feature pass's
//! reference set is that frame's keypoints, which is when the host records this kernel.
//! A motion beyond ICP's jump limits is handed over too: ICP then converges near it and the
//! jump check rejects the frame (rather than ICP tracking falsely from the motion model), and
//! the host relocalises it. Mirrors core/src/cpu/odometry/feature_guess.rs.
#import rigid_estimate
#import track_state

struct FeatureGuessParams {
    // Fewest RANSAC inliers for the estimate to steer ICP (RANSAC's own acceptance is the floor).
    min_inliers: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: FeatureGuessParams;
// The frame's estimate against the last tracked frame (reference camera from current camera).
@group(0) @binding(1) var<storage, read> estimate: RigidEstimate;
// The dense tracker's state: `reference` read, `guess` and `has_guess` written.
@group(0) @binding(2) var<storage, read_write> state: TrackState;

@compute @workgroup_size(1, 1, 1)
fn main() {
    if estimate.accepted == 1u && estimate.inliers >= params.min_inliers {
        state.guess = state.reference * estimate.dst_from_src;
        state.has_guess = 1u;
    }
}
