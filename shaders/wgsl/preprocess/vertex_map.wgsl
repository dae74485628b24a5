// SPDX-License-Identifier: MIT
//! Each invocation back-projects one depth pixel into the camera frame (000-digest Eq. 4.2):
//! vertex = (x, y, z, 1) in metres, or all-NaN where the depth is invalid.
#import invalid
#import camera

struct VertexMapParams {
    // Intrinsics of this pyramid level.
    intrinsics: Intrinsics,
}

// Uniform `VertexMapParams`.
@group(0) @binding(0) var<uniform> params: VertexMapParams;
// Depth, metres.
@group(0) @binding(1) var<storage, read> depth_m: array<f32>;
// Vertices (x, y, z, 1), metres, camera frame.
@group(0) @binding(2) var<storage, read_write> vertex_in_camera: array<vec4<f32>>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = params.intrinsics;
    if gid.x >= k.width_px || gid.y >= k.height_px {
        return;
    }
    let pixel_ix = gid.y * k.width_px + gid.x;
    let z_m = depth_m[pixel_ix];
    if !is_valid_f32(z_m) {
        vertex_in_camera[pixel_ix] = invalid_vec4();
        return;
    }
    vertex_in_camera[pixel_ix] = vec4<f32>(back_project(k, f32(gid.x), f32(gid.y), z_m), 1.0);
}
