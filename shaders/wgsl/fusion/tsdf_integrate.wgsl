// SPDX-License-Identifier: MIT
//! Each invocation walks one voxel column (x, y) along z (as KinectFusion does: one thread per
//! column keeps the workgroup count small), only over the stretch of the column inside the
//! camera's frustum (the half-lines 0 < z_cam <= `max_depth_m` + μ and pixel bounds, solved in
//! closed form per column, one voxel of margin each side), and updates each voxel
//! (000-digest §1.3.2, Eq. 1.6-1.8): projects its centre into the depth image (nearest pixel),
//! takes the signed distance along the optical axis sdf = depth - z (positive in front of the
//! surface), skips voxels outside the image, without depth, or more than μ behind the surface,
//! and folds min(1, sdf / μ) into the running weighted average, weight capped at `max_weight`.
//! With colour on, voxels within the truncation band also average the pixel's colour with the
//! same weights. A voxel left with a TSDF below FAR_TSDF marks its brick in `surface_bricks`
//! (for the raycast's empty-space skipping). Nothing is fused when the pose is inactive (a
//! lost frame).
#import invalid
#import camera
#import camera_pose
#import tsdf

struct TsdfIntegrateParams {
    // The volume.
    volume: VolumeDesc,
    // Intrinsics of the depth image.
    intrinsics: Intrinsics,
    // 1 to fuse colour as well.
    color_enabled: u32,
    // Farthest valid depth, metres: voxels beyond it plus μ cannot be updated.
    max_depth_m: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: TsdfIntegrateParams;
// The pose to fuse at (the tracker's, or one the host gives).
@group(0) @binding(1) var<storage, read> pose: CameraPose;
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
    let range = frustum_interval(a, b, params.max_depth_m + d.truncation_m);
    if !(range.x <= range.y) || range.y < -1.0 || range.x > f32(d.dim_z) {
        return;
    }
    let z0 = u32(max(floor(range.x) - 1.0, 0.0));
    let z1 = u32(min(ceil(range.y) + 1.0, f32(d.dim_z - 1u)));
    for (var z = z0; z <= z1; z++) {
        integrate_voxel(d, gid.x, gid.y, z);
    }
}

fn integrate_voxel(d: VolumeDesc, x: u32, y: u32, z: u32) {
    let p_world = voxel_centre_in_world(d, x, y, z);
    let p_cam = (pose.camera_from_world * vec4<f32>(p_world, 1.0)).xyz;
    if !(p_cam.z > 0.0) {
        return;
    }
    let k = params.intrinsics;
    let u = floor(k.fx_px * p_cam.x / p_cam.z + k.cx_px + 0.5);
    let v = floor(k.fy_px * p_cam.y / p_cam.z + k.cy_px + 0.5);
    if !(u >= 0.0 && v >= 0.0 && u < f32(k.width_px) && v < f32(k.height_px)) {
        return;
    }
    let pixel = u32(v) * k.width_px + u32(u);
    let depth = depth_m[pixel];
    if !is_valid_f32(depth) {
        return;
    }
    let sdf = depth - p_cam.z;
    if sdf < -d.truncation_m {
        return;
    }
    let tsdf = min(1.0, sdf / d.truncation_m);
    let ix = voxel_index(d, x, y, z);
    let word = tsdf_volume[ix];
    let w = voxel_weight(word);
    let updated = (voxel_tsdf(word) * f32(w) + tsdf) / f32(w + 1u);
    tsdf_volume[ix] = pack_voxel(updated, min(w + 1u, d.max_weight));
    if voxel_tsdf(pack_voxel(updated, 1u)) < FAR_TSDF {
        let b = brick_index(d, x, y, z);
        if atomicLoad(&surface_bricks[b]) == 0u {
            atomicStore(&surface_bricks[b], 1u);
        }
    }
    if params.color_enabled != 0u && tsdf < 1.0 {
        let c_old = unpack_rgb8(color_volume[ix]);
        let c_new = (c_old * f32(w) + color[pixel].rgb) / f32(w + 1u);
        color_volume[ix] = pack_rgb8(c_new);
    }
}
