// SPDX-License-Identifier: MIT
//! The whole KinectFusion pipeline on synthetic depth with exact answers: a room with a box and
//! a sphere rendered analytically along a known trajectory must be tracked to < 1 mm and
//! < 0.1° per frame.

use glam::{DQuat, DVec3};
use webfusion_core::fusion::{FusionConfig, KinectFusion, TrackingState};
use webfusion_core::tsdf::TsdfConfig;
use webfusion_core::{ColorImage, DepthImage, PinholeIntrinsics, RgbdCalibration, RgbdFrame, Se3};
use webfusion_tests::{finish, gpu};

use crate::synthetic::{Room, UNITS_PER_M};

/// 320x240 camera with TUM-like focal lengths.
const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 258.65, fy_px: 258.25, cx_px: 159.3, cy_px: 127.65, width_px: 320, height_px: 240 };

/// Known trajectory: a screw motion of 1.2° and 1.3 cm per frame.
fn true_pose(i: usize) -> Se3 {
    let s = i as f64;
    Se3::new(DQuat::from_axis_angle(DVec3::new(0.3, 1.0, 0.2).normalize(), (1.2 * s).to_radians()), DVec3::new(0.008 * s, -0.005 * s, 0.009 * s))
}

fn frame(i: usize) -> RgbdFrame {
    let units = Room::render_depth_units(&K, &true_pose(i));
    RgbdFrame {
        index: i as u64,
        depth_timestamp_ns: i as i64 * 33_333_333,
        color_timestamp_ns: i as i64 * 33_333_333,
        depth: DepthImage::new(K.width_px, K.height_px, units).expect("depth size"),
        color: ColorImage::new(K.width_px, K.height_px, vec![128; K.pixel_count() * 3]).expect("colour size"),
    }
}

fn synthetic_config() -> FusionConfig {
    // A 3.6 m cube of 192³ voxels (18.75 mm) covers the room seen from the first camera.
    FusionConfig { tsdf: TsdfConfig::cube(192, 3.6 / 192.0), ..FusionConfig::default() }
}

#[test]
fn tracks_an_analytic_room_to_a_millimetre_and_a_tenth_of_a_degree() {
    track_the_analytic_room(synthetic_config());
}

#[test]
fn tracks_the_analytic_room_as_well_with_a_sparse_map() {
    let voxel_m = synthetic_config().tsdf.voxel_size_m;
    track_the_analytic_room(FusionConfig { tsdf: TsdfConfig::sparse(voxel_m, 16384), ..FusionConfig::default() });
}

fn track_the_analytic_room(config: FusionConfig) {
    let gpu = gpu();
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_M };
    let mut fusion = KinectFusion::new(&gpu, calibration, config).expect("pipeline");
    let mut previous: Option<Se3> = None;
    for i in 0..10 {
        let report = pollster::block_on(fusion.process_frame(&gpu, &frame(i))).expect("frame");
        assert!(!report.state.is_lost(), "frame {i} lost: {:?}", report.state);
        // World = first camera, so the estimate should equal first⁻¹ · true.
        let truth = true_pose(0).inverse() * true_pose(i);
        let error = truth.inverse() * report.world_from_camera;
        let (t_mm, r_deg) = (error.translation_m.length() * 1e3, error.rotation_angle_rad().to_degrees());
        if let Some(prev) = previous {
            let rel_truth = (true_pose(i - 1)).inverse() * true_pose(i);
            let rel_est = prev.inverse() * report.world_from_camera;
            let rel_err = rel_truth.inverse() * rel_est;
            let (rt_mm, rr_deg) = (rel_err.translation_m.length() * 1e3, rel_err.rotation_angle_rad().to_degrees());
            eprintln!("frame {i}: absolute {t_mm:.3} mm {r_deg:.4}°, relative {rt_mm:.3} mm {rr_deg:.4}°, {:?}", report.icp.last());
            assert!(rt_mm < 1.0 && rr_deg < 0.1, "frame {i}: relative error {rt_mm:.3} mm / {rr_deg:.4}°");
        } else {
            assert_eq!(report.state, TrackingState::Initialised, "the first frame defines the world");
        }
        assert!(t_mm < 2.0 && r_deg < 0.2, "frame {i}: absolute error {t_mm:.3} mm / {r_deg:.4}°");
        previous = Some(report.world_from_camera);
    }
    finish(&gpu);
}

