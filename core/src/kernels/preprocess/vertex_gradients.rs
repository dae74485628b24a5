// SPDX-License-Identifier: MIT
//! Host side of `vertex_gradients`: central differences of a vertex map, smoothed along x.
//!
//! Kernel: `shaders/wgsl/preprocess/vertex_gradients.wgsl`; CPU reference:
//! [`fn@crate::cpu::vertex_gradients`].

/// Pixels one invocation computes, side by side along x (their windows share reads).
pub const PIXELS_PER_INVOCATION: u32 = 2;

/// Invocations that cover a `width_px` x `height_px` vertex map.
pub fn invocations(width_px: u32, height_px: u32) -> [u32; 3] {
    [width_px.div_ceil(PIXELS_PER_INVOCATION), height_px, 1]
}
