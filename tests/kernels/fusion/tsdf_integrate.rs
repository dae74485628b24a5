// SPDX-License-Identifier: MIT
//! `tsdf_integrate`: an analytic wall fuses to its exact signed distance, the GPU matches the
//! CPU reference voxel by voxel on a real Kinect frame fused at two poses, the per-column
//! frustum stretch skips no voxel the full sweep would update, a disabled pose (a lost frame)
//! fuses nothing, and a far wall measured with the Kinect model's noise fuses at its depth with
//! the noise-widened truncation band (and behind it with μ alone).
//!
//! Tolerances: a voxel word is compared as (TSDF, weight, colour). The TSDF may differ by one
//! LSB (1/32767 of μ: the kernel's division and the projection may round differently under
//! FMA contraction), weights and colours must match, except that a voxel whose centre
//! projects within an ulp of a pixel boundary may pick the neighbouring depth sample: at most
//! 0.1 % of the touched voxels may differ beyond that.

use glam::{DQuat, DVec3};
use webfusion_core::cpu::{self, shared::{brick_index, voxel_index, voxel_tsdf, voxel_weight}};
use webfusion_core::kernels::GpuIntrinsics;
use webfusion_core::kernels::tsdf_integrate::{CameraPose, TsdfIntegrateParams};
use webfusion_core::tsdf::{TsdfConfig, VolumeDesc};
use webfusion_core::{PinholeIntrinsics, Se3};
use webfusion_tests::{cast, finish, gpu, run_kernel_in_place};

use crate::preprocess::chain::real_cpu_chain;
use crate::synthetic::K_SMALL;

/// One TSDF LSB.
const TSDF_LSB: f32 = 1.0 / 32767.0;
/// Largest fraction of touched voxels allowed to differ beyond one LSB (pixel-boundary flips).
const MAX_FLIP_FRACTION: f64 = 1e-3;

/// Farthest depth the tests' depth images hold, metres (the kernel's frustum ends there + μ).
const MAX_DEPTH_M: f32 = 5.0;

fn params(desc: VolumeDesc, k: PinholeIntrinsics, world_from_camera: &Se3, color: bool) -> (TsdfIntegrateParams, CameraPose) {
    let p = TsdfIntegrateParams { volume: desc, intrinsics: GpuIntrinsics::from(k), color_enabled: u32::from(color), max_depth_m: MAX_DEPTH_M, ..Default::default() };
    (p, webfusion_core::fusion::predictor::camera_pose(Some(world_from_camera)))
}

/// Integrates on the GPU and on the CPU; returns (GPU, CPU) voxel and colour words. The
/// surface bricks start cleared and must come out the same, except bricks holding a voxel the
/// two updated differently (a pixel-boundary flip); the last GPU bricks are kept in `BRICKS`.
fn integrate(p: &(TsdfIntegrateParams, CameraPose), depth_m: &[f32], color: &[[f32; 4]], voxels: &[u32], colors: &[u32]) -> ((Vec<u32>, Vec<u32>), (Vec<u32>, Vec<u32>)) {
    let gpu = gpu();
    let d = &p.0.volume;
    let bricks = vec![0u32; d.brick_count()];
    let out = run_kernel_in_place(
        &gpu,
        &gpu.kernels.tsdf_integrate,
        &p.0,
        &[bytemuck::bytes_of(&p.1), bytemuck::cast_slice(depth_m), bytemuck::cast_slice(color), bytemuck::cast_slice(voxels), bytemuck::cast_slice(colors), bytemuck::cast_slice(&bricks)],
        [d.dim_x, d.dim_y, 1],
    );
    finish(&gpu);
    let (mut cv, mut cc, mut cb) = (voxels.to_vec(), colors.to_vec(), bricks);
    cpu::tsdf_integrate(&p.0, &p.1, depth_m, color, &mut cv, &mut cc, &mut cb);
    let (gv, gb): (Vec<u32>, Vec<u32>) = (cast(&out[3]), cast(&out[5]));
    let mut flipped = vec![false; cb.len()];
    for z in 0..d.dim_z {
        for y in 0..d.dim_y {
            for x in 0..d.dim_x {
                let i = voxel_index(d, x, y, z) as usize;
                if gv[i] != cv[i] {
                    flipped[brick_index(d, x, y, z) as usize] = true;
                }
            }
        }
    }
    let wrong = (0..cb.len()).filter(|&b| gb[b] != cb[b] && !flipped[b]).count();
    assert_eq!(wrong, 0, "surface bricks: {wrong} differ from the twin's where no voxel differs");
    BRICKS.with(|b| *b.borrow_mut() = gb);
    ((gv, cast(&out[4])), (cv, cc))
}

