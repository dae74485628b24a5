// SPDX-License-Identifier: MIT
//! Each invocation computes one unit normal n = normalize(grad_x x grad_y) (000-digest Eq. 4.3
//! with central differences, 003-digest §4.2), flipped to face the camera (n . v < 0 for the
//! vertex v, the eye being the origin). Stored as (nx, ny, nz, 0); NaN where the vertex or the
//! gradients are invalid or the cross product vanishes.
#import invalid

struct NormalMapParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    // Cross products with a squared norm at or below this (m^4) give no normal.
    min_cross_norm_sq: f32,
    _pad0: u32,
}

// Uniform `NormalMapParams`.
@group(0) @binding(0) var<uniform> params: NormalMapParams;
// Vertices, camera frame.
@group(0) @binding(1) var<storage, read> vertex_in_camera: array<vec4<f32>>;
// x gradients.
@group(0) @binding(2) var<storage, read> grad_x: array<vec4<f32>>;
// y gradients.
@group(0) @binding(3) var<storage, read> grad_y: array<vec4<f32>>;
// Unit normals (nx, ny, nz, 0), camera frame.
@group(0) @binding(4) var<storage, read_write> normal_in_camera: array<vec4<f32>>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let ix = gid.y * params.width_px + gid.x;
    let v = vertex_in_camera[ix];
    let gx = grad_x[ix];
    let gy = grad_y[ix];
    if !is_valid_f32(v.z) || !is_valid_f32(gx.x) || !is_valid_f32(gy.x) {
        normal_in_camera[ix] = invalid_vec4();
        return;
    }
    let c = cross(gx.xyz, gy.xyz);
    let norm_sq = dot(c, c);
    if !(norm_sq > params.min_cross_norm_sq) {
        normal_in_camera[ix] = invalid_vec4();
        return;
    }
    var n = c / sqrt(norm_sq);
    if dot(n, v.xyz) > 0.0 {
        n = -n;
    }
    normal_in_camera[ix] = vec4<f32>(n, 0.0);
}
