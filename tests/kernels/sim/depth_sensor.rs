// SPDX-License-Identifier: MIT
//! `depth_sensor`: the virtual Kinect's raw depth from a raycast, GPU against the CPU twin, on a
//! synthetic scene with exact answers (a wall 2.5 m away behind a box 1 m away, seen from a
//! pose away from the origin) and on a real Kinect frame taken as the model.
//!
//! Exact mode: every pixel equals round(depth · units) and GPU and twin agree on every pixel;
//! radial distances agree within one unit (WGSL's sqrt need not be correctly rounded);
//! out-of-range depths are 0.
//!
//! Kinect mode: the noise is a function of (seed, frame, pixel) only. GPU transcendental
//! functions (log, cos, acos, sqrt) are not correctly rounded, so a lateral sample may round to
//! the neighbouring pixel, or a noisy depth land on the other side of a disparity step, for a few
//! pixels: at least 99 % must be identical, and the rest within one disparity step or a
//! dropout. The model's physics are checked on the synthetic scene: the wall's error statistics
//! against σ_z and the quantisation step, the projector's shadow beside the box at the width
//! geometry gives, no shadow on the other side, and reproducibility.

use webfusion_core::cpu;
use webfusion_core::cpu::sim::depth_sensor::SensorInput;
use webfusion_core::kernels::GpuIntrinsics;
use webfusion_core::kernels::depth_sensor::DepthSensorParams;
use webfusion_core::kernels::gpu_data::CameraPose;
use webfusion_core::sim::sensor::KinectModel;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

const MIN_EXACT: f64 = 0.99;

/// A raycast-like input: depth along z, world vertices and normals, at a camera pose.
struct Scene {
    k: GpuIntrinsics,
    pose: CameraPose,
    depth_m: Vec<f32>,
    vertex: Vec<[f32; 4]>,
    normal: Vec<[f32; 4]>,
    /// The projector's shadow (`projector_shadow`'s twin; its own test checks the GPU).
    shadow: Vec<u32>,
}

impl Scene {
    fn input(&self) -> SensorInput<'_> {
        SensorInput { depth_m: &self.depth_m, vertex_in_world: &self.vertex, normal_in_world: &self.normal, shadow: &self.shadow }
    }
}

/// World from camera: rotated 30° about y and 10° about x, camera at (1, -0.5, 2) m.
fn pose() -> [[f32; 4]; 4] {
    let r = glam::Mat3::from_rotation_y(30f32.to_radians()) * glam::Mat3::from_rotation_x(10f32.to_radians());
    let mut cols = glam::Mat4::from_mat3(r).to_cols_array_2d();
    cols[3] = [1.0, -0.5, 2.0, 1.0];
    cols
}

/// Builds a scene from per-pixel camera-frame depth and camera-frame normals.
fn scene(k: GpuIntrinsics, depth_m: Vec<f32>, normal_cam: impl Fn(usize) -> [f32; 3]) -> Scene {
    let m = pose();
    let pose = cpu::shared::camera_pose(&m, 1);
    let w = k.width_px as usize;
    let mut vertex = Vec::with_capacity(depth_m.len());
    let mut normal = Vec::with_capacity(depth_m.len());
    for (i, &z) in depth_m.iter().enumerate() {
        if !cpu::shared::is_valid_f32(z) {
            vertex.push(cpu::shared::INVALID_VEC4);
            normal.push(cpu::shared::INVALID_VEC4);
            continue;
        }
        let p = cpu::shared::back_project(&k, (i % w) as f32, (i / w) as f32, z);
        let v = cpu::shared::transform_point(&m, p);
        vertex.push([v[0], v[1], v[2], 1.0]);
        let n = normal_cam(i);
        if cpu::shared::is_valid_f32(n[0]) {
            let nw = cpu::shared::transform_vector(&m, n);
            normal.push([nw[0], nw[1], nw[2], 0.0]);
        } else {
            normal.push(cpu::shared::INVALID_VEC4);
        }
    }
    let shadow = cpu::projector_shadow(&KinectModel::default().shadow_params(k), &depth_m);
    Scene { k, pose, depth_m, vertex, normal, shadow }
}

const W: u32 = 320;
const H: u32 = 240;
const WALL_M: f32 = 2.5;
const BOX_M: f32 = 1.0;
const BOX_COLUMNS: std::ops::Range<u32> = 100..160;
const BOX_ROWS: std::ops::Range<u32> = 70..170;