/// Real Kinect data: the first 20 frames of TUM fr1/rpy (turning about 30° at up to
/// 120°/s) must all be tracked, and the trajectory must agree with the motion-capture ground
/// truth to a few centimetres (ATE after SE(3) alignment, TUM conventions). The full 100-frame
/// accuracy run is `scripts/bench_reconstruct.sh`.
#[test]
fn tracks_real_kinect_frames_against_motion_capture() {
    use webfusion_core::eval::{AteOptions, ate};
    use webfusion_core::io::trajectory::TimedPose;
    use webfusion_core::source::FrameSource as _;
    use webfusion_core::tsdf::VolumePlacement;

    let gpu = gpu();
    let mut dataset = webfusion_tests::sample();
    let ground_truth = dataset.ground_truth().expect("ground truth").to_vec();
    // A coarse volume keeps the test fast on lavapipe: 160³ voxels of 3 cm around the camera.
    let config = FusionConfig { tsdf: TsdfConfig { placement: VolumePlacement::Centred, ..TsdfConfig::cube(160, 0.03) }, ..FusionConfig::default() };
    let mut fusion = KinectFusion::new(&gpu, dataset.calibration(), config).expect("pipeline");
    let mut trajectory = Vec::new();
    for i in 0..20 {
        let frame = dataset.read_frame(i).expect("frame");
        let report = pollster::block_on(fusion.process_frame(&gpu, &frame)).expect("process");
        assert!(!report.state.is_lost(), "frame {i} lost: {:?}", report.state);
        trajectory.push(TimedPose { timestamp_ns: frame.depth_timestamp_ns, world_from_camera: report.world_from_camera });
    }
    let report = ate(&ground_truth, &trajectory, &AteOptions::default()).expect("ATE");
    eprintln!("ATE over 20 real frames: RMSE {:.2} cm, max {:.2} cm", report.error_m.rmse * 100.0, report.error_m.max * 100.0);
    assert_eq!(report.error_m.count, 20, "every frame associated");
    assert!(report.error_m.rmse < 0.03, "ATE RMSE {:.3} m", report.error_m.rmse);
    finish(&gpu);
}

/// The sparse map tracks the real frames as the dense box does: 20 frames of the sample at the
/// same voxel size (3 cm), the two trajectories within 1 mm and 0.1° of each other at every
/// frame (the maps differ only in voxels far from any surface, which the dense box updates and
/// the sparse map never allocates), the map's counters without exhaustion.
#[test]
fn a_sparse_map_tracks_real_frames_as_the_dense_box_does() {
    use webfusion_core::source::FrameSource as _;
    use webfusion_core::tsdf::VolumePlacement;

    let gpu = gpu();
    let mut dataset = webfusion_tests::sample();
    let dense = FusionConfig { tsdf: TsdfConfig { placement: VolumePlacement::Centred, ..TsdfConfig::cube(160, 0.03) }, ..FusionConfig::default() };
    let sparse = FusionConfig { tsdf: TsdfConfig::sparse(0.03, 8192), ..FusionConfig::default() };
    let mut dense = KinectFusion::new(&gpu, dataset.calibration(), dense).expect("dense pipeline");
    let mut sparse = KinectFusion::new(&gpu, dataset.calibration(), sparse).expect("sparse pipeline");
    let mut worst = (0.0f64, 0.0f64);
    let mut last_counters = None;
    for i in 0..20 {
        let frame = dataset.read_frame(i).expect("frame");
        let d = pollster::block_on(dense.process_frame(&gpu, &frame)).expect("dense frame");
        let s = pollster::block_on(sparse.process_frame(&gpu, &frame)).expect("sparse frame");
        assert!(!s.state.is_lost(), "frame {i} lost with the sparse map: {:?}", s.state);
        assert!(d.map.is_none(), "a dense box reports no map counters");
        last_counters = s.map;
        let diff = d.world_from_camera.inverse() * s.world_from_camera;
        worst = (worst.0.max(diff.translation_m.length() * 1e3), worst.1.max(diff.rotation_angle_rad().to_degrees()));
    }
    let stats = pollster::block_on(sparse.mapper().stats(&gpu)).expect("map stats").expect("a sparse map");
    eprintln!("sparse vs dense over 20 frames: at most {:.3} mm, {:.4}°; {stats:?}", worst.0, worst.1);
    assert!(worst.0 < 1.0 && worst.1 < 0.1, "trajectories apart by up to {:.3} mm / {:.4}°", worst.0, worst.1);
    assert!(!stats.exhausted() && stats.out_of_range == 0, "the map had room: {stats:?}");
    assert!(stats.blocks_used > 100 && stats.visible_blocks > 50, "blocks were allocated and integrated: {stats:?}");
    assert_eq!(last_counters, Some(stats), "the last frame's report carries the map's counters");
    finish(&gpu);
}

