// SPDX-License-Identifier: MIT
// One voxel's TSDF update (000-digest §1.3.2, Eq. 1.6-1.8), shared by the dense map's
// `tsdf_integrate` and the sparse map's `block_integrate`. The importing kernel declares
// `params` (with `intrinsics` and `color_enabled`), `pose`, `depth_m`, `color`, `tsdf_volume`,
// `color_volume` and `surface_bricks` as tsdf_integrate.wgsl does. Mirrors
// core/src/cpu/fusion/tsdf_integrate.rs::integrate_voxel.
#import invalid
#import camera
#import camera_pose
#import tsdf

// Updates the voxel centred at `p_world`, stored at `ix` in `tsdf_volume` (and `color_volume`),
// whose brick word is `brick`: projects the centre into the depth image (nearest pixel), takes
// the signed distance along the optical axis sdf = depth - z (positive in front of the
// surface), skips it outside the image, without depth, or more than the depth's truncation band
// b (truncation_band_m: μ, or wider where the sensor is noisier) behind the surface, and folds
// min(1, sdf / b) into the running weighted average, weight capped at `max_weight`. With
// colour on, voxels within the truncation band also average the pixel's colour with the same
// weights. A voxel left with a TSDF below FAR_TSDF marks its brick.
fn integrate_voxel(d: VolumeDesc, p_world: vec3<f32>, ix: u32, brick: u32) {
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
    let band = truncation_band_m(d, depth);
    if sdf < -band {
        return;
    }
    let tsdf = min(1.0, sdf / band);
    let word = tsdf_volume[ix];
    let w = voxel_weight(word);
    let updated = (voxel_tsdf(word) * f32(w) + tsdf) / f32(w + 1u);
    tsdf_volume[ix] = pack_voxel(updated, min(w + 1u, d.max_weight));
    if voxel_tsdf(pack_voxel(updated, 1u)) < FAR_TSDF {
        if atomicLoad(&surface_bricks[brick]) == 0u {
            atomicStore(&surface_bricks[brick], 1u);
        }
    }
    if params.color_enabled != 0u && tsdf < 1.0 {
        let c_old = unpack_rgb8(color_volume[ix]);
        let c_new = (c_old * f32(w) + color[pixel].rgb) / f32(w + 1u);
        color_volume[ix] = pack_rgb8(c_new);
    }
}