/// A fronto-parallel wall at 2.5 m with a box face at 1 m in front of part of it; a hole (no
/// surface) in the top-left corner.
fn wall_and_box() -> Scene {
    let k = GpuIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: W, height_px: H, ..Default::default() };
    let depth: Vec<f32> = (0..W * H)
        .map(|i| {
            let (x, y) = (i % W, i / W);
            if x < 20 && y < 20 {
                cpu::shared::INVALID
            } else if BOX_COLUMNS.contains(&x) && BOX_ROWS.contains(&y) {
                BOX_M
            } else {
                WALL_M
            }
        })
        .collect();
    scene(k, depth, |_| [0.0, 0.0, -1.0])
}

fn params(k: GpuIntrinsics, noise: bool, seed: u32) -> DepthSensorParams {
    let model = KinectModel::default();
    let mut p = model.params(k, 5000.0, noise);
    p.seed = seed;
    p
}

fn run(p: &DepthSensorParams, s: &Scene) -> (Vec<u16>, Vec<u16>) {
    run_with(p, s, None)
}

/// [`run`] through the pipeline compiled with `constants` (the kernel's default when `None`).
fn run_with(p: &DepthSensorParams, s: &Scene, constants: Option<&[(&str, f64)]>) -> (Vec<u16>, Vec<u16>) {
    let gpu = gpu();
    let n = (p.intrinsics.width_px * p.intrinsics.height_px) as usize;
    let words = n.div_ceil(2);
    let specialised = constants.map(|c| gpu.kernels.depth_sensor.specialised(c));
    let out = run_kernel_slots(
        &gpu,
        specialised.as_ref().unwrap_or(&gpu.kernels.depth_sensor),
        p,
        &[Slot::In(bytemuck::bytes_of(&s.pose)), Slot::In(bytemuck::cast_slice(&s.depth_m)), Slot::In(bytemuck::cast_slice(&s.vertex)), Slot::In(bytemuck::cast_slice(&s.normal)), Slot::In(bytemuck::cast_slice(&s.shadow)), Slot::Out(4 * words)],
        [words as u32, 1, 1],
    );
    finish(&gpu);
    let packed: Vec<u32> = cast(&out[0]);
    let g: Vec<u16> = (0..n).map(|i| (packed[i / 2] >> (16 * (i & 1))) as u16).collect();
    (g, cpu::depth_sensor(p, &s.pose, s.input()))
}

/// Raw depth: at least `min_exact` of the pixels identical, the rest a dropout on one side or
/// within `max_diff` units.
fn compare_raw(what: &str, g: &[u16], c: &[u16], max_diff: u16, min_exact: f64) -> Result<usize, String> {
    if g.len() != c.len() {
        return Err(format!("{what}: {} GPU pixels vs {} CPU", g.len(), c.len()));
    }
    let mut exact = 0;
    for (i, (&a, &b)) in g.iter().zip(c).enumerate() {
        if a == b {
            exact += 1;
        } else if a != 0 && b != 0 && a.abs_diff(b) > max_diff {
            return Err(format!("{what}[{i}]: GPU {a} vs CPU {b} units"));
        }
    }
    if (exact as f64) < min_exact * g.len() as f64 {
        return Err(format!("{what}: only {exact} of {} pixels identical (need {min_exact})", g.len()));
    }
    Ok(exact)
}

/// Proves [`compare_raw`] can fail: a value moved past `max_diff`, the whole image one unit
/// off, a written pixel left at the harness's sentinel half-word, and a dropout everywhere.
fn assert_negative_control(what: &str, g: &[u16], c: &[u16], max_diff: u16, min_exact: f64) {
    let i = c.iter().position(|&v| v > 0).expect("a pixel with a return");
    let mut moved = g.to_vec();
    moved[i] = c[i] + max_diff + 1;
    let shifted: Vec<u16> = g.iter().map(|&v| v.wrapping_add(1)).collect();
    let mut sentinel = g.to_vec();
    sentinel[i] = 0xbeef;
    let dark = vec![0u16; g.len()];
    for (case, bad) in [("a value past tolerance", moved), ("every pixel one off", shifted), ("a sentinel", sentinel), ("no return anywhere", dark)] {
        assert!(compare_raw(what, &bad, c, max_diff, min_exact).is_err(), "{what}: the comparison accepted {case}");
    }
}

