// SPDX-License-Identifier: MIT
//! `plane_rectify`: texture rectification against the CPU twin, per plane of the synthetic
//! room corner (exact; the texels of each plane show its checker colours) and of a real frame
//! (the reference's planes and completed labels). Tolerance: at least 99.9 % of the texels
//! identical (a texel centre projecting to a pixel's edge may round either way: WGSL may fuse
//! the projection's multiply-adds). Negative controls: a covered texel emptied, a colour
//! changed, a sentinel, the grid shifted by a row.

use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::planes::mesh::{blend_reach_px, complete_labels, frame_plane_grid, pack_rgba8, rectify_params};
use webfusion_core::planes::{PlaneConfig, reference};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::sim::plane_scenes::{PlaneScene, UNITS_PER_METRE};
use webfusion_core::{PinholeIntrinsics, RgbdCalibration, RgbdFrame};
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };

/// At most 1 ‰ of the texels different.
fn compare(what: &str, g: &[u32], c: &[u32]) -> Result<usize, String> {
    webfusion_tests::compare_u32_mostly(what, g, c, 1)
}

/// Rectifies every plane of `frame`'s reference segmentation on both sides; returns the
/// covered texels over all planes.
fn check(what: &str, calibration: &RgbdCalibration, frame: &RgbdFrame) -> usize {
    let gpu = gpu();
    let k = calibration.intrinsics;
    let pre = preprocess(calibration, &PreprocessConfig::default(), frame);
    let config = PlaneConfig::default();
    let seg = reference::segment(&pre.levels, Some(&pre.depth_unfiltered_m), &config);
    assert!(seg.planes.len() >= 2, "{what}: planes to rectify");
    let labels = complete_labels(&seg, &pre.depth_unfiltered_m, &k, &config, blend_reach_px(&PreprocessConfig::default()));
    let colour = pack_rgba8(&frame.color);
    let mut covered_total = 0;
    for (i, plane) in seg.planes.iter().enumerate() {
        let grid = frame_plane_grid(plane, i as u32, &labels, &k).expect("a grid");
        let p = rectify_params(&grid, &k, i as u32);
        let n = (grid.width * grid.height) as usize;
        let out = run_kernel_slots(&gpu, &gpu.kernels.plane_rectify, &p, &[Slot::In(bytemuck::cast_slice(&labels)), Slot::In(bytemuck::cast_slice(&colour)), Slot::Out(4 * n)], [grid.width, grid.height, 1]);
        let g: Vec<u32> = cast(&out[0]);
        let mut c = vec![0u32; n];
        cpu::plane_rectify(&p, &labels, &colour, &mut c);
        let name = format!("{what} plane {i}");
        let differ = compare(&name, &g, &c).unwrap();
        let covered: Vec<usize> = (0..n).filter(|&t| c[t] >> 24 != 0).collect();
        eprintln!("{name}: {}x{} texels at {} px/m, {} covered, {differ} differ", grid.width, grid.height, grid.px_per_m, covered.len());
        assert!(covered.len() > 1000, "{name}: the plane covers {} texels of its box", covered.len());
        covered_total += covered.len();
        let (mut emptied, mut recoloured, mut sentinel) = (g.clone(), g.clone(), g.clone());
        // More than the tolerance (n / 1000) of texels, spread over the plane.
        let spoil = n / 500 + 1;
        assert!(covered.len() >= spoil, "{name}: too few covered texels for the controls");
        for &t in covered.iter().step_by(covered.len() / spoil).take(spoil) {
            emptied[t] = 0;
            recoloured[t] ^= 0x10;
            sentinel[t] = webfusion_tests::SENTINEL_F32.to_bits();
        }
        let w = grid.width as usize;
        let mut shifted = g[w..].to_vec();
        shifted.extend_from_slice(&g[..w]);
        for (case, bad) in [("emptied texels", emptied), ("changed colours", recoloured), ("sentinels", sentinel), ("a shifted grid", shifted)] {
            assert!(compare(&name, &bad, &c).is_err(), "{name}: the comparison accepted {case}");
        }
    }
    finish(&gpu);
    covered_total
}

#[test]
fn room_corner_planes_rectify_like_the_twin() {
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 };
    let frame = PlaneScene::room_corner().render(&K, None).frame;
    check("room corner", &calibration, &frame);
}

#[test]
fn a_real_frame_rectifies_like_the_twin() {
    let (calibration, frame) = sample_frame(0);
    check("real frame", &calibration, &frame);
}
