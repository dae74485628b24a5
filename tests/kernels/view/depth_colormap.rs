// SPDX-License-Identifier: MIT
//! `depth_colormap`: raw depth through the shared depth colour map, GPU against the CPU twin
//! on a real Kinect frame and on a synthetic ramp with padded rows (padding never written), and
//! the map's fixed points (no return is opaque black, near is dark blue, the far end yellow).
//!
//! Tolerance: each channel is `trunc(255 · polynomial)` in f32; FMA contraction may put a value
//! on the other side of an integer, so a channel may differ by 1, and 99 % of the pixels must be
//! identical.

use webfusion_core::cpu;
use webfusion_core::kernels::depth_colormap::DepthColormapParams;
use webfusion_core::view::{DEFAULT_DEPTH_VIEW_MAX_M, ROW_ALIGN_PX};
use webfusion_tests::{SENTINEL_F32, Slot, assert_negative_control_rgba8, cast, compare_rgba8, finish, gpu, run_kernel_slots, sample_frame};

const MAX_CHANNEL_DIFF: u8 = 1;
const MIN_EXACT: f64 = 0.99;

fn colormap(p: &DepthColormapParams, depth: &[u16]) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let out_px = (p.row_stride_px * p.height_px) as usize;
    let packed = cpu::shared::pack_u16_pairs(depth);
    let out = run_kernel_slots(&gpu, &gpu.kernels.depth_colormap, p, &[Slot::In(bytemuck::cast_slice(&packed)), Slot::Out(4 * out_px)], [p.width_px, p.height_px, 1]);
    finish(&gpu);
    let mut c = vec![SENTINEL_F32.to_bits(); out_px];
    cpu::depth_colormap(p, depth, &mut c);
    (cast(&out[0]), c)
}

#[test]
fn a_real_frame_matches_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let (w, h) = (frame.depth.width_px, frame.depth.height_px);
    let p = DepthColormapParams {
        width_px: w,
        height_px: h,
        row_stride_px: w.next_multiple_of(ROW_ALIGN_PX),
        metres_per_unit: 1.0 / calibration.depth_units_per_metre,
        max_depth_m: DEFAULT_DEPTH_VIEW_MAX_M,
        ..Default::default()
    };
    let (g, c) = colormap(&p, &frame.depth.units);
    let exact = compare_rgba8("depth view", &g, &c, MAX_CHANNEL_DIFF, MIN_EXACT).unwrap();
    assert_negative_control_rgba8("depth view", &g, &c, MAX_CHANNEL_DIFF, MIN_EXACT);
    let black = c.iter().filter(|&&p| p == 0xff00_0000).count();
    assert!(black > 0 && black < c.len() / 2, "holes are black, most of the frame is not ({black} of {})", c.len());
    eprintln!("depth view: {exact} of {} pixels identical", c.len());
}

#[test]
fn a_ramp_with_padded_rows_and_the_maps_fixed_points() {
    // 100 px wide rows 128 px apart: the padding must stay untouched.
    let (w, h) = (100u32, 6u32);
    let p = DepthColormapParams { width_px: w, height_px: h, row_stride_px: 128, metres_per_unit: 0.001, max_depth_m: 4.0, ..Default::default() };
    // Row 0: no return; rows 1..: 0 to 5 m across the row.
    let depth: Vec<u16> = (0..w * h).map(|i| if i < w { 0 } else { ((i % w) * 50) as u16 }).collect();
    let (g, c) = colormap(&p, &depth);
    compare_rgba8("ramp", &g, &c, MAX_CHANNEL_DIFF, MIN_EXACT).unwrap();
    assert_negative_control_rgba8("ramp", &g, &c, MAX_CHANNEL_DIFF, MIN_EXACT);
    let at = |x: u32, y: u32| g[(y * p.row_stride_px + x) as usize].to_le_bytes();
    assert!((0..w).all(|x| at(x, 0) == [0, 0, 0, 255]), "no return: opaque black");
    let (near, far) = (at(1, 1), at(99, 1));
    assert!(near[2] > near[0] && near[2] > near[1], "near is blue: {near:?}");
    assert!(far[0] > 200 && far[1] > 200 && far[2] < 80, "the far end (beyond max) is yellow: {far:?}");
    assert_eq!(at(90, 2), at(99, 2), "depth beyond max_depth_m saturates");
    for y in 0..h {
        for x in w..p.row_stride_px {
            assert_eq!(g[(y * p.row_stride_px + x) as usize], SENTINEL_F32.to_bits(), "padding ({x}, {y}) untouched");
        }
    }
}