#[test]
fn exact_depth_is_the_model_depth_planar_or_radial() {
    let s = wall_and_box();
    let mut p = params(s.k, false, 0);
    let (g, c) = run(&p, &s);
    compare_raw("exact", &g, &c, 0, 1.0).unwrap();
    assert_negative_control("exact", &g, &c, 0, 1.0);
    for (i, &v) in g.iter().enumerate() {
        let z = s.depth_m[i];
        let want = if cpu::shared::is_valid_f32(z) { (z * 5000.0).round() as u16 } else { 0 };
        assert_eq!(v, want, "pixel {i}: depth {z} m");
    }
    p.radial = 1;
    let (g, c) = run(&p, &s);
    // WGSL's sqrt need not be correctly rounded: a distance may round to the next unit.
    compare_raw("radial", &g, &c, 1, MIN_EXACT).unwrap();
    assert_negative_control("radial", &g, &c, 1, MIN_EXACT);
    let k = s.k;
    let corner = (H - 1) * W + (W - 1);
    let rx = ((W - 1) as f32 - k.cx_px) / k.fx_px;
    let ry = ((H - 1) as f32 - k.cy_px) / k.fy_px;
    let ray = (rx * rx + ry * ry + 1.0).sqrt();
    let want = (WALL_M * ray * 5000.0).round() as u16;
    assert!(g[corner as usize].abs_diff(want) <= 1, "the corner's distance along its ray: {} vs {want}", g[corner as usize]);
    // Out of range: the wall beyond max depth, the box inside.
    p.radial = 0;
    p.max_depth_m = 2.0;
    let (g, _) = run(&p, &s);
    assert_eq!(g[(BOX_ROWS.start * W + BOX_COLUMNS.start) as usize], 5000, "the box at 1 m");
    assert_eq!(g[(200 * W + 300) as usize], 0, "the wall beyond max depth gives no return");
}

#[test]
fn the_exact_sensors_pipeline_is_the_kernel_without_its_noise_model() {
    // A sensor of exact depth compiles `depth_sensor` with NOISE_MODEL off: the same exact
    // depth as the twin, planar and radial.
    let s = wall_and_box();
    let exact: &[(&str, f64)] = &[("NOISE_MODEL", 0.0)];
    for radial in [0, 1] {
        let p = DepthSensorParams { radial, ..params(s.k, false, 0) };
        let (g, c) = run_with(&p, &s, Some(exact));
        compare_raw("exact pipeline", &g, &c, u16::from(radial == 1), MIN_EXACT).unwrap();
        assert_negative_control("exact pipeline", &g, &c, u16::from(radial == 1), MIN_EXACT);
    }
    // The noise model is compiled out, not merely off: asked for noise, this pipeline still
    // renders exact depth, which the twin's noisy image does not match.
    let noisy = params(s.k, true, 7);
    let (g, c) = run_with(&noisy, &s, Some(exact));
    let (exact_g, _) = run(&params(s.k, false, 0), &s);
    assert_eq!(g, exact_g, "the exact pipeline ignores the noise flag");
    assert!(compare_raw("noise compiled out", &g, &c, 0, 1.0).is_err(), "the exact pipeline must differ from the noisy twin");
}

