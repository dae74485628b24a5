// SPDX-License-Identifier: MIT
//! Each invocation writes one word of a virtual depth sensor's raw image (two u16 pixels, the
//! layout the preprocessor uploads and `depth_colormap` reads): for pixels 2i and 2i + 1 of a
//! raycast of the map (`raycast` + `surface_normals` at the sensor's pose), the depth in raw
//! units (planar z, or the distance along the ray with `radial`), 0 where the ray hits nothing,
//! or the depth falls outside [min_depth_m, max_depth_m] or past 65535 units.
//!
//! With `noise` = 1 each pixel is a seeded Kinect v1 measurement (the stream depends only on
//! seed, frame index and pixel, so a run is reproducible and a frame can be re-rendered alone):
//! 1. incidence: the angle θ between the ray and the model's normal; beyond
//!    `max_incidence_rad` the projected pattern is too stretched to match: no return;
//! 2. lateral noise: the pixel reads the model at its centre displaced by a normal sample of
//!    σ_L(θ) pixels per axis (Nguyen et al. 2012), nearest pixel (no mixing across edges);
//! 3. depth edges: a sampled pixel whose 4-neighbour's disparity differs by more than
//!    `edge_disparity_px` straddles a depth step the pattern matcher cannot resolve: no return;
//! 4. projector shadow: the sampled point is dark where `projector_shadow` found the IR
//!    projector's light blocked by a nearer surface;
//! 5. axial noise: a normal sample of σ_z(z, θ) (Nguyen et al. 2012) added to the depth;
//! 6. disparity quantisation: disparity = b·f / z in steps of 1/`disparity_subpixel` pixel
//!    (b = |baseline_m|, f = `disparity_focal_px`, the IR camera's focal length), back to depth.
#import invalid
#import camera
#import camera_pose
#import kinect
#import random

