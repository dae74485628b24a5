// SPDX-License-Identifier: MIT
//! Each invocation computes the unit normal of one pixel of a raycast surface from its
//! neighbours' vertices (as InfiniTAM does for its predictions):
//! n = normalize((V(x+1) - V(x-1)) × (V(y+1) - V(y-1))), turned to face the camera that
//! rendered it (n · (V - camera centre) < 0). NaN where the pixel, one of its four neighbours
//! (the image border included) or the cross product is invalid; also where the pose is
//! disabled nothing is written, as the raycast wrote nothing.
#import invalid
#import camera_pose

struct SurfaceNormalsParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    // Squared norm of the cross product (m⁴) at or below which no normal is emitted.
    min_cross_norm_sq: f32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: SurfaceNormalsParams;
// The pose the surface was rendered from (its camera centre orients the normals).
@group(0) @binding(1) var<uniform> pose: CameraPose;
// Raycast vertices (x, y, z, 1), world frame.
@group(0) @binding(2) var<storage, read> vertex_in_world: array<vec4<f32>>;
// Out: unit normals (nx, ny, nz, 0), world frame.
@group(0) @binding(3) var<storage, read_write> normal_in_world: array<vec4<f32>>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = params.width_px;
    if gid.x >= w || gid.y >= params.height_px || pose.enabled == 0u {
        return;
    }
    let ix = gid.y * w + gid.x;
    if gid.x == 0u || gid.y == 0u || gid.x + 1u >= w || gid.y + 1u >= params.height_px {
        normal_in_world[ix] = invalid_vec4();
        return;
    }
    let v = vertex_in_world[ix];
    let xp = vertex_in_world[ix + 1u];
    let xm = vertex_in_world[ix - 1u];
    let yp = vertex_in_world[ix + w];
    let ym = vertex_in_world[ix - w];
    if !is_valid_f32(v.x) || !is_valid_f32(xp.x) || !is_valid_f32(xm.x) || !is_valid_f32(yp.x) || !is_valid_f32(ym.x) {
        normal_in_world[ix] = invalid_vec4();
        return;
    }
    let c = cross(xp.xyz - xm.xyz, yp.xyz - ym.xyz);
    let len_sq = dot(c, c);
    if !(len_sq > params.min_cross_norm_sq) {
        normal_in_world[ix] = invalid_vec4();
        return;
    }
    var n = c / sqrt(len_sq);
    if dot(n, v.xyz - pose.world_from_camera[3].xyz) > 0.0 {
        n = -n;
    }
    normal_in_world[ix] = vec4<f32>(n, 0.0);
}