/// Frames of a scene (its ray-distance function) along `poses`, grey colour.
fn scene_frames(poses: &[Se3], ray_distance: impl Fn([f64; 3], [f64; 3]) -> Option<f64> + Copy) -> Vec<RgbdFrame> {
    poses
        .iter()
        .enumerate()
        .map(|(i, pose)| RgbdFrame {
            index: i as u64,
            depth_timestamp_ns: i as i64 * 33_333_333,
            color_timestamp_ns: i as i64 * 33_333_333,
            depth: DepthImage::new(K.width_px, K.height_px, crate::synthetic::render_scene_units(&K, pose, ray_distance)).expect("depth size"),
            color: ColorImage::new(K.width_px, K.height_px, vec![128; K.pixel_count() * 3]).expect("colour size"),
        })
        .collect()
}

fn small_motion(i: usize) -> Se3 {
    let s = i as f64;
    Se3::new(DQuat::from_axis_angle(DVec3::new(0.3, 1.0, 0.2).normalize(), (0.5 * s).to_radians()), DVec3::new(0.004 * s, -0.002 * s, 0.003 * s))
}

/// Tracks `frames` depth-only (a grey image carries no photometric information) and returns
/// every frame's report.
fn track_all(frames: &[RgbdFrame]) -> Vec<webfusion_core::fusion::FrameReport> {
    let gpu = gpu();
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_M };
    let mut config = synthetic_config();
    config.icp.rgb_weight = 0.0;
    let mut fusion = KinectFusion::new(&gpu, calibration, config).expect("pipeline");
    let reports = frames.iter().map(|f| pollster::block_on(fusion.process_frame(&gpu, f)).expect("frame")).collect();
    finish(&gpu);
    reports
}

/// A single wall constrains only its normal's translation and the two rotations that tilt
/// it: the three other directions have no information, so the scaled system is singular in
/// f32 and every frame after the first is lost as ill-conditioned, not drifting.
#[test]
fn a_single_wall_is_lost_as_ill_conditioned() {
    let wall = |o: [f64; 3], d: [f64; 3]| crate::synthetic::nearest_plane(o, d, &[([0.0, 0.0, 1.0], 2.0)]);
    let poses: Vec<Se3> = (0..4).map(small_motion).collect();
    let reports = track_all(&scene_frames(&poses, wall));
    assert_eq!(reports[0].state, TrackingState::Initialised);
    for r in &reports[1..] {
        let finest = r.icp.last().expect("ICP ran");
        eprintln!("wall frame {}: {:?}, finest level condition {:.3e}; levels {:?}", r.index, r.state, finest.condition, r.icp);
        assert!(matches!(r.state, TrackingState::Lost(webfusion_core::fusion::LostReason::IllConditioned { .. })), "frame {}: {:?}", r.index, r.state);
        assert_eq!(r.world_from_camera, Se3::IDENTITY, "a lost frame keeps the last good pose");
    }
}

