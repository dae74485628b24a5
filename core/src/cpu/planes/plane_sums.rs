// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_sums.wgsl`.

use crate::cpu::planes::moments::{PLANE_MOMENT_VEC4S, PlaneMoments, plane_moments_combine, plane_moments_zero};
use crate::cpu::shared::kinect_sigma_m;
use crate::kernels::plane_sums::PlaneSumsParams;

/// Pixels per chunk (one workgroup's share).
pub const PLANE_SUMS_CHUNK_PX: usize = 4096;
/// u32 words of a chunk's plane mask.
pub const CHUNK_MASK_WORDS: usize = 2;
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
pub fn plane_sums(params: &PlaneSumsParams, keys: &[u32], vertex_in_camera: &[[f32; 4]], normal_in_camera: &[[f32; 4]], raw_depth_m: &[f32], normals: &[[f32; 4]], partials: &mut [[f32; 4]], chunk_masks: &[u32], planes: u32) {
    let pixel_count = (params.width_px * params.height_px) as usize;
    let chunks = plane_sums_chunks(pixel_count);
    for k in 0..planes {
        let nf = normals[(k >> params.normal_shift) as usize];
        for c in 0..chunks {
            if chunk_masks[c * CHUNK_MASK_WORDS + k as usize / 32] & (1 << (k % 32)) == 0 {
                let base = (k as usize * chunks + c) * PLANE_MOMENT_VEC4S;
                partials[base..base + PLANE_MOMENT_VEC4S].fill([0.0; 4]);
                continue;
            }
            let mut scratch = vec![plane_moments_zero(); PLANE_SUMS_WORKGROUP];
            let run = PLANE_SUMS_CHUNK_PX / PLANE_SUMS_WORKGROUP;
            for (lid, acc) in scratch.iter_mut().enumerate() {
                let (mut count, mut area) = (0.0f32, 0.0f32);
                let mut p0 = [0.0f32; 3];
                let ([mut sd, mut sdd, mut sdd_off, mut sn], [mut snd_x, mut snd_y, mut snd_z], [mut noise, mut noise_off]) = ([[0.0f32; 3]; 4], [[0.0f32; 3]; 3], [[0.0f32; 3]; 2]);
                for i in 0..run {
                    let ix = c * PLANE_SUMS_CHUNK_PX + lid * run + i;
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
                    let nv = normal_in_camera[ix];
                    let n = [nv[0], nv[1], nv[2]];
                    if count == 0.0 {
                        p0 = p;
                    }
                    let d: [f32; 3] = std::array::from_fn(|j| p[j] - p0[j]);
                    count += 1.0;
                    area += p[2] * p[2] * p[2] / (params.fx_px * params.fy_px * np);
                    for j in 0..3 {
                        sd[j] += d[j];
                        sdd[j] += d[j] * d[j];
                        sn[j] += n[j];
                        snd_x[j] += n[0] * d[j];
                        snd_y[j] += n[1] * d[j];
                        snd_z[j] += n[2] * d[j];
                        noise[j] += noise_scale * p[j] * p[j];
                    }
                    let off = [d[0] * d[1], d[0] * d[2], d[1] * d[2]];
                    let noise_p = [p[0] * p[1], p[0] * p[2], p[1] * p[2]];
                    for j in 0..3 {
                        sdd_off[j] += off[j];
                        noise_off[j] += noise_scale * noise_p[j];
                    }
                }
                if count > 0.0 {
                    let mean_d = sd.map(|x| x / count);
                    let v4 = |a: [f32; 3]| [a[0], a[1], a[2], 0.0];
                    acc[0] = [count, area, 0.0, 0.0];
                    acc[1] = v4(std::array::from_fn(|j| p0[j] + mean_d[j]));
                    acc[2] = v4(sn.map(|x| x / count));
                    acc[3] = v4(std::array::from_fn(|j| sdd[j] - sd[j] * mean_d[j]));
                    acc[4] = v4([sdd_off[0] - sd[0] * mean_d[1], sdd_off[1] - sd[0] * mean_d[2], sdd_off[2] - sd[1] * mean_d[2]]);
                    acc[5] = v4(std::array::from_fn(|j| snd_x[j] - sn[0] * mean_d[j]));
                    acc[6] = v4(std::array::from_fn(|j| snd_y[j] - sn[1] * mean_d[j]));
                    acc[7] = v4(std::array::from_fn(|j| snd_z[j] - sn[2] * mean_d[j]));
                    acc[8] = v4(noise);
                    acc[9] = v4(noise_off);
                }
            }
            let m = tree_combine(&mut scratch);
            let base = (k as usize * chunks + c) * PLANE_MOMENT_VEC4S;
            partials[base..base + PLANE_MOMENT_VEC4S].copy_from_slice(&m);
        }
    }
}