struct DepthSensorParams {
    // Intrinsics of the images (the raycast's).
    intrinsics: Intrinsics,
    // Raw units per metre of the output (TUM: 5000).
    units_per_metre: f32,
    // Nearest depth the sensor returns, metres.
    min_depth_m: f32,
    // Farthest depth the sensor returns, metres.
    max_depth_m: f32,
    // Non-zero: write the distance along the ray instead of the depth along z.
    radial: u32,
    // 0: exact depth; 1: the Kinect v1 model above.
    noise: u32,
    // Seed of the noise stream.
    seed: u32,
    // Index of the frame in the simulated sequence (a second input of the stream).
    frame_index: u32,
    // Signed offset of the IR projector from the IR camera along the camera's x, metres.
    baseline_m: f32,
    // Focal length of the IR camera the disparity is measured in, pixels.
    disparity_focal_px: f32,
    // Disparity steps per pixel.
    disparity_subpixel: f32,
    // Largest incidence angle with a return, radians.
    max_incidence_rad: f32,
    // Disparity difference to a neighbour that marks a depth edge, pixels.
    edge_disparity_px: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: DepthSensorParams;
// The sensor's pose (the raycast's).
@group(0) @binding(1) var<uniform> pose: CameraPose;
// The raycast's depth along z, metres (NaN: no surface).
@group(0) @binding(2) var<storage, read> depth_m: array<f32>;
// The raycast's surface points, world frame (x, y, z, 1).
@group(0) @binding(3) var<storage, read> vertex_in_world: array<vec4<f32>>;
// The raycast's unit normals, world frame (NaN: none).
@group(0) @binding(4) var<storage, read> normal_in_world: array<vec4<f32>>;
// Per pixel, 1 where the projector's light is blocked (`projector_shadow`; read with noise only).
@group(0) @binding(5) var<storage, read> shadow: array<u32>;
// Out: raw depth, pixel i in bits 16 (i & 1) .. 16 (i & 1) + 15 of word i / 2.
@group(0) @binding(6) var<storage, read_write> depth_raw: array<u32>;

// The model's depth at pixel (x, y); NaN outside the image or where nothing was hit.
fn model_depth(x: i32, y: i32) -> f32 {
    let k = params.intrinsics;
    if x < 0 || y < 0 || x >= i32(k.width_px) || y >= i32(k.height_px) {
        return invalid_f32();
    }
    return depth_m[u32(y) * k.width_px + u32(x)];
}

// Incidence angle at pixel index `ix` (radians; 0 where the normal is unknown).
fn incidence_rad(ix: u32) -> f32 {
    let n = normal_in_world[ix];
    if !is_valid_f32(n.x) {
        return 0.0;
    }
    let ray = normalize(vertex_in_world[ix].xyz - pose.world_from_camera[3].xyz);
    return acos(clamp(abs(dot(ray, n.xyz)), 0.0, 1.0));
}

// Disparity of depth z, pixels.
fn disparity_px(z_m: f32) -> f32 {
    return abs(params.baseline_m) * params.disparity_focal_px / z_m;
}

// True when a 4-neighbour of (x, y) (depth z) lies across a depth step.
fn at_depth_edge(x: i32, y: i32, z_m: f32) -> bool {
    let d = disparity_px(z_m);
    let neighbours = array<vec2<i32>, 4>(vec2<i32>(-1, 0), vec2<i32>(1, 0), vec2<i32>(0, -1), vec2<i32>(0, 1));
    for (var i = 0u; i < 4u; i = i + 1u) {
        let zn = model_depth(x + neighbours[i].x, y + neighbours[i].y);
        if is_valid_f32(zn) && abs(disparity_px(zn) - d) > params.edge_disparity_px {
            return true;
        }
    }
    return false;
}

// Raw units of depth z seen at pixel (x, y); 0 outside the range or the u16 scale.
fn to_units(x: i32, y: i32, z_m: f32) -> u32 {
    if !(z_m >= params.min_depth_m && z_m <= params.max_depth_m) {
        return 0u;
    }
    var d = z_m;
    if params.radial != 0u {
        let k = params.intrinsics;
        let rx = (f32(x) - k.cx_px) / k.fx_px;
        let ry = (f32(y) - k.cy_px) / k.fy_px;
        d = z_m * sqrt(rx * rx + ry * ry + 1.0);
    }
    let units = floor(d * params.units_per_metre + 0.5);
    if units > 65535.0 {
        return 0u;
    }
    return u32(units);
}

// Whether this pipeline has the noise model at all: the sensor of exact depth compiles its
// own pipeline with it off (then `noise` must be 0), since lavapipe runs the code of every
// branch, taken or not (the untaken noise model cost 4 of the kernel's 5 ms at 640x480).
override NOISE_MODEL: bool = true;

// The raw depth of pixel index `ix`.
fn sense(ix: u32) -> u32 {
    let k = params.intrinsics;
    let x = i32(ix % k.width_px);
    let y = i32(ix / k.width_px);
    let z0 = depth_m[ix];
    if !is_valid_f32(z0) {
        return 0u;
    }
    if !NOISE_MODEL || params.noise == 0u {
        return to_units(x, y, z0);
    }
    var state = pcg_hash(ix + pcg_hash(params.frame_index + pcg_hash(params.seed)));
    let theta0 = incidence_rad(ix);
    if theta0 > params.max_incidence_rad {
        return 0u;
    }
    let lateral = random_gauss2(&state) * kinect_lateral_sigma_px(theta0);
    let sx = i32(floor(f32(x) + lateral.x + 0.5));
    let sy = i32(floor(f32(y) + lateral.y + 0.5));
    let zs = model_depth(sx, sy);
    if !is_valid_f32(zs) {
        return 0u;
    }
    let s = u32(sy) * k.width_px + u32(sx);
    let theta = incidence_rad(s);
    if theta > params.max_incidence_rad || at_depth_edge(sx, sy, zs) || shadow[s] != 0u {
        return 0u;
    }
    let z_noisy = zs + random_gauss2(&state).x * kinect_sigma_at_angle_m(zs, theta);
    let bf = abs(params.baseline_m) * params.disparity_focal_px;
    let disparity = floor(bf / z_noisy * params.disparity_subpixel + 0.5) / params.disparity_subpixel;
    if !(z_noisy > 0.0) || !(disparity > 0.0) {
        return 0u;
    }
    return to_units(x, y, bf / disparity);
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = params.intrinsics.width_px * params.intrinsics.height_px;
    let first = 2u * gid.x;
    if first >= n {
        return;
    }
    var word = sense(first);
    if first + 1u < n {
        word = word | (sense(first + 1u) << 16u);
    }
    depth_raw[gid.x] = word;
}