/// A corridor (two walls, floor and ceiling, open ahead) leaves the translation along it
/// unconstrained: lost as ill-conditioned too. The same corridor with an end wall in view is
/// tracked: the check is about information, not about planes.
#[test]
fn a_corridor_is_lost_as_ill_conditioned_until_its_end_wall_is_seen() {
    let walls = [([1.0, 0.0, 0.0], 1.0), ([-1.0, 0.0, 0.0], 1.0), ([0.0, 1.0, 0.0], 1.0), ([0.0, -1.0, 0.0], 1.0)];
    let corridor = move |o: [f64; 3], d: [f64; 3]| crate::synthetic::nearest_plane(o, d, &walls);
    let with_end = move |o: [f64; 3], d: [f64; 3]| {
        let mut all = walls.to_vec();
        all.push(([0.0, 0.0, 1.0], 3.0));
        crate::synthetic::nearest_plane(o, d, &all)
    };
    let poses: Vec<Se3> = (0..4).map(small_motion).collect();
    let open = track_all(&scene_frames(&poses, corridor));
    for r in &open[1..] {
        eprintln!("corridor frame {}: {:?}, condition {:.3e}", r.index, r.state, r.icp.last().map_or(0.0, |s| s.condition));
        assert!(matches!(r.state, TrackingState::Lost(webfusion_core::fusion::LostReason::IllConditioned { .. })), "open corridor, frame {}: {:?}", r.index, r.state);
    }
    let closed = track_all(&scene_frames(&poses, with_end));
    for (i, r) in closed.iter().enumerate().skip(1) {
        let truth = poses[0].inverse() * poses[i];
        let err = truth.inverse() * r.world_from_camera;
        eprintln!("corridor with an end wall, frame {i}: {:?}, condition {:.3e}, error {:.3} mm", r.state, r.icp.last().map_or(0.0, |s| s.condition), err.translation_m.length() * 1e3);
        assert_eq!(r.state, TrackingState::Tracked, "closed corridor, frame {i}");
        assert!(err.translation_m.length() < 2e-3 && err.rotation_angle_rad().to_degrees() < 0.2, "closed corridor, frame {i}: {err:?}");
    }
}

/// A sudden jump (the camera teleported 40 cm) is lost as implausible, and tracking recovers
/// when the camera comes back.
#[test]
fn a_sudden_jump_is_lost_and_tracking_recovers() {
    let mut poses: Vec<Se3> = (0..3).map(true_pose).collect();
    poses.push(Se3::new(DQuat::IDENTITY, DVec3::new(0.4, 0.0, 0.0)) * true_pose(3));
    poses.push(true_pose(3));
    let frames: Vec<RgbdFrame> = poses.iter().enumerate().map(|(i, p)| {
        let mut f = frame(0);
        f.index = i as u64;
        f.depth = DepthImage::new(K.width_px, K.height_px, Room::render_depth_units(&K, p)).expect("depth");
        f
    }).collect();
    let reports = track_all(&frames);
    for r in &reports {
        eprintln!("jump test frame {}: {:?}", r.index, r.state);
    }
    assert!(matches!(reports[3].state, TrackingState::Lost(_)), "the teleported frame is lost: {:?}", reports[3].state);
    assert_eq!(reports[3].world_from_camera, reports[2].world_from_camera, "and keeps the last good pose");
    assert_eq!(reports[4].state, TrackingState::Recovered, "back at the path: recovered");
}

/// The frame engine's contract: a frame is one submission and one late readback, with no
/// host wait while submitting when a readback slot is free; the report arrives later.
#[test]
fn a_frame_is_one_submission_one_late_readback_and_no_wait() {
    let gpu = gpu();
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_M };
    let mut fusion = KinectFusion::new(&gpu, calibration, synthetic_config()).expect("pipeline");
    let mut reports = Vec::new();
    for i in 0..6 {
        let before = gpu.counters.snapshot();
        pollster::block_on(fusion.submit_frame(&gpu, &frame(i))).expect("submit");
        let during = gpu.counters.snapshot() - before;
        assert_eq!((during.submits, during.host_waits, during.readbacks), (1, 0, 1), "frame {i}: one submission, no wait, one readback started ({during:?})");
        // The GPU finishes while the host does something else (here: an observer's wait, not
        // the pipeline's); the report is then collected without waiting.
        gpu.device.poll(wgpu::PollType::wait_indefinitely()).expect("the GPU finishes");
        let before = gpu.counters.snapshot();
        reports.extend(fusion.poll_reports(&gpu).expect("poll"));
        assert_eq!((gpu.counters.snapshot() - before).host_waits, 0, "collecting reports never waits");
    }
    assert_eq!(reports.len(), 6, "every frame reported");
    for (i, r) in reports.iter().enumerate() {
        assert_eq!(r.index, i as u64, "in order");
        assert_eq!((r.host.submits, r.host.host_waits, r.host.readbacks), (1, 0, 1), "frame {i}'s own count");
        assert!(!r.state.is_lost(), "frame {i} tracked");
    }
    finish(&gpu);
}

