// SPDX-License-Identifier: MIT
//! `plane_window`: the planes within reach of each pixel, along rows then columns, against the
//! CPU twin (bit for bit: integer work) on a real frame's segmentation and on labels with
//! planes past the table, and the two passes against the direct (2r + 1)² window they stand
//! for. Negative controls: a bit dropped, a bit added, a sentinel, the image shifted by a row.

use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::planes::mesh::{plane_window_params, window_masks};
use webfusion_core::planes::{NO_LABEL, PlaneConfig, reference};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::PinholeIntrinsics;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

const REACH: u32 = 4;

/// Both passes on the GPU and on the twin: (GPU rows, GPU window, twin rows, twin window).
fn run(k: &PinholeIntrinsics, labels: &[u32], count: u32) -> (Vec<[u32; 2]>, Vec<[u32; 2]>, Vec<[u32; 2]>, Vec<[u32; 2]>) {
    let gpu = gpu();
    let n = labels.len();
    let pass = |axis: u32, masks_in: &[[u32; 2]]| -> Vec<[u32; 2]> {
        let out = run_kernel_slots(
            &gpu,
            &gpu.kernels.plane_window,
            &plane_window_params(k, REACH, axis),
            &[Slot::In(bytemuck::cast_slice(labels)), Slot::In(bytemuck::bytes_of(&count)), Slot::In(bytemuck::cast_slice(masks_in)), Slot::Out(8 * n)],
            [k.width_px, k.height_px, 1],
        );
        cast(&out[0])
    };
    let rows = pass(0, &[[0, 0]]);
    let window = pass(1, &rows);
    finish(&gpu);
    let mut c_rows = vec![[0u32; 2]; n];
    cpu::plane_window(&plane_window_params(k, REACH, 0), labels, &[count], &[], &mut c_rows);
    let mut c_window = vec![[0u32; 2]; n];
    cpu::plane_window(&plane_window_params(k, REACH, 1), labels, &[count], &c_rows, &mut c_window);
    (rows, window, c_rows, c_window)
}

fn compare(what: &str, g: &[[u32; 2]], c: &[[u32; 2]]) -> Result<(), String> {
    match g.iter().zip(c).position(|(a, b)| a != b) {
        Some(i) => Err(format!("{what}: pixel {i}: GPU {:?} vs CPU {:?}", g[i], c[i])),
        None if g.len() != c.len() => Err(format!("{what}: {} vs {} pixels", g.len(), c.len())),
        None => Ok(()),
    }
}

fn assert_same_with_controls(what: &str, g: &[[u32; 2]], c: &[[u32; 2]], width: usize) {
    compare(what, g, c).unwrap();
    let i = c.iter().position(|m| m[0] != 0).expect("a pixel near a plane");
    let (mut dropped, mut added, mut sentinel) = (g.to_vec(), g.to_vec(), g.to_vec());
    dropped[i][0] &= dropped[i][0] - 1;
    added[i][1] |= 1 << 31;
    sentinel[i] = [webfusion_tests::SENTINEL_F32.to_bits(); 2];
    let mut shifted = g[width..].to_vec();
    shifted.extend_from_slice(&g[..width]);
    for (case, bad) in [("a dropped plane", dropped), ("an added plane", added), ("a sentinel", sentinel), ("a shifted image", shifted)] {
        assert!(compare(what, &bad, c).is_err(), "{what}: the comparison accepted {case}");
    }
}

/// The planes below `count` labelling a pixel of the (2 REACH + 1)² window around each pixel.
fn direct_window(k: &PinholeIntrinsics, labels: &[u32], count: u32) -> Vec<[u32; 2]> {
    let (w, h, r) = (k.width_px as i64, k.height_px as i64, i64::from(REACH));
    let mut out = vec![[0u32; 2]; labels.len()];
    for y in 0..h {
        for x in 0..w {
            for v in (y - r).max(0)..=(y + r).min(h - 1) {
                for u in (x - r).max(0)..=(x + r).min(w - 1) {
                    let m = labels[(v * w + u) as usize];
                    if m < count {
                        out[(y * w + x) as usize][(m / 32) as usize] |= 1 << (m % 32);
                    }
                }
            }
        }
    }
    out
}

#[test]
fn a_real_frames_planes_gather_like_the_twin_and_the_direct_window() {
    let (calibration, frame) = sample_frame(0);
    let k = calibration.intrinsics;
    let pre = preprocess(&calibration, &PreprocessConfig::default(), &frame);
    let seg = reference::segment(&pre.levels, Some(&pre.depth_unfiltered_m), &PlaneConfig::default());
    let count = seg.planes.len() as u32;
    assert!(count >= 2, "planes to gather");
    let (rows, window, c_rows, c_window) = run(&k, &seg.labels, count);
    assert_same_with_controls("rows", &rows, &c_rows, k.width_px as usize);
    assert_same_with_controls("window", &window, &c_window, k.width_px as usize);
    assert_eq!(c_window, direct_window(&k, &seg.labels, count), "the two passes are the window");
    assert_eq!(c_window, window_masks(&seg.labels, count, &k, REACH), "the helper runs both passes");
    let near = c_window.iter().filter(|m| m[0].count_ones() >= 2).count();
    eprintln!("{near} pixels within reach of two planes or more");
    assert!(near > 100, "borders between planes");
}

#[test]
fn labels_past_the_table_and_in_the_second_word_are_gathered_like_the_twin() {
    // 64 x 48 pixels of stripes: labels 0..70 (64 and up past MAX_PLANES, 40 and up past the
    // table of 40), NO_LABEL between them.
    let k = PinholeIntrinsics { fx_px: 50.0, fy_px: 50.0, cx_px: 31.5, cy_px: 23.5, width_px: 64, height_px: 48 };
    let labels: Vec<u32> = (0..64 * 48u32).map(|i| if (i / 3) % 4 == 3 { NO_LABEL } else { (i / 7) % 71 }).collect();
    let (rows, window, c_rows, c_window) = run(&k, &labels, 40);
    assert_same_with_controls("stripes, rows", &rows, &c_rows, 64);
    assert_same_with_controls("stripes, window", &window, &c_window, 64);
    assert_eq!(c_window, direct_window(&k, &labels, 40));
    assert!(c_window.iter().any(|m| m[1] != 0), "planes 32..40 in the second word");
    assert!(c_window.iter().all(|m| m[1] >> 8 == 0), "nothing past the table");
}
