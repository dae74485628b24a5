// SPDX-License-Identifier: MIT
//! Each invocation walks one voxel column (x, y) along z (as KinectFusion does: one thread per
//! column keeps the workgroup count small) and updates each voxel (000-digest §1.3.2,
//! Eq. 1.6-1.8): projects its centre into
//! the depth image (nearest pixel), takes the signed distance along the optical axis
//! sdf = depth - z (positive in front of the surface), skips voxels outside the frustum,
//! without depth, or more than μ behind the surface, and folds min(1, sdf / μ) into the
//! running weighted average, weight capped at `max_weight`. With colour on, voxels within the
//! truncation band also average the pixel's colour with the same weights.
#import invalid
#import camera
#import tsdf

struct TsdfIntegrateParams {
    // The volume.
    volume: VolumeDesc,
    // Intrinsics of the depth image.
    intrinsics: Intrinsics,
    // World to camera, column-major.
    camera_from_world: mat4x4<f32>,
    // Non-zero: also fuse colour.
    color_enabled: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Uniform `TsdfIntegrateParams`.
@group(0) @binding(0) var<uniform> params: TsdfIntegrateParams;
// Depth, metres (NaN = none).
@group(0) @binding(1) var<storage, read> depth_m: array<f32>;
// Colour (r, g, b, 1), registered to depth.
@group(0) @binding(2) var<storage, read> color: array<vec4<f32>>;
// Voxel words, updated in place.
@group(0) @binding(3) var<storage, read_write> tsdf_volume: array<u32>;
// Colour words, updated in place.
@group(0) @binding(4) var<storage, read_write> color_volume: array<u32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let d = params.volume;
    if gid.x >= d.dim_x || gid.y >= d.dim_y {
        return;
    }
    for (var z = 0u; z < d.dim_z; z++) {
        integrate_voxel(d, gid.x, gid.y, z);
    }
}

fn integrate_voxel(d: VolumeDesc, x: u32, y: u32, z: u32) {
    let p_world = voxel_centre_in_world(d, x, y, z);
    let p_cam = (params.camera_from_world * vec4<f32>(p_world, 1.0)).xyz;
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
    if params.color_enabled != 0u && tsdf < 1.0 {
        let c_old = unpack_rgb8(color_volume[ix]);
        let c_new = (c_old * f32(w) + color[pixel].rgb) / f32(w + 1u);
        color_volume[ix] = pack_rgb8(c_new);
    }
}