thread_local! {
    static BRICKS: std::cell::RefCell<Vec<u32>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// The voxels a full sweep of every voxel (no frustum stretch) would update: the kernel's
/// per-voxel tests applied to each voxel of the volume.
fn full_sweep(p: &(TsdfIntegrateParams, CameraPose), depth_m: &[f32], voxels: &[u32]) -> Vec<u32> {
    use webfusion_core::cpu::shared::{pack_voxel, transform_point, voxel_centre_in_world, voxel_index};
    let (p, pose) = p;
    let d = &p.volume;
    let k = &p.intrinsics;
    let mut out = voxels.to_vec();
    for z in 0..d.dim_z {
        for y in 0..d.dim_y {
            for x in 0..d.dim_x {
                let c = transform_point(&pose.camera_from_world, voxel_centre_in_world(d, x, y, z));
                if !(c[2] > 0.0) {
                    continue;
                }
                let u = (k.fx_px * c[0] / c[2] + k.cx_px + 0.5).floor();
                let v = (k.fy_px * c[1] / c[2] + k.cy_px + 0.5).floor();
                if !(u >= 0.0 && v >= 0.0 && u < k.width_px as f32 && v < k.height_px as f32) {
                    continue;
                }
                let depth = depth_m[(v as u32 * k.width_px + u as u32) as usize];
                let band_m = webfusion_core::cpu::shared::truncation_band_m(d, depth);
                if depth.is_nan() || depth - c[2] < -band_m {
                    continue;
                }
                let ix = voxel_index(d, x, y, z) as usize;
                let w = voxel_weight(out[ix]);
                let tsdf = ((depth - c[2]) / band_m).min(1.0);
                out[ix] = pack_voxel((voxel_tsdf(out[ix]) * w as f32 + tsdf) / (w + 1) as f32, (w + 1).min(d.max_weight));
            }
        }
    }
    out
}

/// Compares voxel and colour words under the tolerances above; returns the number of voxels
/// differing beyond one LSB.
pub(crate) fn compare_volumes(gpu: (&[u32], &[u32]), cpu: (&[u32], &[u32])) -> Result<usize, String> {
    let (gv, gc) = gpu;
    let (cv, cc) = cpu;
    let touched = cv.iter().filter(|&&w| voxel_weight(w) > 0).count().max(1);
    let mut flips = 0;
    for i in 0..cv.len() {
        let same_weight = voxel_weight(gv[i]) == voxel_weight(cv[i]);
        let tsdf_err = (voxel_tsdf(gv[i]) - voxel_tsdf(cv[i])).abs();
        let colour_err = (0..3).map(|c| ((gc[i] >> (8 * c)) & 0xff).abs_diff((cc[i] >> (8 * c)) & 0xff)).max().unwrap_or(0);
        if !(same_weight && tsdf_err <= 1.5 * TSDF_LSB && colour_err <= 1) {
            flips += 1;
        }
    }
    if flips as f64 > MAX_FLIP_FRACTION * touched as f64 {
        return Err(format!("{flips} of {touched} touched voxels differ (allowed {:.0})", MAX_FLIP_FRACTION * touched as f64));
    }
    Ok(flips)
}

#[test]
fn a_wall_fuses_to_its_signed_distance() {
    // A wall 1.0 m in front of the camera filling the image; 32³ voxels of 5 cm, μ = 20 cm.
    let k = K_SMALL;
    let config = TsdfConfig { max_weight: 2, ..TsdfConfig::cube(32, 0.05) };
    let desc = config.desc(config.origin_for_first_camera(&Se3::IDENTITY));
    let depth = vec![1.0f32; k.pixel_count()];
    let color = vec![[0.2f32, 0.4, 0.6, 1.0]; k.pixel_count()];
    let mut voxels = vec![0u32; desc.voxel_count()];
    let mut colors = vec![0u32; desc.voxel_count()];
    let p = params(desc, k, &Se3::IDENTITY, true);
    for frame in 1..=3u32 {
        let ((gv, gc), (cv, cc)) = integrate(&p, &depth, &color, &voxels, &colors);
        assert_eq!(compare_volumes((&gv, &gc), (&cv, &cc)), Ok(0), "frame {frame}: GPU and CPU agree exactly on a wall");
        if frame == 1 {
            // Every observed voxel was updated by this frame: the marked bricks are exactly
            // those holding a voxel below FAR_TSDF, and the free space in front of the wall's
            // band (and the space behind it) leaves bricks unmarked.
            let marked = BRICKS.with(|b| b.borrow().clone());
            assert_eq!(marked, cpu::shared::surface_bricks(&desc, &gv), "the wall's surface bricks");
            let n = marked.iter().filter(|&&m| m != 0).count();
            assert!(n > 0 && n < marked.len() / 2, "some bricks marked, most not ({n} of {})", marked.len());
        }
        // The central column (x, y = 16) sees the wall head-on.
        for z in 0..desc.dim_z {
            let ix = (16 + 32 * (16 + 32 * z)) as usize;
            let z_m = (z as f32 + 0.5) * 0.05;
            let sdf = 1.0 - z_m;
            let word = gv[ix];
            let x_m = desc.origin_x_m + 16.5 * 0.05;
            let u = (k.fx_px * x_m / z_m + k.cx_px + 0.5).floor();
            if u >= k.width_px as f32 {
                assert_eq!(voxel_weight(word), 0, "z = {z_m} m projects outside the image: untouched");
                continue;
            }
            if sdf < -desc.truncation_m {
                assert_eq!(voxel_weight(word), 0, "z = {z_m} m lies more than μ behind the wall: untouched");
                continue;
            }
            assert_eq!(voxel_weight(word), frame.min(2), "z = {z_m} m: weight after {frame} frames (cap 2)");
            let expected = (sdf / desc.truncation_m).min(1.0);
            assert!((voxel_tsdf(word) - expected).abs() <= 2.0 * TSDF_LSB, "z = {z_m} m: TSDF {} vs {expected}", voxel_tsdf(word));
            if expected < 1.0 {
                assert_eq!(gc[ix] & 0xff_ffff, 51 | (102 << 8) | (153 << 16), "z = {z_m} m: colour in the band");
            }
        }
        voxels = gv;
        colors = gc;
    }
    // Outside the frustum (behind the camera's field of view at the volume's corner) nothing is written.
    assert_eq!(voxel_weight(voxels[0]), 0, "corner voxel outside the frustum stays unobserved");
}

#[test]
fn real_frame_at_two_poses_matches_cpu() {
    let chain = real_cpu_chain();
    let k = chain.levels[0].intrinsics;
    let config = TsdfConfig::cube(64, 3.0 / 64.0);
    let desc = config.desc(config.origin_for_first_camera(&Se3::IDENTITY));
    let (mut voxels, mut colors) = (vec![0u32; desc.voxel_count()], vec![0u32; desc.voxel_count()]);
    let poses = [Se3::IDENTITY, Se3::new(DQuat::from_axis_angle(DVec3::new(0.2, 1.0, 0.1).normalize(), 0.05), DVec3::new(0.03, -0.02, 0.05))];
    for (i, pose) in poses.iter().enumerate() {
        let p = params(desc, k, pose, true);
        let ((gv, gc), (cv, cc)) = integrate(&p, &chain.depth_unfiltered_m, &chain.color, &voxels, &colors);
        let flips = compare_volumes((&gv, &gc), (&cv, &cc)).unwrap_or_else(|e| panic!("pose {i}: {e}"));
        let touched = cv.iter().filter(|&&w| voxel_weight(w) > 0).count();
        eprintln!("pose {i}: {touched} voxels touched, {flips} differ beyond 1 LSB");
        assert!(touched > 10_000, "the frame touches a good part of the volume ({touched})");
        // Negative controls: one TSDF moved by 2 LSB, one weight changed, one colour changed.
        let some = cv.iter().position(|&w| voxel_weight(w) > 0 && voxel_tsdf(w).abs() < 0.5).expect("a voxel near the surface");
        let mut bad = cv.clone();
        bad[some] = cpu::shared::pack_voxel(voxel_tsdf(cv[some]) + 3.0 * TSDF_LSB, voxel_weight(cv[some]));
        assert!(compare_volumes((&bad, &cc), (&cv, &cc)) == Ok(1), "a TSDF 3 LSB off is counted");
        bad[some] = cv[some] + (1 << 16);
        assert!(compare_volumes((&bad, &cc), (&cv, &cc)) == Ok(1), "a weight off by one is counted");
        let mut bad_c = cc.clone();
        bad_c[some] ^= 0x0400;
        assert!(compare_volumes((&cv, &bad_c), (&cv, &cc)) == Ok(1), "a colour 4 levels off is counted");
        let mut many = cv.clone();
        for w in many.iter_mut().filter(|w| voxel_weight(**w) > 0).take(touched / 100) {
            *w += 1 << 16;
        }
        assert!(compare_volumes((&many, &cc), (&cv, &cc)).is_err(), "1 % of voxels wrong fails the comparison");
        voxels = gv;
        colors = gc;
    }
}

#[test]
fn the_frustum_stretch_updates_exactly_what_a_full_sweep_does() {
    let chain = real_cpu_chain();
    let k = chain.levels[0].intrinsics;
    let config = TsdfConfig::cube(64, 3.0 / 64.0);
    let desc = config.desc(config.origin_for_first_camera(&Se3::IDENTITY));
    let empty = vec![0u32; desc.voxel_count()];
    // Straight ahead, and turned so that the frustum cuts the columns at a slant.
    for pose in [Se3::IDENTITY, Se3::new(DQuat::from_axis_angle(DVec3::new(0.4, 1.0, 0.3).normalize(), 0.6), DVec3::new(0.2, -0.1, 0.4))] {
        let p = params(desc, k, &pose, false);
        let ((gv, _), (cv, _)) = integrate(&p, &chain.depth_unfiltered_m, &chain.color, &empty, &empty);
        let swept = full_sweep(&p, &chain.depth_unfiltered_m, &empty);
        let touched = swept.iter().filter(|&&w| voxel_weight(w) > 0).count();
        assert!(touched > 5000, "the frame touches voxels ({touched})");
        assert_eq!(cv, swept, "the CPU twin's frustum stretch misses no voxel of the full sweep");
        compare_volumes((&gv, &vec![0; gv.len()]), (&swept, &vec![0; gv.len()])).unwrap_or_else(|e| panic!("GPU vs full sweep: {e}"));
    }
}

#[test]
fn a_disabled_pose_fuses_nothing() {
    let chain = real_cpu_chain();
    let k = chain.levels[0].intrinsics;
    let config = TsdfConfig::cube(32, 0.1);
    let desc = config.desc(config.origin_for_first_camera(&Se3::IDENTITY));
    let mut p = params(desc, k, &Se3::IDENTITY, true);
    p.1.enabled = 0;
    let voxels: Vec<u32> = (0..desc.voxel_count() as u32).collect();
    let ((gv, gc), (cv, cc)) = integrate(&p, &chain.depth_unfiltered_m, &chain.color, &voxels, &voxels);
    assert!(gv == voxels && gc == voxels, "the GPU left the volume as it was");
    assert!(cv == voxels && cc == voxels, "so did the CPU twin");
}

/// Mean over the columns of `desc` of where the fused TSDF crosses zero along z (the camera at
/// the identity looks along +z: the depth of the surface), linearly interpolated between the
/// last voxel in front (TSDF > 0) and the first behind; columns without a crossing are left out.
fn mean_zero_crossing_m(desc: &VolumeDesc, voxels: &[u32]) -> (f64, usize) {
    let (mut sum, mut n) = (0.0, 0);
    for y in 0..desc.dim_y {
        for x in 0..desc.dim_x {
            let mut front: Option<(f32, f32)> = None;
            for z in 0..desc.dim_z {
                let word = voxels[voxel_index(desc, x, y, z) as usize];
                if voxel_weight(word) == 0 {
                    continue;
                }
                let (t, z_m) = (voxel_tsdf(word), cpu::shared::voxel_centre_in_world(desc, x, y, z)[2]);
                if let Some((z0, t0)) = front
                    && t <= 0.0
                {
                    sum += f64::from(z0 + (z_m - z0) * t0 / (t0 - t));
                    n += 1;
                    break;
                }
                front = (t > 0.0).then_some((z_m, t));
            }
        }
    }
    (sum / n.max(1) as f64, n)
}

#[test]
fn a_far_noisy_wall_fuses_where_it_is_with_the_noise_band_and_behind_it_without() {
    // A wall 4 m away filling the image, measured with the Kinect model's axial noise there
    // (σ = 2.58 cm, seeded Gaussian per pixel and frame), 96 frames fused into 1 cm voxels with
    // μ = 2 cm. Fixed at μ, the band is narrower than the noise: samples in front are clamped
    // to +1 while those more than μ behind are dropped, so the average crosses zero behind the
    // wall (E[min(1, sdf/μ) | sdf > -μ] = 0 puts it 17 mm behind). Widened to 3σ = 7.7 cm, both
    // tails hold 0.13 % of the samples: the crossing is the wall's depth within the sampling
    // error (~25 pixels x 96 frames: σ/√2400 = 0.5 mm). The GPU matches the twin on the first frames.
    let k = K_SMALL;
    let wall_m = 4.0f32;
    let sigma_m = cpu::shared::kinect_sigma_m(wall_m);
    let color = vec![[0.5f32; 4]; k.pixel_count()];
    let mut bias_mm = Vec::new();
    for sigmas in [webfusion_core::tsdf::DEFAULT_NOISE_BAND_SIGMAS, 0.0] {
        // 32 x 32 x 96 voxels of 1 cm, 3.6 to 4.56 m in front of the camera.
        let config = TsdfConfig { dims_voxels: [32, 32, 96], truncation_m: 0.02, noise_band_sigmas: sigmas, color: false, ..TsdfConfig::cube(32, 0.01) };
        let desc = config.desc([-0.16, -0.16, 3.6]);
        let band_m = cpu::shared::truncation_band_m(&desc, wall_m);
        assert_eq!(band_m, if sigmas > 0.0 { 3.0 * sigma_m } else { 0.02 }, "the band at the wall");
        let p = params(desc, k, &Se3::IDENTITY, false);
        let (mut voxels, colors) = (vec![0u32; desc.voxel_count()], vec![0u32; desc.voxel_count()]);
        let mut state = 0x5eed_u32;
        for frame in 0..96 {
            let depth: Vec<f32> = (0..k.pixel_count()).map(|_| wall_m + sigma_m * cpu::shared::random_gauss2(&mut state)[0]).collect();
            if frame < 4 {
                // The GPU's update of the widened band matches the twin's (then the twin goes on
                // alone: lavapipe is slow, and the update is the same).
                let ((gv, gc), (cv, cc)) = integrate(&p, &depth, &color, &voxels, &colors);
                compare_volumes((&gv, &gc), (&cv, &cc)).unwrap_or_else(|e| panic!("band of {sigmas} σ, frame {frame}: {e}"));
                voxels = gv;
            } else {
                let (mut c, mut b) = (colors.clone(), vec![0u32; desc.brick_count()]);
                cpu::tsdf_integrate(&p.0, &p.1, &depth, &color, &mut voxels, &mut c, &mut b);
            }
        }
        // Nothing far beyond the band behind the wall is fused (15 cm: 5.8σ of noise).
        let behind = voxels[voxel_index(&desc, 16, 16, ((wall_m + band_m + 0.15 - 3.6) / 0.01) as u32) as usize];
        assert_eq!(voxel_weight(behind), 0, "band of {sigmas} σ: nothing 15 cm beyond the band");
        let (crossing_m, columns) = mean_zero_crossing_m(&desc, &voxels);
        assert!(columns > 500, "band of {sigmas} σ: the wall crosses zero in most columns ({columns})");
        bias_mm.push((crossing_m - f64::from(wall_m)) * 1000.0);
        eprintln!("band of {sigmas} σ ({:.1} cm): surface {:+.2} mm from the wall over {columns} columns", band_m * 100.0, bias_mm.last().unwrap());
    }
    assert!(bias_mm[0].abs() < 2.0, "3σ band: the wall where it is ({:+.2} mm)", bias_mm[0]);
    // Negative control: the fixed band puts it well behind.
    assert!(bias_mm[1] > 8.0, "μ at every depth: the wall behind itself ({:+.2} mm)", bias_mm[1]);
}