/// The stages recombine: a pose-driven mapper (preprocess and mapper, no tracker) fuses the
/// room at the true poses into the same map the CPU twins build, and the predictor raycasts
/// it to the room's true depth.
#[test]
fn a_pose_driven_mapper_recombines_the_stages() {
    use webfusion_core::fusion::pose_driven::PoseDrivenMapper;
    use webfusion_core::tsdf::TsdfStore as _;
    let gpu = gpu();
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_M };
    let config = synthetic_config();
    let poses: Vec<Se3> = (0..4).map(|i| true_pose(0).inverse() * true_pose(i)).collect();
    let mut mapper = PoseDrivenMapper::new(&gpu, calibration, config.preprocess, config.tsdf, &Se3::IDENTITY, true).expect("mapper");
    let desc = mapper.volume().desc();
    let mut voxels = vec![0u32; desc.voxel_count()];
    let mut colors = vec![0u32; desc.voxel_count()];
    let mut bricks = vec![0u32; desc.brick_count()];
    for (i, pose) in poses.iter().enumerate() {
        let f = frame(i);
        pollster::block_on(mapper.submit_frame(&gpu, &f, pose)).expect("fuse");
        // The same frame through the CPU twins.
        let chain = webfusion_core::cpu::preprocess::chain::preprocess(&calibration, &config.preprocess, &f);
        let p = webfusion_core::kernels::tsdf_integrate::TsdfIntegrateParams {
            volume: desc,
            intrinsics: webfusion_core::kernels::GpuIntrinsics::from(K),
            color_enabled: 1,
            max_depth_m: config.preprocess.max_depth_m,
            ..Default::default()
        };
        webfusion_core::cpu::tsdf_integrate(&p, &webfusion_core::fusion::predictor::camera_pose(Some(pose)), &chain.depth_unfiltered_m, &chain.color, &mut voxels, &mut colors, &mut bricks);
    }
    let gpu_bricks: Vec<u32> = pollster::block_on(gpu.read_buffer(mapper.volume().surface_bricks(), desc.brick_count())).expect("read the bricks");
    let brick_diff = gpu_bricks.iter().zip(&bricks).filter(|(g, c)| g != c).count();
    assert!(brick_diff * 100 <= bricks.iter().filter(|&&b| b != 0).count(), "surface bricks: {brick_diff} differ from the twins'");
    let gpu_voxels: Vec<u32> = pollster::block_on(gpu.read_buffer(mapper.volume().voxels(), desc.voxel_count())).expect("read the map");
    let touched = voxels.iter().filter(|&&w| w >> 16 > 0).count();
    let differ = gpu_voxels.iter().zip(&voxels).filter(|&(&g, &c)| (g >> 16) != (c >> 16) || ((g as u16 as i16) as i32 - (c as u16 as i16) as i32).abs() > 2).count();
    eprintln!("pose-driven map: {touched} voxels fused, {differ} differ from the CPU twins beyond 2 LSB");
    assert!(touched > 100_000, "the map holds the room ({touched} voxels)");
    assert!((differ as f64) < 1e-3 * touched as f64, "{differ} voxels differ");
    // The predictor's raycast from the last pose sees the room where it is.
    let prediction = mapper.predictor().expect("predicting");
    let depth: Vec<f32> = pollster::block_on(gpu.read_buffer(&prediction.finest().depth_m, K.pixel_count())).expect("read the prediction");
    let truth = Room::render_depth_units(&K, &true_pose(3));
    let errors: Vec<f32> = depth.iter().zip(&truth).filter(|(d, t)| !d.is_nan() && **t > 0).map(|(d, t)| (d - f32::from(*t) / UNITS_PER_M).abs()).collect();
    let mut sorted = errors.clone();
    sorted.sort_by(f32::total_cmp);
    let median = sorted[sorted.len() / 2];
    eprintln!("pose-driven prediction: {} pixels, median depth error {:.2} mm", errors.len(), median * 1e3);
    assert!(errors.len() > K.pixel_count() * 8 / 10, "most pixels predicted");
    assert!(median < 2e-3, "median depth error {median} m");
    finish(&gpu);
}
