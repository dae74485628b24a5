// SPDX-License-Identifier: MIT
//! Host side of `bilateral_filter`: edge-preserving smoothing of the metric depth.
//!
//! Kernel: `shaders/wgsl/preprocess/bilateral_filter.wgsl`; CPU reference:
//! [`fn@crate::cpu::bilateral_filter`].

/// Pixels one invocation filters, side by side along x (one per component of its vectors).
pub const PIXELS_PER_INVOCATION: u32 = 4;

/// Invocations that filter a `width_px` x `height_px` image.
pub fn invocations(width_px: u32, height_px: u32) -> [u32; 3] {
    [width_px.div_ceil(PIXELS_PER_INVOCATION), height_px, 1]
}
