// SPDX-License-Identifier: MIT
//! Each invocation scans one row of a raycast's depth and marks the pixels a structured-light
//! sensor's IR projector cannot light (its shadow: where a Kinect returns no depth beside a
//! foreground object). The projector sits `baseline_m` along the camera's x, so camera and
//! projector form a rectified pair: a point seen at column u with depth z lies on the projector
//! ray of column p(u) = u − b·f_x / z, and the points of one projector ray are seen along one
//! image row. The projector lights the nearest of them, so u is dark when a pixel further
//! towards the projector (u' > u for b > 0) has p(u') < p(u) − `edge_disparity_px`: a surface in
//! front of u on u's projector ray. One scan from the projector's side with a running minimum
//! (maximum for b < 0) finds them all in O(width), whatever the shadow's width.
#import invalid
#import camera

struct ProjectorShadowParams {
    // Intrinsics of the raycast.
    intrinsics: Intrinsics,
    // Signed offset of the IR projector from the IR camera along the camera's x, metres.
    baseline_m: f32,
    // How far in front (in disparity pixels) an occluder must be: the sensor's depth-step
    // tolerance, so a smooth surface does not shadow itself.
    edge_disparity_px: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: ProjectorShadowParams;
// The raycast's depth along z, metres (NaN: no surface).
@group(0) @binding(1) var<storage, read> depth_m: array<f32>;
// Out: per pixel 1 where the projector's light is blocked, else 0 (also where nothing was hit).
@group(0) @binding(2) var<storage, read_write> shadow: array<u32>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = params.intrinsics;
    let row = gid.x;
    if row >= k.height_px {
        return;
    }
    let bf = params.baseline_m * k.fx_px;
    let towards_positive = params.baseline_m > 0.0;
    // The extreme projector column of the pixels scanned so far (those nearer the projector).
    var extreme = select(-3.0e38, 3.0e38, towards_positive);
    for (var i = 0u; i < k.width_px; i = i + 1u) {
        let u = select(i, k.width_px - 1u - i, towards_positive);
        let ix = row * k.width_px + u;
        let z = depth_m[ix];
        if !is_valid_f32(z) {
            shadow[ix] = 0u;
            continue;
        }
        let p = f32(u) - bf / z;
        var dark = false;
        if towards_positive {
            dark = p - extreme > params.edge_disparity_px;
            extreme = min(extreme, p);
        } else {
            dark = extreme - p > params.edge_disparity_px;
            extreme = max(extreme, p);
        }
        shadow[ix] = select(0u, 1u, dark);
    }
}
