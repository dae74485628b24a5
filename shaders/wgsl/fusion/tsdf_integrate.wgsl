// SPDX-License-Identifier: MIT
//! Each invocation walks one voxel column (x, y) along z (as KinectFusion does: one thread per
//! column keeps the workgroup count small), only over the stretch of the column inside the
//! camera's frustum (the half-lines 0 < z_cam <= `max_depth_m` + b, b the truncation band
//! there, and pixel bounds, solved in closed form per column, one voxel of margin each side), and updates each voxel with
//! `integrate_voxel` (shared/tsdf_update.wgsl: projective TSDF running average, colour, and the
//! brick mark in `surface_bricks` for the raycast's empty-space skipping). The dense map only;
//! the sparse one integrates with `block_integrate`. Nothing is fused when the pose is inactive
//! (a lost frame).
#import tsdf_update

struct TsdfIntegrateParams {
    // The volume.
    volume: VolumeDesc,
    // Intrinsics of the depth image.
    intrinsics: Intrinsics,
    // 1 to fuse colour as well.
    color_enabled: u32,
    // Farthest valid depth, metres: voxels beyond it plus its truncation band cannot be updated.
    max_depth_m: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: TsdfIntegrateParams;
// The pose to fuse at (the tracker's, or one the host gives).
@group(0) @binding(1) var<uniform> pose: CameraPose;
// Depth to fuse, metres (NaN: none).
@group(0) @binding(2) var<storage, read> depth_m: array<f32>;
// Colour (r, g, b, 1) in [0, 1].
@group(0) @binding(3) var<storage, read> color: array<vec4<f32>>;
// Voxel words (TSDF + weight), updated in place.
@group(0) @binding(4) var<storage, read_write> tsdf_volume: array<u32>;
// Colour words (RGB8), updated in place (one placeholder word when colour is off).
@group(0) @binding(5) var<storage, read_write> color_volume: array<u32>;
// One word per brick, set to 1 when a voxel in it takes a TSDF below FAR_TSDF.
@group(0) @binding(6) var<storage, read_write> surface_bricks: array<atomic<u32>>;

// The z-index interval [lo, hi] of column points a + k b (camera frame) inside the frustum, as
// floats (empty when lo > hi). Each condition is c0 + k c1 >= 0 (or > 0).
fn frustum_interval(a: vec3<f32>, b: vec3<f32>, far_m: f32) -> vec2<f32> {
    let k = params.intrinsics;
    var lo = -1e30;
    var hi = 1e30;
    // z > 0, z <= far, and the four image borders (multiplied out by z > 0).
    var cs = array<vec2<f32>, 6>(
        vec2<f32>(a.z, b.z),
        vec2<f32>(far_m - a.z, -b.z),
        vec2<f32>(k.fx_px * a.x + (k.cx_px + 0.5) * a.z, k.fx_px * b.x + (k.cx_px + 0.5) * b.z),
        vec2<f32>(-(k.fx_px * a.x + (k.cx_px + 0.5 - f32(k.width_px)) * a.z), -(k.fx_px * b.x + (k.cx_px + 0.5 - f32(k.width_px)) * b.z)),
        vec2<f32>(k.fy_px * a.y + (k.cy_px + 0.5) * a.z, k.fy_px * b.y + (k.cy_px + 0.5) * b.z),
        vec2<f32>(-(k.fy_px * a.y + (k.cy_px + 0.5 - f32(k.height_px)) * a.z), -(k.fy_px * b.y + (k.cy_px + 0.5 - f32(k.height_px)) * b.z)),
    );
    for (var i = 0u; i < 6u; i++) {
        let c = cs[i];
        if c.y > 0.0 {
            lo = max(lo, -c.x / c.y);
        } else if c.y < 0.0 {
            hi = min(hi, -c.x / c.y);
        } else if c.x < 0.0 {
            return vec2<f32>(1.0, 0.0);
        }
    }
    return vec2<f32>(lo, hi);
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let d = params.volume;
    if gid.x >= d.dim_x || gid.y >= d.dim_y || pose.enabled == 0u {
        return;
    }
    let c = pose.camera_from_world;
    let a = (c * vec4<f32>(voxel_centre_in_world(d, gid.x, gid.y, 0u), 1.0)).xyz;
    let b = (c * vec4<f32>(0.0, 0.0, d.voxel_size_m, 0.0)).xyz;
    let range = frustum_interval(a, b, params.max_depth_m + truncation_band_m(d, params.max_depth_m));
    if !(range.x <= range.y) || range.y < -1.0 || range.x > f32(d.dim_z) {
        return;
    }
    let z0 = u32(max(floor(range.x) - 1.0, 0.0));
    let z1 = u32(min(ceil(range.y) + 1.0, f32(d.dim_z - 1u)));
    for (var z = z0; z <= z1; z++) {
        integrate_voxel(d, voxel_centre_in_world(d, gid.x, gid.y, z), voxel_index(d, gid.x, gid.y, z), brick_index(d, gid.x, gid.y, z));
    }
}
