// SPDX-License-Identifier: MIT
//! Host side of `feature_smooth`: one pass (along x or y) of the binomial pre-smoothing the
//! descriptors read.
//!
//! Kernel: `shaders/wgsl/odometry/feature_smooth.wgsl`; CPU reference:
//! [`fn@crate::cpu::feature_smooth`].

/// Pixels one invocation smooths, one after another along the pass's axis.
pub const PIXELS_PER_INVOCATION: u32 = 4;

/// Invocations of the pass along `axis` (0: x, 1: y) over a `width_px` x `height_px` image.
pub fn invocations(width_px: u32, height_px: u32, axis: u32) -> [u32; 3] {
    if axis == 1 { [width_px, height_px.div_ceil(PIXELS_PER_INVOCATION), 1] } else { [width_px.div_ceil(PIXELS_PER_INVOCATION), height_px, 1] }
}
