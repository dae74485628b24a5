// SPDX-License-Identifier: MIT
//! `plane_sums_reduce`: each plane's chunk partials combined into its moments, against the CPU
//! twin (tolerances of plane_sums' `compare_moments`, with its negative controls), on a real
//! frame; and the GPU's f32 moments against the f64 reference's sums of the same planes
//! (`planes::reference::label`): the plane fitted to each lies within 0.01° and 0.1 mm of the
//! f64 fit, so centred f32 moments lose nothing a plane fit needs.

use webfusion_core::cpu;
use webfusion_core::cpu::planes::moments::{PLANE_MOMENT_VEC4S, PlaneMoments, plane_moments_to_sums};
use webfusion_core::cpu::planes::plane_sums::plane_sums_chunks;
use webfusion_core::kernels::plane_sums_reduce::PlaneSumsReduceParams;
use webfusion_core::planes::PlaneConfig;
use webfusion_core::planes::reference::{self, PlaneFit, PlaneSums};
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

use super::plane_keys::real_fixture;
use super::plane_sums::{assert_moments_controls, first_full, real_keys};

/// Runs plane_sums_reduce for `planes` planes on the GPU and its twin; returns (GPU, twin).
pub(crate) fn run(chunks: usize, partials: &[[f32; 4]], planes: u32) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let gpu = gpu();
    let params = PlaneSumsReduceParams { chunks: chunks as u32, ..Default::default() };
    let size = planes as usize * PLANE_MOMENT_VEC4S;
    let out = run_kernel_slots(&gpu, &gpu.kernels.plane_sums_reduce, &params, &[Slot::In(bytemuck::cast_slice(partials)), Slot::Out(16 * size)], [64 * planes, 1, 1]);
    finish(&gpu);
    let mut c = vec![[0.0f32; 4]; size];
    cpu::plane_sums_reduce(&params, partials, &mut c, planes);
    (cast(&out[0]), c)
}

/// The real frame's moments per plane (twins of plane_keys, plane_sums, plane_sums_reduce).
pub(crate) fn real_moments() -> (Vec<[f32; 4]>, Vec<[f32; 4]>, Vec<PlaneMoments>) {
    let (pre, planes, labels) = real_fixture();
    let (params, keys) = real_keys(&pre, &planes, &labels);
    let full = &pre.levels[0];
    let chunks = plane_sums_chunks(keys.len());
    let mut partials = vec![[0.0f32; 4]; planes.len() * chunks * PLANE_MOMENT_VEC4S];
    cpu::plane_sums(&params, &keys, &full.vertex_in_camera, &full.normal_in_camera, &pre.depth_unfiltered_m, &planes, &mut partials, &super::plane_keys::masks_of(&keys), planes.len() as u32);
    let (g, c) = run(chunks, &partials, planes.len() as u32);
    let sets = c.chunks(PLANE_MOMENT_VEC4S).map(|m| m.try_into().unwrap()).collect();
    (g, c, sets)
}

#[test]
fn a_real_frame_reduces_like_the_twin_and_fits_like_f64() {
    let (g, c, _) = real_moments();
    assert_moments_controls("real frame", &g, &c, first_full(&c));
    // The f64 reference's sums of the same planes, from its own labelling.
    let (pre, planes, _) = real_fixture();
    let fits: Vec<PlaneFit> = planes
        .iter()
        .map(|p| PlaneFit {
            sums: PlaneSums::default(),
            normal: [p[0], p[1], p[2]].map(f64::from),
            offset_m: f64::from(p[3]),
            centroid: [0.0; 3],
            tangents: [[0.0; 3]; 2],
            tangent_variance_m2: [0.0; 2],
            rms_m: 0.0,
            bend_deg: 0.0,
        })
        .collect();
    let (_, sums64) = reference::label(&pre.levels[0], &fits, &PlaneConfig::default(), Some(&pre.depth_unfiltered_m));
    for (k, (m, s64)) in g.chunks(PLANE_MOMENT_VEC4S).zip(&sums64).enumerate() {
        let m: PlaneMoments = m.try_into().unwrap();
        let (f32fit, f64fit) = (reference::fit(&plane_moments_to_sums(&m)).unwrap(), reference::fit(s64).unwrap());
        let angle = super::plane_fit::angle_deg(f32fit.normal, f64fit.normal);
        let offset = (f32fit.offset_m - f64fit.offset_m).abs();
        eprintln!("plane {k}: {} vs {} pixels, normal {angle:.5}° apart, offset {:.4} mm apart, rms {:.2} vs {:.2} mm", m[0][0], s64.count, offset * 1e3, f32fit.rms_m * 1e3, f64fit.rms_m * 1e3);
        assert!((f64::from(m[0][0]) - s64.count).abs() <= 1e-3 * s64.count, "plane {k}: the same pixels, but for a few at the distance limit");
        assert!(angle < 0.01 && offset < 1e-4, "plane {k}: f32 moments fit like f64 sums");
        assert!((f32fit.rms_m - f64fit.rms_m).abs() < 1e-3 * f64fit.rms_m.max(1e-3), "plane {k}: rms");
    }
}
