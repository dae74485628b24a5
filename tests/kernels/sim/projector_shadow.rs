// SPDX-License-Identifier: MIT
//! `projector_shadow`: the IR projector's shadow, GPU against the CPU twin (bit-exact: one
//! subtraction and one division per pixel, compared with the same f32 operations) on a wall
//! behind a box and on a real Kinect frame, and the shadow's geometry: beside the box on the
//! projector's far side, b·f_x·(1/z_box − 1/z_wall) pixels wide, none on the other side, and the
//! mirror image when the projector is on the other side.

use webfusion_core::cpu;
use webfusion_core::kernels::GpuIntrinsics;
use webfusion_core::kernels::projector_shadow::ProjectorShadowParams;
use webfusion_core::sim::sensor::KinectModel;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

const W: u32 = 320;
const H: u32 = 240;
const WALL_M: f32 = 2.5;
const BOX_M: f32 = 1.0;
const BOX_COLUMNS: std::ops::Range<u32> = 100..160;

fn run(p: &ProjectorShadowParams, depth: &[f32]) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let n = depth.len();
    let out = run_kernel_slots(&gpu, &gpu.kernels.projector_shadow, p, &[Slot::In(bytemuck::cast_slice(depth)), Slot::Out(4 * n)], [p.intrinsics.height_px, 1, 1]);
    finish(&gpu);
    (cast(&out[0]), cpu::projector_shadow(p, depth))
}

fn assert_same(what: &str, g: &[u32], c: &[u32]) {
    let differ = g.iter().zip(c).filter(|(a, b)| a != b).count();
    assert_eq!(differ, 0, "{what}: {differ} pixels differ");
    // Negative controls: a flipped pixel, an unwritten (sentinel) pixel.
    let mut flipped = g.to_vec();
    flipped[0] ^= 1;
    assert_ne!(flipped, c, "{what}: a flipped pixel must differ");
    let mut sentinel = g.to_vec();
    sentinel[1] = webfusion_tests::SENTINEL_F32.to_bits();
    assert_ne!(sentinel, c, "{what}: a sentinel must differ");
}

#[test]
fn a_box_casts_the_geometric_shadow_on_the_wall() {
    let k = GpuIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: W, height_px: H, ..Default::default() };
    let depth: Vec<f32> = (0..W * H).map(|i| if BOX_COLUMNS.contains(&(i % W)) && (70..170).contains(&(i / W)) { BOX_M } else if i % W < 10 { cpu::shared::INVALID } else { WALL_M }).collect();
    let model = KinectModel::default();
    let p = model.shadow_params(k);
    let (g, c) = run(&p, &depth);
    assert_same("shadow", &g, &c);
    let row = 120;
    let dark = |img: &[u32], x: u32| img[(row * W + x) as usize] == 1;
    let width = model.baseline_m * k.fx_px * (1.0 / BOX_M - 1.0 / WALL_M);
    let left = (0..BOX_COLUMNS.start).rev().take_while(|&x| dark(&g, x)).count() as f32;
    let right = (BOX_COLUMNS.end..W).take_while(|&x| dark(&g, x)).count();
    eprintln!("shadow {left} px (geometry {width:.1}), {right} px on the other side");
    assert!((left - width).abs() <= 1.0, "shadow of {left} px, geometry says {width}");
    assert_eq!(right, 0, "no shadow on the side away from the projector");
    assert!((0..W).filter(|&x| !(60..BOX_COLUMNS.start).contains(&x)).all(|x| !dark(&g, x)), "nothing else is dark on the row");
    assert!((0..W * H).filter(|i| (i / W) < 60).all(|i| g[i as usize] == 0), "rows without the box are lit");
    // The projector on the other side: the mirror image.
    let mirrored = ProjectorShadowParams { baseline_m: -p.baseline_m, ..p };
    let (gm, cm) = run(&mirrored, &depth);
    assert_same("mirrored", &gm, &cm);
    let right = (BOX_COLUMNS.end..W).take_while(|&x| dark(&gm, x)).count() as f32;
    assert!((right - width).abs() <= 1.0 && !dark(&gm, BOX_COLUMNS.start - 1), "mirrored shadow of {right} px");
}

#[test]
fn a_real_frame_matches_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let depth: Vec<f32> = frame.depth.units.iter().map(|&u| if u == 0 { cpu::shared::INVALID } else { f32::from(u) / calibration.depth_units_per_metre }).collect();
    let p = KinectModel::default().shadow_params(GpuIntrinsics::from(calibration.intrinsics));
    let (g, c) = run(&p, &depth);
    assert_same("real frame", &g, &c);
    let dark = g.iter().filter(|&&v| v == 1).count();
    eprintln!("real frame: {dark} of {} pixels in the projector's shadow", g.len());
    assert!(dark > 0 && dark < g.len() / 20, "some, not many, pixels are shadowed: {dark}");
}
