// SPDX-License-Identifier: MIT
//! Host side of `vertex_normals`: unit normals of a vertex map.
//!
//! Kernel: `shaders/wgsl/preprocess/vertex_normals.wgsl`; CPU reference:
//! [`fn@crate::cpu::vertex_normals`].

/// Pixels one invocation computes, one above the other (their along-y windows share reads).
pub const PIXELS_PER_INVOCATION: u32 = 2;

/// Invocations that cover a `width_px` x `height_px` vertex map.
pub fn invocations(width_px: u32, height_px: u32) -> [u32; 3] {
    [width_px, height_px.div_ceil(PIXELS_PER_INVOCATION), 1]
}
