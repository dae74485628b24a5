// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_sums_reduce.wgsl`.

use crate::cpu::planes::moments::{PLANE_MOMENT_VEC4S, PlaneMoments, plane_moments_combine, plane_moments_zero};
use crate::cpu::planes::plane_sums::tree_combine;
use crate::kernels::plane_sums_reduce::PlaneSumsReduceParams;

/// Invocations per workgroup.
pub const PLANE_SUMS_REDUCE_WORKGROUP: usize = 64;

/// Combines the partials of planes `0..planes` (the dispatch size) as the kernel's workgroups do.
pub fn plane_sums_reduce(params: &PlaneSumsReduceParams, partials: &[[f32; 4]], moments: &mut [[f32; 4]], planes: u32) {
    let chunks = params.chunks as usize;
    for k in 0..planes as usize {
        let mut scratch = vec![plane_moments_zero(); PLANE_SUMS_REDUCE_WORKGROUP];
        for (lid, acc) in scratch.iter_mut().enumerate() {
            for c in (lid..chunks).step_by(PLANE_SUMS_REDUCE_WORKGROUP) {
                let base = (k * chunks + c) * PLANE_MOMENT_VEC4S;
                let m: PlaneMoments = partials[base..base + PLANE_MOMENT_VEC4S].try_into().expect("10 vec4");
                *acc = plane_moments_combine(acc, &m);
            }
        }
        let m = tree_combine(&mut scratch);
        moments[k * PLANE_MOMENT_VEC4S..(k + 1) * PLANE_MOMENT_VEC4S].copy_from_slice(&m);
    }
}
