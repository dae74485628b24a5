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
    let gpu = gpu();
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_M };
    let mut fusion = KinectFusion::new(&gpu, calibration, synthetic_config()).expect("pipeline");
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
            assert_eq!(report.state, TrackingState::Initialised);
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
    let mut dataset = webfusion_core::io::tum::TumDataset::open(webfusion_tests::tum_dir(), None).expect("TUM data");
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
