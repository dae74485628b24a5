// SPDX-License-Identifier: MIT
//! `normal_colormap`: normals through the shared normal colour map, GPU against the CPU twin on
//! a real frame's normals (holes included) with padded rows, and the map's fixed points.
//!
//! Tolerance: `trunc(255 · (0.5 - 0.5 n))` in f32; FMA contraction may round across an
//! integer, so a channel may differ by 1, and 99 % of the pixels must be identical.

use webfusion_core::cpu;
use webfusion_core::kernels::normal_colormap::NormalColormapParams;
use webfusion_tests::{SENTINEL_F32, Slot, assert_negative_control_rgba8, cast, compare_rgba8, finish, gpu, run_kernel_slots};

use crate::preprocess::chain::real_cpu_chain;

const MAX_CHANNEL_DIFF: u8 = 1;
const MIN_EXACT: f64 = 0.99;

fn colormap(p: &NormalColormapParams, normals: &[[f32; 4]]) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let out_px = (p.row_stride_px * p.height_px) as usize;
    let out = run_kernel_slots(&gpu, &gpu.kernels.normal_colormap, p, &[Slot::In(bytemuck::cast_slice(normals)), Slot::Out(4 * out_px)], [p.width_px, p.height_px, 1]);
    finish(&gpu);
    let mut c = vec![SENTINEL_F32.to_bits(); out_px];
    cpu::normal_colormap(p, normals, &mut c);
    (cast(&out[0]), c)
}

#[test]
fn a_real_normal_map_matches_the_twin() {
    let chain = real_cpu_chain();
    // Level 1 (320 px) in rows 384 px apart: the padding must stay untouched.
    let l = &chain.levels[1];
    let k = l.intrinsics;
    let p = NormalColormapParams { width_px: k.width_px, height_px: k.height_px, row_stride_px: 384, ..Default::default() };
    let (g, c) = colormap(&p, &l.normal_in_camera);
    compare_rgba8("normal view", &g, &c, MAX_CHANNEL_DIFF, MIN_EXACT).unwrap();
    assert_negative_control_rgba8("normal view", &g, &c, MAX_CHANNEL_DIFF, MIN_EXACT);
    let black = g.iter().filter(|&&p| p == 0xff00_0000).count();
    assert!(black > 0 && black < (k.pixel_count()) / 2, "holes are black, most of the frame is not ({black})");
}

#[test]
fn the_maps_fixed_points() {
    let p = NormalColormapParams { width_px: 4, height_px: 1, row_stride_px: 64, ..Default::default() };
    let normals = [[f32::NAN; 4], [0.0, 0.0, -1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0]];
    let (g, c) = colormap(&p, &normals);
    compare_rgba8("fixed points", &g, &c, 0, 1.0).unwrap();
    let px: Vec<[u8; 4]> = g[..4].iter().map(|p| p.to_le_bytes()).collect();
    assert_eq!(px, vec![[0, 0, 0, 255], [127, 127, 255, 255], [0, 127, 127, 255], [127, 255, 127, 255]], "none black, facing the camera blue, +x dark red, up (-y) green");
}
