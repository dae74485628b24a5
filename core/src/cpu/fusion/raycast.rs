// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/raycast.wgsl`.

use crate::cpu::shared::{BRICK_SHIFT, FAR_TSDF, INVALID, INVALID_VEC4, MAP_SPARSE, MapRef, NO_SLOT, TsdfSample, back_project, box_corner_in_world, dot3, is_valid_f32, kinect_sigma_m, sample_tsdf, transform_vector, voxel_anchor, voxel_slot, voxel_tsdf, voxel_weight};
use crate::cpu::fusion::raycast_range::tile_depth_range;
use crate::kernels::GpuIntrinsics;
use crate::kernels::raycast::{CameraPose, RaycastParams};
use crate::tsdf::VolumeDesc;

const OPAQUE: u32 = 0xff00_0000;
/// Twin of `REFINE_ROUNDS`.
const REFINE_ROUNDS: u32 = 8;
/// Twin of `FINE_SAMPLES`.
const FINE_SAMPLES: u32 = 8;

/// Twin of `nearest_slot()`.
pub fn nearest_slot(map: MapRef<'_>, d: &VolumeDesc, p_world: [f32; 3]) -> u32 {
    let origin = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
    let anchor = voxel_anchor(d);
    let g: [f32; 3] = std::array::from_fn(|i| ((p_world[i] - origin[i]) / d.voxel_size_m).floor() + anchor[i] as f32);
    let dims = [d.dim_x, d.dim_y, d.dim_z];
    if (0..3).any(|i| g[i] < 0.0 || g[i] >= dims[i] as f32) {
        return NO_SLOT;
    }
    voxel_slot(map, d, g[0] as u32, g[1] as u32, g[2] as u32)
}

/// Twin of `block_exit_t()`.
pub fn block_exit_t(d: &VolumeDesc, o: [f32; 3], inv_dir: [f32; 3], p: [f32; 3]) -> f32 {
    let anchor_m = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
    let edge_m = (1u32 << BRICK_SHIFT) as f32 * d.voxel_size_m;
    let t_out: [f32; 3] = std::array::from_fn(|i| {
        let lo = anchor_m[i] + ((p[i] - anchor_m[i]) / edge_m).floor() * edge_m;
        let t_a = (lo - o[i]) * inv_dir[i];
        let t_b = (lo + edge_m - o[i]) * inv_dir[i];
        t_a.max(t_b)
    });
    t_out[0].min(t_out[1]).min(t_out[2])
}

/// Twin of `hint_at()` (shared/depth_hint.wgsl; `hint_metres_per_unit` is the importing
/// kernel's parameter).
pub fn hint_at(hint_metres_per_unit: f32, depth_hint_raw: &[u32], ix: u32) -> f32 {
    let raw_units = (depth_hint_raw[(ix / 2) as usize] >> ((ix & 1) * 16)) & 0xffff;
    if raw_units == 0 {
        return INVALID;
    }
    raw_units as f32 * hint_metres_per_unit
}

/// Twin of `depth_hint_range()`: (nearest, farthest) depth, NaN when there is none.
pub fn depth_hint_range(k: &GpuIntrinsics, hint_metres_per_unit: f32, depth_hint_raw: &[u32], x: u32, y: u32) -> (f32, f32) {
    let own = hint_at(hint_metres_per_unit, depth_hint_raw, y * k.width_px + x);
    if is_valid_f32(own) {
        return (own, own);
    }
    let mut range = (INVALID, INVALID);
    for r in [2u32, 4] {
        let xs = [x + r, x - r.min(x), x, x];
        let ys = [y, y, y + r, y - r.min(y)];
        for i in 0..4 {
            if xs[i] < k.width_px && ys[i] < k.height_px {
                let h = hint_at(hint_metres_per_unit, depth_hint_raw, ys[i] * k.width_px + xs[i]);
                if is_valid_f32(h) {
                    range = if is_valid_f32(range.0) { (range.0.min(h), range.1.max(h)) } else { (h, h) };
                }
            }
        }
    }
    range
}

