// SPDX-License-Identifier: MIT
//! Each invocation takes central differences of the vertex map at one pixel (003-digest §4.2):
//! grad_x = V(x+1, y) - V(x-1, y), grad_y = V(x, y+1) - V(x, y-1), stored as (dx, dy, dz, 0) in
//! metres. Both are invalid (NaN) on the image border or where any of the four neighbours or
//! the centre is invalid.
#import invalid

struct VertexGradientsParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    _pad0: u32,
    _pad1: u32,
}

// Uniform `VertexGradientsParams`.
@group(0) @binding(0) var<uniform> params: VertexGradientsParams;
// Vertices, camera frame.
@group(0) @binding(1) var<storage, read> vertex_in_camera: array<vec4<f32>>;
// V(x+1) - V(x-1), metres.
@group(0) @binding(2) var<storage, read_write> grad_x: array<vec4<f32>>;
// V(y+1) - V(y-1), metres.
@group(0) @binding(3) var<storage, read_write> grad_y: array<vec4<f32>>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = params.width_px;
    let h = params.height_px;
    if gid.x >= w || gid.y >= h {
        return;
    }
    let ix = gid.y * w + gid.x;
    if gid.x == 0u || gid.y == 0u || gid.x + 1u == w || gid.y + 1u == h {
        grad_x[ix] = invalid_vec4();
        grad_y[ix] = invalid_vec4();
        return;
    }
    let centre = vertex_in_camera[ix];
    let left = vertex_in_camera[ix - 1u];
    let right = vertex_in_camera[ix + 1u];
    let up = vertex_in_camera[ix - w];
    let down = vertex_in_camera[ix + w];
    if !is_valid_f32(centre.z) || !is_valid_f32(left.z) || !is_valid_f32(right.z) || !is_valid_f32(up.z) || !is_valid_f32(down.z) {
        grad_x[ix] = invalid_vec4();
        grad_y[ix] = invalid_vec4();
        return;
    }
    grad_x[ix] = vec4<f32>(right.xyz - left.xyz, 0.0);
    grad_y[ix] = vec4<f32>(down.xyz - up.xyz, 0.0);
}
