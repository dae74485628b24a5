// SPDX-License-Identifier: MIT
//! `intensity_pyramid_down`: the mean of a 2x2 block, `0.25 * ((a + b) + (c + d))` in the same
//! order on both sides, with the block clamped inside the finer image.

use webfusion_core::cpu;
use webfusion_core::kernels::intensity_pyramid_down::IntensityPyramidDownParams;
use webfusion_tests::{Tolerance, assert_negative_control, cast, compare_f32, finish, gpu, run_kernel};

use crate::preprocess::chain::real_cpu_chain;

/// Three correctly rounded additions in a fixed order and an exact multiplication by 0.25:
/// bit-exact on any IEEE-conforming device (lavapipe is); 1 ulp (2⁻²³ relative) is allowed
/// for a device that contracts or flushes differently.
const TOL: Tolerance = Tolerance { absolute: 0.0, relative: 1.2e-7 };

fn params(src_w: u32, src_h: u32, dst_w: u32, dst_h: u32) -> IntensityPyramidDownParams {
    IntensityPyramidDownParams { src_width_px: src_w, src_height_px: src_h, dst_width_px: dst_w, dst_height_px: dst_h }
}

fn run(p: &IntensityPyramidDownParams, src: &[f32]) -> (Vec<f32>, Vec<f32>) {
    assert_eq!(src.len(), (p.src_width_px * p.src_height_px) as usize, "source size");
    let gpu = gpu();
    let n = (p.dst_width_px * p.dst_height_px) as usize;
    let out = run_kernel(&gpu, &gpu.kernels.intensity_pyramid_down, p, &[bytemuck::cast_slice(src)], &[4 * n], [p.dst_width_px, p.dst_height_px, 1]);
    let mut c = vec![0.0; n];
    cpu::intensity_pyramid_down(p, src, &mut c);
    finish(&gpu);
    (cast(&out[0]), c)
}

/// `x + 100 y`: integers, so every 2x2 sum and its quarter are exact in f32.
fn ramp(w: u32, h: u32) -> Vec<f32> {
    (0..h).flat_map(|y| (0..w).map(move |x| (x + 100 * y) as f32)).collect()
}

/// The exact mean of the ramp over the block whose top-left corner is (x, y): (x + 0.5) + 100 (y + 0.5).
fn ramp_block_mean(x: u32, y: u32) -> f32 {
    x as f32 + 0.5 + 100.0 * (y as f32 + 0.5)
}

#[test]
fn ramp_has_exact_block_means() {
    let (w, h) = (64, 48);
    let p = params(w, h, w / 2, h / 2);
    let (g, c) = run(&p, &ramp(w, h));
    compare_f32("intensity_coarse", &g, &c, Tolerance::EXACT).unwrap();
    for gy in 0..h / 2 {
        for gx in 0..w / 2 {
            let got = g[(gy * w / 2 + gx) as usize];
            assert_eq!(got, ramp_block_mean(2 * gx, 2 * gy), "coarse pixel ({gx}, {gy})");
        }
    }
    assert_negative_control("intensity_coarse", &g, &c, TOL);
}

#[test]
fn odd_sizes_clamp_blocks_inside_the_image() {
    let (w, h) = (7, 5);
    // Rounded down (the pyramid's sizes): the last finer column and row are never read.
    let p = params(w, h, w / 2, h / 2);
    let (g, c) = run(&p, &ramp(w, h));
    compare_f32("intensity_coarse", &g, &c, Tolerance::EXACT).unwrap();
    let expected: Vec<f32> = (0..h / 2).flat_map(|gy| (0..w / 2).map(move |gx| ramp_block_mean(2 * gx, 2 * gy))).collect();
    assert_eq!(g, expected, "{w}x{h} -> {}x{}", w / 2, h / 2);
    // Rounded up: the last column (and row) of blocks would start at the image's last
    // column (row); the kernel clamps them to start one earlier, at w - 2 (h - 2).
    let (dw, dh) = (w.div_ceil(2), h.div_ceil(2));
    let p = params(w, h, dw, dh);
    let (g, c) = run(&p, &ramp(w, h));
    compare_f32("intensity_coarse", &g, &c, Tolerance::EXACT).unwrap();
    let expected: Vec<f32> = (0..dh).flat_map(|gy| (0..dw).map(move |gx| ramp_block_mean((2 * gx).min(w - 2), (2 * gy).min(h - 2)))).collect();
    assert_eq!(g, expected, "{w}x{h} -> {dw}x{dh}");
    assert_eq!(g[(dw - 1) as usize], ramp_block_mean(5, 0), "clamped last column averages columns 5 and 6");
    assert_negative_control("intensity_coarse", &g, &c, TOL);
}

#[test]
fn real_frame_matches_cpu() {
    let chain = real_cpu_chain();
    let k0 = chain.levels[0].intrinsics;
    // Levels 0 -> 1 -> 2, as the tracker's intensity pyramid, each from the CPU's finer level.
    let mut fine = chain.intensity.clone();
    for level in 1..3 {
        let (kf, kc) = (k0.pyramid_level(level - 1), k0.pyramid_level(level));
        let p = params(kf.width_px, kf.height_px, kc.width_px, kc.height_px);
        let (g, c) = run(&p, &fine);
        let what = format!("intensity[{level}]");
        let cmp = compare_f32(&what, &g, &c, TOL).unwrap();
        eprintln!("{what}: {cmp:?}");
        assert_eq!(cmp.invalid, 0, "{what}: intensity is never invalid");
        assert_negative_control(&what, &g, &c, TOL);
        fine = c;
    }
}