/// Casts every pixel's ray as one invocation of the kernel does.
#[expect(clippy::too_many_arguments, reason = "one argument per WGSL binding, in binding order")]
pub fn raycast(
    params: &RaycastParams,
    pose: &CameraPose,
    tsdf_volume: &[u32],
    color_volume: &[u32],
    vertex_in_world: &mut [[f32; 4]],
    depth_m: &mut [f32],
    color_rgba8: &mut [u32],
    depth_hint_raw: &[u32],
    depth_range_tiles: &[u32],
    block_table: &[u32],
) {
    let map = MapRef { tsdf_volume, block_table };
    let k = &params.intrinsics;
    let d = &params.volume;
    if pose.enabled == 0 {
        return;
    }
    for gy in 0..k.height_px {
        for gx in 0..k.width_px {
            let ix = (gy * k.width_px + gx) as usize;
            let mut miss = || {
                vertex_in_world[ix] = INVALID_VEC4;
                depth_m[ix] = INVALID;
                color_rgba8[ix] = 0;
            };
            let ray_cam = back_project(k, gx as f32, gy as f32, 1.0);
            let inv_len = 1.0 / dot3(ray_cam, ray_cam).sqrt();
            let z_per_t = inv_len;
            let m = &pose.world_from_camera;
            let origin = [m[3][0], m[3][1], m[3][2]];
            let dir = transform_vector(m, ray_cam.map(|c| c * inv_len));
            let lo = box_corner_in_world(d).map(|c| c + 0.5 * d.voxel_size_m);
            let dims = [d.dim_x, d.dim_y, d.dim_z];
            let hi: [f32; 3] = std::array::from_fn(|i| lo[i] + (dims[i] - 1) as f32 * d.voxel_size_m);
            let safe_dir = dir.map(|c| if c.abs() < 1e-12 { 1e-12 } else { c });
            let inv_dir = safe_dir.map(|c| 1.0 / c);
            let t0: [f32; 3] = std::array::from_fn(|i| (lo[i] - origin[i]) * inv_dir[i]);
            let t1: [f32; 3] = std::array::from_fn(|i| (hi[i] - origin[i]) * inv_dir[i]);
            let t_near: [f32; 3] = std::array::from_fn(|i| t0[i].min(t1[i]));
            let t_far: [f32; 3] = std::array::from_fn(|i| t0[i].max(t1[i]));
            let mut t = t_near[0].max(t_near[1]).max(t_near[2]).max(params.min_depth_m / z_per_t);
            let mut t_end = t_far[0].min(t_far[1]).min(t_far[2]).min(params.max_depth_m / z_per_t);
            let max_step = params.step_factor * d.truncation_m;
            let mut hinted = false;
            if params.use_depth_hint != 0 {
                let (near, far) = depth_hint_range(&params.intrinsics, params.hint_metres_per_unit, depth_hint_raw, gx, gy);
                if is_valid_f32(near) {
                    t = t.max((near - params.hint_margin_m - 3.0 * kinect_sigma_m(near)) / z_per_t);
                    t_end = t_end.min((far + params.hint_margin_m + 3.0 * kinect_sigma_m(far)) / z_per_t);
                    hinted = true;
                }
            }
            if !hinted && params.range_tile_px != 0 {
                let tile = ((gy / params.range_tile_px) * params.range_tiles_x + gx / params.range_tile_px) as usize;
                let Some((near, far)) = tile_depth_range([depth_range_tiles[2 * tile], depth_range_tiles[2 * tile + 1]]) else {
                    miss();
                    continue;
                };
                t = t.max(near / z_per_t - max_step);
                t_end = t_end.min(far / z_per_t + max_step);
            }
            if !(t < t_end) {
                miss();
                continue;
            }
            let min_step = 0.5 * d.voxel_size_m;
            let nearest_margin = 0.5 * 3f32.sqrt() * d.voxel_size_m / d.truncation_m;
            let t_start = t;
            let at = |t: f32| std::array::from_fn(|i| origin[i] + dir[i] * t);
            let mut i = 0;
            let mut hit = false;
            let mut t_hit = 0.0;
            let mut prev_positive = false;
            let mut prev_t = t;
            for _round in 0..REFINE_ROUNDS {
                // Coarse: the nearest voxel only, until it lies within the margin of a
                // surface or behind one.
                let mut candidate = false;
                while i < params.max_steps && t < t_end {
                    i += 1;
                    let p = at(t);
                    let slot = nearest_slot(map, d, p);
                    if slot == NO_SLOT && d.kind == MAP_SPARSE {
                        // A block a sparse map never allocated: crossed in one step.
                        prev_positive = false;
                        prev_t = t;
                        t = (block_exit_t(d, origin, inv_dir, p) + 0.01 * d.voxel_size_m).max(t + min_step);
                        continue;
                    }
                    let word = if slot == NO_SLOT { 0 } else { tsdf_volume[slot as usize] };
                    if voxel_weight(word) == 0 {
                        prev_positive = false;
                        prev_t = t;
                        t += max_step;
                        continue;
                    }
                    let n = voxel_tsdf(word);
                    if n > nearest_margin || (n > 0.0 && !prev_positive) {
                        prev_positive = true;
                        prev_t = t;
                        if n >= FAR_TSDF {
                            t += max_step;
                        } else {
                            t += ((n - nearest_margin) * d.truncation_m * params.step_factor).clamp(min_step, max_step);
                        }
                        continue;
                    }
                    // Within the margin of a surface or behind one: a candidate crossing, or
                    // (behind one with no positive sample before it) the end of the ray.
                    candidate = prev_positive;
                    break;
                }
                if !candidate {
                    break;
                }
                // Fine: trilinear samples at probes chosen one after another.
                let (mut a_t, mut a, mut have_a) = (0.0f32, TsdfSample { tsdf: 0.0, valid: false }, false);
                let (mut b_t, mut b, mut have_b) = (0.0f32, TsdfSample { tsdf: 0.0, valid: false }, false);
                let mut probe_t = t;
                let mut back = min_step;
                for _k in 0..FINE_SAMPLES {
                    let s = sample_tsdf(map, d, at(probe_t));
                    if !s.valid {
                        break;
                    }
                    if s.tsdf > 0.0 {
                        (a, a_t, have_a) = (s, probe_t, true);
                    } else {
                        (b, b_t, have_b) = (s, probe_t, true);
                    }
                    if !have_a {
                        if probe_t > prev_t {
                            probe_t = prev_t;
                        } else if probe_t > t_start {
                            probe_t = (probe_t - back).max(t_start);
                            back *= 2.0;
                        } else {
                            break;
                        }
                    } else if !have_b {
                        probe_t = a_t + (a.tsdf * d.truncation_m + min_step).min(max_step);
                        if !(probe_t < t_end) {
                            break;
                        }
                    } else if b_t - a_t > 4.0 * min_step {
                        probe_t = 0.5 * (a_t + b_t);
                    } else {
                        break;
                    }
                }
                if have_a && have_b {
                    t_hit = a_t + (b_t - a_t) * a.tsdf / (a.tsdf - b.tsdf);
                    hit = true;
                    break;
                }
                // No bracket: march on coarsely from the farthest positive sample, or past
                // the candidate.
                prev_positive = have_a;
                prev_t = if have_a { a_t } else { t };
                t = (if have_a { a_t } else { t }) + min_step;
            }
            if !hit {
                miss();
                continue;
            }
            let p: [f32; 3] = at(t_hit);
            vertex_in_world[ix] = [p[0], p[1], p[2], 1.0];
            depth_m[ix] = t_hit * z_per_t;
            let origin_v = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
            let anchor = voxel_anchor(d);
            let c: [u32; 3] = std::array::from_fn(|i| (((p[i] - origin_v[i]) / d.voxel_size_m + anchor[i] as f32).max(0.0) as u32).min(dims[i] - 1));
            let c_slot = voxel_slot(map, d, c[0], c[1], c[2]);
            let rgb = if c_slot == NO_SLOT { 0 } else { color_volume[(c_slot as usize).min(color_volume.len() - 1)] };
            color_rgba8[ix] = rgb | OPAQUE;
        }
    }
}
