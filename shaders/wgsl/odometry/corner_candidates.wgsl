// SPDX-License-Identifier: MIT
//! Each invocation decides whether one pixel of a pyramid level's FAST scores may become a
//! keypoint, so that `keypoint_select` only ranks what this leaves: the score where it is
//! positive, a strict local maximum among its 8 neighbours (non-maximum suppression; equal
//! scores go to the smaller pixel index) and the depth around its level-0 position passes
//! seed 002's border filter (the 3×3 window at that pixel has a depth at its centre and at most
//! 2 missing, as 002's code's +1000 per zero depth rejected at 3000; and none differs from the
//! centre's by more than 4 σ(z) of the Kinect noise model plus 2 z / f, the step between two
//! pixels on a surface at 63° to the ray: a corner on a depth discontinuity has no single 3D
//! point); 0 otherwise. One
//! invocation per pixel: the tests that used to run serially inside each cell's invocation
//! run in parallel over the image. Mirrors core/src/cpu/odometry/corner_candidates.rs.
#import invalid
#import keypoint_depth

struct CornerCandidatesParams {
    // The level's size.
    width_px: u32,
    height_px: u32,
    // Pyramid level (the level's pixel is 2^level full-resolution pixels).
    level: u32,
    // Full-resolution (level 0) size, for the depth.
    depth_width_px: u32,
    depth_height_px: u32,
    // Full-resolution focal length along x, pixels (the depth step between neighbours).
    fx_px: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: CornerCandidatesParams;
// The level's FAST scores (0: no corner).
@group(0) @binding(1) var<storage, read> score: array<f32>;
// Full-resolution depth, metres; invalid where none.
@group(0) @binding(2) var<storage, read> depth_m: array<f32>;
// Out: the score of a candidate keypoint, 0 elsewhere.
@group(0) @binding(3) var<storage, read_write> candidate: array<f32>;

// True when the score s at (x, y) beats its 8 neighbours': higher, or equal with a smaller index.
fn is_local_max(x: u32, y: u32, s: f32) -> bool {
    let w = params.width_px;
    let ix = y * w + x;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let u = i32(x) + dx;
            let v = i32(y) + dy;
            if (dx == 0 && dy == 0) || u < 0 || v < 0 || u >= i32(w) || v >= i32(params.height_px) {
                continue;
            }
            let q = u32(v) * w + u32(u);
            let t = score[q];
            if t > s || (t == s && q < ix) {
                return false;
            }
        }
    }
    return true;
}

// 002's border filter at level-0 position (x0, y0).
fn depth_window_ok(x0: f32, y0: f32) -> bool {
    let w = i32(params.depth_width_px);
    let h = i32(params.depth_height_px);
    let c = keypoint_depth_pixel(x0, y0, w, h);
    let u = c.x;
    let v = c.y;
    let z = depth_m[v * w + u];
    if !is_valid_f32(z) || !(z > 0.0) {
        return false;
    }
    let step = same_surface_step_m(z, params.fx_px);
    var missing = 0u;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let n = depth_m[(v + dy) * w + u + dx];
            if !is_valid_f32(n) || !(n > 0.0) {
                missing++;
            } else if abs(n - z) > step {
                return false;
            }
        }
    }
    return missing < 3u;
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let ix = gid.y * params.width_px + gid.x;
    let s = score[ix];
    let scale = f32(1u << params.level);
    let keep = s > 0.0 && is_local_max(gid.x, gid.y, s) && depth_window_ok((f32(gid.x) + 0.5) * scale - 0.5, (f32(gid.y) + 0.5) * scale - 0.5);
    candidate[ix] = select(0.0, s, keep);
}
