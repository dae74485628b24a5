// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_sums.wgsl`.

use crate::cpu::planes::moments::{PLANE_MOMENT_VEC4S, PlaneMoments, plane_moments_add_point, plane_moments_combine, plane_moments_zero};
use crate::cpu::shared::kinect_sigma_m;
use crate::kernels::plane_sums::PlaneSumsParams;

/// Pixels per chunk (one workgroup's share).
pub const PLANE_SUMS_CHUNK_PX: usize = 4096;
/// Invocations per workgroup.
pub const PLANE_SUMS_WORKGROUP: usize = 64;

/// Chunks of a map of `pixel_count` pixels.
pub fn plane_sums_chunks(pixel_count: usize) -> usize {
    pixel_count.div_ceil(PLANE_SUMS_CHUNK_PX)
}

/// Twin of the workgroup tree: combines `scratch` pairwise at strides 32, 16, ..., 1.
pub fn tree_combine(scratch: &mut [PlaneMoments]) -> PlaneMoments {
    let mut stride = scratch.len() / 2;
    while stride > 0 {
        for lid in 0..stride {
            scratch[lid] = plane_moments_combine(&scratch[lid], &scratch[lid + stride]);
        }
        stride >>= 1;
    }
    scratch[0]
}

/// Sums every (plane, chunk) as the kernel's workgroups do, for planes `0..planes` (the
/// dispatch's second dimension).
#[expect(clippy::too_many_arguments, reason = "one argument per WGSL binding, in binding order, and the dispatch size")]
pub fn plane_sums(params: &PlaneSumsParams, keys: &[u32], vertex_in_camera: &[[f32; 4]], normal_in_camera: &[[f32; 4]], raw_depth_m: &[f32], normals: &[[f32; 4]], partials: &mut [[f32; 4]], planes: u32) {
    let pixel_count = (params.width_px * params.height_px) as usize;
    let chunks = plane_sums_chunks(pixel_count);
    for k in 0..planes {
        let nf = normals[(k >> params.normal_shift) as usize];
        for c in 0..chunks {
            let mut scratch = vec![plane_moments_zero(); PLANE_SUMS_WORKGROUP];
            for (lid, acc) in scratch.iter_mut().enumerate() {
                for i in 0..PLANE_SUMS_CHUNK_PX / PLANE_SUMS_WORKGROUP {
                    let ix = c * PLANE_SUMS_CHUNK_PX + i * PLANE_SUMS_WORKGROUP + lid;
                    if ix >= pixel_count || keys[ix] != k {
                        continue;
                    }
                    let v = vertex_in_camera[ix];
                    let mut p = [v[0], v[1], v[2]];
                    let mut noise_scale = 0.0;
                    if params.use_raw != 0 {
                        let z = raw_depth_m[ix];
                        let (x, y) = ((ix as u32 % params.width_px) as f32, (ix as u32 / params.width_px) as f32);
                        p = [(x - params.cx_px) / params.fx_px * z, (y - params.cy_px) / params.fy_px * z, z];
                        let s = kinect_sigma_m(z) / z;
                        noise_scale = s * s;
                    }
                    let np = (nf[0] * p[0] + nf[1] * p[1] + nf[2] * p[2]).abs().max(1e-6);
                    let area = p[2] * p[2] * p[2] / (params.fx_px * params.fy_px * np);
                    let n = normal_in_camera[ix];
                    plane_moments_add_point(acc, p, [n[0], n[1], n[2]], area, noise_scale);
                }
            }
            let m = tree_combine(&mut scratch);
            let base = (k as usize * chunks + c) * PLANE_MOMENT_VEC4S;
            partials[base..base + PLANE_MOMENT_VEC4S].copy_from_slice(&m);
        }
    }
}
