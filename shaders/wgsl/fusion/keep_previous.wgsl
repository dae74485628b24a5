// SPDX-License-Identifier: MIT
//! Each invocation keeps one pixel of a fused frame for the next frame's photometric term:
//! previous = (intensity, its central-difference gradient along x and y, depth in metres) at
//! this pyramid level (gradient 0 on the image border), written only when the frame was tracked
//! (`pose.enabled`), so after a lost frame the reference stays the last fused one. Keeping the
//! gradient lets `track_reduce` read one bilinear vec4 per pair instead of five intensities.

struct KeepPreviousParams {
    // Level width, pixels.
    width_px: u32,
    // Level height, pixels.
    height_px: u32,
    _pad0: u32,
    _pad1: u32,
}

#import camera_pose

@group(0) @binding(0) var<uniform> params: KeepPreviousParams;
// The frame's pose; nothing is kept when it is inactive (lost).
@group(0) @binding(1) var<uniform> pose: CameraPose;
// This frame's intensity at this level.
@group(0) @binding(2) var<storage, read> intensity: array<f32>;
// This frame's depth at this level, metres.
@group(0) @binding(3) var<storage, read> depth_m: array<f32>;
// Out: (intensity, ∂I/∂x, ∂I/∂y, depth) for the next frame.
@group(0) @binding(4) var<storage, read_write> previous: array<vec4<f32>>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px || pose.enabled == 0u {
        return;
    }
    let w = params.width_px;
    let ix = gid.y * w + gid.x;
    var g = vec2<f32>(0.0);
    if gid.x > 0u && gid.y > 0u && gid.x + 1u < w && gid.y + 1u < params.height_px {
        g = 0.5 * vec2<f32>(intensity[ix + 1u] - intensity[ix - 1u], intensity[ix + w] - intensity[ix - w]);
    }
    previous[ix] = vec4<f32>(intensity[ix], g, depth_m[ix]);
}