#[test]
fn the_kinect_model_matches_the_twin_and_the_physics() {
    let s = wall_and_box();
    let model = KinectModel::default();
    let p = params(s.k, true, 7);
    let (g, c) = run(&p, &s);
    // One disparity step at the wall, in units.
    let bf = model.baseline_m.abs() * model.disparity_focal_px;
    let step_units = (WALL_M * WALL_M / (bf * model.disparity_subpixel) * 5000.0).ceil() as u16;
    let exact = compare_raw("kinect", &g, &c, step_units, MIN_EXACT).unwrap();
    assert_negative_control("kinect", &g, &c, step_units, MIN_EXACT);
    eprintln!("kinect: {exact} of {} pixels identical", g.len());

    // The wall's errors (pixels well away from the box, the hole and the borders).
    let mut errors = Vec::new();
    for y in 20..H - 20 {
        for x in 200..W - 20 {
            let v = g[(y * W + x) as usize];
            if v > 0 {
                errors.push(f64::from(v) / 5000.0 - f64::from(WALL_M));
            }
        }
    }
    let n = errors.len() as f64;
    let mean = errors.iter().sum::<f64>() / n;
    let std = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
    let step_m = f64::from(WALL_M * WALL_M / (bf * model.disparity_subpixel));
    // The incidence here is at most ~30°, so σ is σ_z(z); quantisation adds step²/12.
    let expected = (f64::from(cpu::shared::kinect_sigma_m(WALL_M)).powi(2) + step_m * step_m / 12.0).sqrt();
    eprintln!("wall: {} px, mean {:.2} mm, std {:.2} mm (model {:.2} mm)", errors.len(), mean * 1e3, std * 1e3, expected * 1e3);
    assert!(n > 0.95 * f64::from((H - 40) * (W - 220)), "almost every wall pixel returns: {n}");
    assert!(mean.abs() < 1.5e-3, "the noise is unbiased: mean {mean} m");
    assert!((std / expected - 1.0).abs() < 0.15, "spread {std} m vs the model's {expected} m");

    // The projector (at +x) shadows the wall left of the box over b·f·(1/z_box − 1/z_wall) px.
    let shadow_px = model.baseline_m * s.k.fx_px * (1.0 / BOX_M - 1.0 / WALL_M);
    let row = (BOX_ROWS.start + BOX_ROWS.end) / 2;
    let dark = |x: u32| (row - 5..row + 5).all(|y| g[(y * W + x) as usize] == 0);
    let left = (0..BOX_COLUMNS.start).rev().take_while(|&x| dark(x)).count() as f32;
    let right = (BOX_COLUMNS.end..W).take_while(|&x| dark(x)).count() as f32;
    eprintln!("shadow: {left} px left of the box (geometry: {shadow_px:.1}), {right} px right");
    assert!((left - shadow_px).abs() <= 3.0, "shadow of {left} px, geometry says {shadow_px}");
    assert!(right <= 1.0, "no shadow on the side away from the projector: {right} px");

    // Reproducible: the same seed and frame give the same image; another seed or frame not.
    let (again, _) = run(&p, &s);
    assert_eq!(again, g, "same seed, same frame");
    let other_seed = params(s.k, true, 8);
    let mut other_frame = p;
    other_frame.frame_index = 1;
    for (what, q) in [("seed", other_seed), ("frame", other_frame)] {
        let (o, _) = run(&q, &s);
        let differ = o.iter().zip(&g).filter(|(a, b)| a != b).count();
        assert!(differ > g.len() / 4, "another {what} draws other noise: {differ} pixels differ");
    }
}

#[test]
fn a_real_frame_as_the_model_matches_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let (w, h) = (frame.depth.width_px, frame.depth.height_px);
    let k = GpuIntrinsics::from(calibration.intrinsics);
    let depth: Vec<f32> = frame.depth.units.iter().map(|&u| if u == 0 { cpu::shared::INVALID } else { f32::from(u) / calibration.depth_units_per_metre }).collect();
    // Normals from neighbour differences of the back-projected points (camera frame).
    let point = |x: u32, y: u32| {
        let z = depth[(y * w + x) as usize];
        cpu::shared::back_project(&k, x as f32, y as f32, z)
    };
    let normal = |i: usize| {
        let (x, y) = ((i as u32) % w, (i as u32) / w);
        if x + 1 >= w || y + 1 >= h {
            return [cpu::shared::INVALID; 3];
        }
        let (p, px, py) = (point(x, y), point(x + 1, y), point(x, y + 1));
        let n = cpu::shared::cross3(std::array::from_fn(|j| px[j] - p[j]), std::array::from_fn(|j| py[j] - p[j]));
        let len = cpu::shared::dot3(n, n).sqrt();
        if !(len > 0.0) { [cpu::shared::INVALID; 3] } else { n.map(|c| -c / len) }
    };
    let s = scene(k, depth.clone(), normal);
    let p = params(k, true, 3);
    let (g, c) = run(&p, &s);
    let exact = compare_raw("real frame", &g, &c, 200, MIN_EXACT).unwrap();
    assert_negative_control("real frame", &g, &c, 200, MIN_EXACT);
    let returns = g.iter().filter(|&&v| v > 0).count();
    let model_valid = s.depth_m.iter().filter(|z| cpu::shared::is_valid_f32(**z)).count();
    eprintln!("real frame: {exact} of {} identical; {returns} returns of {model_valid} model pixels", g.len());
    assert!(returns > model_valid / 2 && returns < model_valid, "the model drops some pixels, not most: {returns} of {model_valid}");
}
