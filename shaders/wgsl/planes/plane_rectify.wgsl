// SPDX-License-Identifier: MIT
//! Seed 003's texture rectification (§4.4 step 4), parallel by destination texel: each
//! invocation takes one texel of a plane's texel grid, projects its centre (a point of the
//! plane, camera frame) to the nearest pixel and, when that pixel carries the plane's label,
//! copies its colour (alpha 255); else the texel is empty (0). 003 composed the projection as a
//! homography from the box's corners; the pinhole projection of the plane point is the same
//! map, without its 3 x 3 solves. Mirrors core/src/cpu/planes/plane_rectify.rs.
#import planes

struct PlaneRectifyParams {
    // The grid's plane frame (camera frame, metres): origin, u axis, v axis.
    origin_x: f32,
    origin_y: f32,
    origin_z: f32,
    u_x: f32,
    u_y: f32,
    u_z: f32,
    v_x: f32,
    v_y: f32,
    v_z: f32,
    // In-plane coordinates of texel (0, 0)'s corner, metres.
    min_u_m: f32,
    min_v_m: f32,
    // Texels per metre.
    px_per_m: f32,
    // Texels along u and v.
    width: u32,
    height: u32,
    // The plane's label.
    label: u32,
    // The image: size and pinhole intrinsics.
    image_width_px: u32,
    image_height_px: u32,
    fx_px: f32,
    fy_px: f32,
    cx_px: f32,
    cy_px: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: PlaneRectifyParams;
// Per pixel its plane label (e.g. after plane_complete).
@group(0) @binding(1) var<storage, read> labels: array<u32>;
// Per pixel its colour, RGBA8 packed little-endian (R in the low byte).
@group(0) @binding(2) var<storage, read> colour_rgba8: array<u32>;
// Out: per texel its colour with alpha 255, or 0 where empty.
@group(0) @binding(3) var<storage, read_write> texels_rgba8: array<u32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width || gid.y >= params.height {
        return;
    }
    let t = gid.y * params.width + gid.x;
    texels_rgba8[t] = 0u;
    let s_u = params.min_u_m + (f32(gid.x) + 0.5) / params.px_per_m;
    let s_v = params.min_v_m + (f32(gid.y) + 0.5) / params.px_per_m;
    let origin = vec3<f32>(params.origin_x, params.origin_y, params.origin_z);
    let p = origin + s_u * vec3<f32>(params.u_x, params.u_y, params.u_z) + s_v * vec3<f32>(params.v_x, params.v_y, params.v_z);
    if !(p.z > 1e-6) {
        return;
    }
    // Nearest pixel (halves round up, as the twin's floor(x + 0.5)).
    let x = floor(p.x / p.z * params.fx_px + params.cx_px + 0.5);
    let y = floor(p.y / p.z * params.fy_px + params.cy_px + 0.5);
    if !(x >= 0.0 && y >= 0.0 && x < f32(params.image_width_px) && y < f32(params.image_height_px)) {
        return;
    }
    let px = u32(y) * params.image_width_px + u32(x);
    if labels[px] == params.label && params.label != NO_LABEL {
        texels_rgba8[t] = (colour_rgba8[px] & 0x00ffffffu) | 0xff000000u;
    }
}
