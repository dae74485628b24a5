// SPDX-License-Identifier: MIT
//! `plane_label`: the final per-pixel labelling against the CPU twin, on the box scene with its
//! true planes (every pixel of a true plane within the tolerance gets it; the board-on-wall
//! scene's wall pixels 2 cm behind the board's plane get the wall) and on a real frame with the
//! reference's planes. Tolerance: at least 99.9 % of the labels identical (a pixel at the angle
//! or distance limit may fall either way: WGSL's dot may fuse).

use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::{CpuPyramidLevel, preprocess};
use webfusion_core::kernels::plane_label::PlaneLabelParams;
use webfusion_core::planes::{NO_LABEL, PlaneConfig, reference};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::sim::plane_scenes::{NO_PLANE, PlaneScene, UNITS_PER_METRE};
use webfusion_core::{PinholeIntrinsics, RgbdCalibration, RgbdFrame};
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };

fn full_level(calibration: &RgbdCalibration, frame: &RgbdFrame) -> CpuPyramidLevel {
    preprocess(calibration, &PreprocessConfig::default(), frame).levels.swap_remove(0)
}

fn run(level: &CpuPyramidLevel, planes: &[[f32; 4]]) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let config = PlaneConfig::default();
    let n = level.vertex_in_camera.len();
    let p = PlaneLabelParams { pixel_count: n as u32, cos_label: config.label_angle_deg.to_radians().cos(), min_distance_m: config.label_min_distance_m, ..Default::default() };
    let count = planes.len() as u32;
    let planes_buf: Vec<[f32; 4]> = if planes.is_empty() { vec![[0.0; 4]] } else { planes.to_vec() };
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.plane_label,
        &p,
        &[Slot::In(bytemuck::cast_slice(&level.vertex_in_camera)), Slot::In(bytemuck::cast_slice(&level.normal_in_camera)), Slot::In(bytemuck::cast_slice(&planes_buf)), Slot::In(bytemuck::bytes_of(&count)), Slot::Out(4 * n)],
        [n as u32, 1, 1],
    );
    finish(&gpu);
    let mut c = vec![0u32; n];
    cpu::plane_label(&p, &level.vertex_in_camera, &level.normal_in_camera, &planes_buf, &[count], &mut c);
    (cast(&out[0]), c)
}

/// At most 1 ‰ of the labels different.
fn compare(what: &str, g: &[u32], c: &[u32]) -> Result<usize, String> {
    webfusion_tests::compare_u32_mostly(what, g, c, 1)
}

fn assert_same_with_controls(what: &str, g: &[u32], c: &[u32]) {
    compare(what, g, c).unwrap();
    let labelled: Vec<usize> = (0..c.len()).filter(|&i| c[i] != NO_LABEL).take(c.len() / 500 + 1).collect();
    assert!(!labelled.is_empty(), "{what}: a control needs labelled pixels");
    let mut unlabelled = g.to_vec();
    let mut relabelled = g.to_vec();
    let mut sentinel = g.to_vec();
    for &i in &labelled {
        unlabelled[i] = NO_LABEL;
        relabelled[i] = c[i] + 1;
        sentinel[i] = webfusion_tests::SENTINEL_F32.to_bits();
    }
    for (case, bad) in [("unlabelled pixels", unlabelled), ("other planes", relabelled), ("sentinels", sentinel)] {
        assert!(compare(what, &bad, c).is_err(), "{what}: the comparison accepted {case}");
    }
}

fn true_planes(scene: &PlaneScene) -> Vec<[f32; 4]> {
    scene.planes_in_camera().iter().map(|p| p.map_or([0.0, 0.0, 0.0, 1e9], |p| [p.normal.x as f32, p.normal.y as f32, p.normal.z as f32, p.offset_m as f32])).collect()
}

#[test]
fn true_planes_label_their_pixels_and_parallel_planes_stay_apart() {
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 };
    for scene in [PlaneScene::box_on_floor(), PlaneScene::whiteboard()] {
        let r = scene.render(&K, None);
        let level = full_level(&calibration, &r.frame);
        let (g, c) = run(&level, &true_planes(&scene));
        assert_same_with_controls(scene.name, &g, &c);
        // Pixels labelled: each with its own surface, but for a rim along the borders.
        let (mut right, mut wrong) = (0usize, 0usize);
        for (ix, &l) in g.iter().enumerate() {
            if l != NO_LABEL && r.plane_of_pixel[ix] != NO_PLANE {
                if l == r.plane_of_pixel[ix] { right += 1 } else { wrong += 1 }
            }
        }
        eprintln!("{}: {right} pixels on their own plane, {wrong} on another", scene.name);
        assert!(wrong * 100 < right, "{}: {wrong} of {} pixels on another plane", scene.name, right + wrong);
        assert!(right * 10 > 8 * r.plane_of_pixel.iter().filter(|&&l| l != NO_PLANE).count(), "{}: most plane pixels labelled", scene.name);
    }
    // No planes: nothing labelled.
    let r = PlaneScene::room_corner().render(&K, None);
    let (g, c) = run(&full_level(&calibration, &r.frame), &[]);
    compare("no planes", &g, &c).unwrap();
    assert!(g.iter().all(|&l| l == NO_LABEL));
}

#[test]
fn a_real_frame_labels_like_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let pre = preprocess(&calibration, &PreprocessConfig::default(), &frame);
    let seg = reference::segment(&pre.levels, Some(&pre.depth_unfiltered_m), &PlaneConfig::default());
    assert!(seg.planes.len() >= 2, "the reference finds the desk and the partition");
    let planes: Vec<[f32; 4]> = seg.planes.iter().map(|p| [p.normal[0], p.normal[1], p.normal[2], p.offset_m]).collect();
    let (g, c) = run(&pre.levels[0], &planes);
    assert_same_with_controls("real frame", &g, &c);
}
