// SPDX-License-Identifier: MIT
//! `label_colormap`: plane labels over the frame's colour, GPU against the CPU twin on a real
//! frame with the labels the reference's planes give it (padded rows), and the colours' rules
//! on crafted pixels.
//!
//! Tolerance: `trunc(255 c)` in f32; FMA contraction may round across an integer, so a channel
//! may differ by 1, and 99 % of the pixels must be identical.

use webfusion_core::cpu;
use webfusion_core::cpu::shared::plane_colour;
use webfusion_core::kernels::label_colormap::LabelColormapParams;
use webfusion_core::planes::NO_LABEL;
use webfusion_tests::{SENTINEL_F32, Slot, assert_negative_control_rgba8, cast, compare_rgba8, finish, gpu, run_kernel_slots};

use crate::planes::plane_keys::real_fixture;

fn colormap(p: &LabelColormapParams, labels: &[u32], color: &[[f32; 4]]) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let out_px = (p.row_stride_px * p.height_px) as usize;
    let out = run_kernel_slots(&gpu, &gpu.kernels.label_colormap, p, &[Slot::In(bytemuck::cast_slice(labels)), Slot::In(bytemuck::cast_slice(color)), Slot::Out(4 * out_px)], [p.width_px, p.height_px, 1]);
    finish(&gpu);
    let mut c = vec![SENTINEL_F32.to_bits(); out_px];
    cpu::label_colormap(p, labels, color, &mut c);
    (cast(&out[0]), c)
}

#[test]
fn a_real_frames_planes_match_the_twin() {
    let (pre, planes, labels) = real_fixture();
    let k = pre.levels[0].intrinsics;
    let p = LabelColormapParams { width_px: k.width_px, height_px: k.height_px, row_stride_px: 704, label_count: planes.len() as u32 };
    let (g, c) = colormap(&p, &labels, &pre.color);
    compare_rgba8("label view", &g, &c, 1, 0.99).unwrap();
    assert_negative_control_rgba8("label view", &g, &c, 1, 0.99);
    assert!(g.chunks(704).all(|row| row[640..].iter().all(|&px| px == SENTINEL_F32.to_bits())), "padding untouched");
}

#[test]
fn planes_are_coloured_and_the_rest_greyed() {
    let p = LabelColormapParams { width_px: 4, height_px: 1, row_stride_px: 64, label_count: 2 };
    let color = [[1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0], [1.0, 1.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0]];
    let labels = [NO_LABEL, 0, 1, 2];
    let (g, c) = colormap(&p, &labels, &color);
    compare_rgba8("crafted", &g, &c, 1, 0.75).unwrap();
    let px: Vec<[u8; 4]> = c[..4].iter().map(|p| p.to_le_bytes()).collect();
    let expect = |v: f32| (v.clamp(0.0, 1.0) * 255.0) as u8;
    let grey = expect(0.4 * 0.299);
    assert_eq!(px[0], [grey, grey, grey, 255], "no plane: grey");
    assert_eq!(&px[1][..3], &plane_colour(0).map(|v| expect(0.6 * v)), "plane 0 over black");
    assert_eq!(&px[3][..3], &[expect(0.4); 3], "a label past the count is no plane");
    assert_ne!(plane_colour(0), plane_colour(1), "planes differ");
}
