// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/feature_guess.wgsl`.

use crate::cpu::shared::mat4_mul;
use crate::kernels::feature_guess::{FeatureGuessParams, RigidEstimate, TrackState};

/// The kernel's single invocation: an accepted estimate with at least `min_inliers` inliers
/// becomes the tracker's guess, reference · dst_from_src.
pub fn feature_guess(params: &FeatureGuessParams, estimate: &RigidEstimate, state: &mut TrackState) {
    if estimate.accepted == 1 && estimate.inliers >= params.min_inliers {
        state.guess = mat4_mul(&state.reference, &estimate.dst_from_src);
        state.has_guess = 1;
    }
}
