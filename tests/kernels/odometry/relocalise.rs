// SPDX-License-Identifier: MIT
//! Relocalisation on the synthetic room (exact depth, view-independent texture): KinectFusion
//! with feature odometry beside it tracks the first eleven poses of the room's loop (each a
//! keyframe: the loop moves 10.5 cm and 4° a frame), then the camera jumps to the far side of
//! the loop, where nothing it saw is in view, and back between two of the early keyframes.
//! The far frames are lost and nothing relocalises them into the map; the return is
//! relocalised against a stored keyframe (not the last tracked frame, 50 cm and 24° away: it
//! is outside the plausible jump) and ICP confirms it: Recovered, within 1 cm and 0.5° of the
//! truth, and the next frames track on from there. Every tracked frame took one submission
//! (features, their guess on the GPU, and the dense frame) and one wait after it. The negative control: a relocalisation to
//! a wrong pose is rejected by ICP and, undone, leaves nothing behind.

use webfusion_core::fusion::{FusionConfig, KinectFusion, TrackingState};
use webfusion_core::odometry::assist::{AssistedFrame, FeatureAssist, Guess};
use webfusion_core::odometry::tracker::OdometryConfig;
use webfusion_core::sim::room::SyntheticRoom;
use webfusion_core::{PinholeIntrinsics, RgbdCalibration, Se3};
use webfusion_tests::{finish, gpu};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 525.0, fy_px: 525.0, cx_px: 319.5, cy_px: 239.5, width_px: 640, height_px: 480 };

#[test]
fn a_return_after_a_jump_is_relocalised_against_a_keyframe_and_confirmed_by_icp() {
    let gpu = gpu();
    let room = SyntheticRoom::new(6.0, 3.0, 6.0);
    let (loop90, loop180) = (room.path(90), room.path(180));
    // Tracked 0..=10; the far side (40, 41); back halfway between 5 and 6, then on.
    let mut poses: Vec<Se3> = loop90[..=10].to_vec();
    poses.extend([loop90[40], loop90[41], loop180[11], loop180[13], loop180[15]]);
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: 5000.0 };
    // The default map (sparse blocks around the first camera, which is the world frame).
    let config = FusionConfig::default();
    let mut fusion = KinectFusion::new(&gpu, calibration, config.clone()).expect("fusion");
    let mut assist = FeatureAssist::new(&gpu, fusion.preprocessor(), OdometryConfig::default()).expect("features");
    assist.set_jump_limits(f64::from(config.icp.max_jump_m), f64::from(config.icp.max_jump_rad));
    assist.keep_pair_view(true);
    let mut outcomes = Vec::new();
    for (i, truth) in poses.iter().enumerate() {
        let frame = room.frame(&K, &poses, i);
        let AssistedFrame { report, guess, host } = pollster::block_on(assist.process_frame(&gpu, &mut fusion, &frame)).expect("frame");
        if matches!(report.state, TrackingState::Tracked | TrackingState::Initialised) {
            // Features, their guess and the dense frame: one submission, one wait after it (and
            // the keypoints for the pair view beside the frame's report).
            assert_eq!((host.submits, host.host_waits, host.readbacks), (1, 1, 2), "frame {i}: {host:?}");
        }
        let error = poses[0].inverse().compose(truth).inverse().compose(&report.world_from_camera);
        let (t_cm, r_deg) = (error.translation_m.length() * 100.0, error.rotation_angle_rad().to_degrees());
        let kind = match guess {
            Some(Guess::Motion(_)) => "motion".to_owned(),
            Some(Guess::Relocalised { keyframe, inliers, .. }) => format!("relocalised against frame {keyframe} ({inliers} inliers)"),
            None => "none".to_owned(),
        };
        eprintln!("frame {i}: {:?}, guess {kind}, error {t_cm:.2} cm {r_deg:.2}°", report.state);
        outcomes.push((report.state, guess, t_cm, r_deg));
    }
    let stats = assist.stats();
    eprintln!("{stats:?}, {} keyframes", assist.keyframes());
    for (i, (state, _, t_cm, r_deg)) in outcomes[..=10].iter().enumerate() {
        assert!(!state.is_lost() && *t_cm < 1.0 && *r_deg < 0.5, "frame {i} of the first stretch: {state:?}, {t_cm} cm, {r_deg}°");
    }
    assert!(outcomes[11].0.is_lost() && outcomes[12].0.is_lost(), "the far side, never mapped, was tracked: {:?}, {:?}", outcomes[11].0, outcomes[12].0);
    let (state, guess, t_cm, r_deg) = outcomes[13];
    assert_eq!(state, TrackingState::Recovered, "the return: guess {guess:?}");
    assert!(matches!(guess, Some(Guess::Relocalised { keyframe, .. }) if keyframe < 10), "relocalised against an early keyframe: {guess:?}");
    assert!(t_cm < 1.0 && r_deg < 0.5, "the return: {t_cm} cm, {r_deg}°");
    for (i, (state, _, t_cm, r_deg)) in outcomes.iter().enumerate().skip(14) {
        assert!(*state == TrackingState::Tracked && *t_cm < 1.0 && *r_deg < 0.5, "frame {i} after the return: {state:?}, {t_cm} cm, {r_deg}°");
    }
    assert_eq!(stats.relocalisations_confirmed, 1, "{stats:?}");
    // The last pair as the browser's odometry view shows it: frame 15 against frame 14.
    let pair = assist.last_pair().expect("a pair");
    let inliers = pair.matches.iter().filter(|m| m.2).count();
    assert_eq!((pair.frame, pair.reference_frame), (15, 14));
    assert!(inliers >= 20 && pair.matches.iter().all(|&(q, t, _)| (q as usize) < pair.current.len() && (t as usize) < pair.reference.len()), "{} matches, {inliers} inliers", pair.matches.len());
    assert!(pair.current.iter().chain(&pair.reference).all(|k| k[0] >= 0.0 && k[0] < 640.0 && k[1] >= 0.0 && k[1] < 480.0), "keypoints in full-resolution pixels");
    assert!(pair.stages_ms[4] >= 0.0 || !gpu.has_timestamps, "the estimation is timed on the GPU");
    finish(&gpu);
}

/// A reseed 30 cm off the truth (a false relocalisation) is rejected by ICP (the frame is lost,
/// nothing fused, the last good pose reported), and reseeding back at the last good pose
/// undoes it: the next frame, taken where the last good one was, is Recovered exactly there
/// (left at the false pose, ICP would start 30 cm off and lose it). The tracked frames start
/// ICP from the true pose, as given poses would, so that only the reseed is under test.
#[test]
fn a_false_relocalisation_is_rejected_by_icp_and_undone() {
    let gpu = gpu();
    let room = SyntheticRoom::new(6.0, 3.0, 6.0);
    let loop180 = room.path(180);
    // The fine loop (5 cm and 2° a frame) to frame 10, frame 11 (falsely relocalised), then
    // frame 10's pose again.
    let mut poses: Vec<Se3> = loop180[..12].to_vec();
    poses.push(loop180[10]);
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: 5000.0 };
    let mut fusion = KinectFusion::new(&gpu, calibration, FusionConfig::default()).expect("fusion");
    let mut last_good = Se3::IDENTITY;
    for (i, truth) in poses.iter().enumerate() {
        let in_world = poses[0].inverse().compose(truth);
        match i {
            11 => fusion.reseed(&gpu, &Se3::new(glam::DQuat::IDENTITY, glam::DVec3::new(0.3, 0.0, 0.0)).compose(&in_world)).expect("reseed"),
            12 => {}
            _ => fusion.set_initial_guess(&gpu, &in_world),
        }
        let report = pollster::block_on(fusion.process_frame(&gpu, &room.frame(&K, &poses, i))).expect("frame");
        let error = in_world.inverse().compose(&report.world_from_camera);
        let (t_cm, r_deg) = (error.translation_m.length() * 100.0, error.rotation_angle_rad().to_degrees());
        eprintln!("frame {i}: {:?}, error {t_cm:.2} cm {r_deg:.2}°", report.state);
        if i == 11 {
            assert!(report.state.is_lost(), "ICP confirmed a relocalisation 30 cm off: {:?}, {t_cm} cm", report.state);
            assert_eq!(report.world_from_camera, last_good, "a lost frame reports the last good pose, not the false one");
            fusion.reseed(&gpu, &last_good).expect("undo");
        } else {
            let expected = match i {
                0 => TrackingState::Initialised,
                12 => TrackingState::Recovered,
                _ => TrackingState::Tracked,
            };
            assert_eq!(report.state, expected, "frame {i}");
            assert!(t_cm < 0.5 && r_deg < 0.2, "frame {i}: {t_cm} cm, {r_deg}°");
            last_good = report.world_from_camera;
        }
    }
    finish(&gpu);
}

/// A jump beyond ICP's plausible inter-frame motion that the features still match (seven steps
/// of the fine loop at once: 36 cm and 14°, most of the view shared): in the frame's single
/// submission ICP starts at the feature motion and its jump check rejects it; the assist then
/// relocalises the frame at that motion against the last tracked frame and tracks it again
/// (the reseed's render and the frame again: three submissions in all), Recovered within 1 cm
/// and 0.5° of the truth. The frames after it are tracked in one submission each.
#[test]
fn a_jump_beyond_icps_limits_is_relocalised_at_the_feature_motion() {
    let gpu = gpu();
    let room = SyntheticRoom::new(6.0, 3.0, 6.0);
    let loop180 = room.path(180);
    let mut poses: Vec<Se3> = loop180[..=6].to_vec();
    poses.extend([loop180[13], loop180[14], loop180[15]]);
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: 5000.0 };
    let config = FusionConfig::default();
    let mut fusion = KinectFusion::new(&gpu, calibration, config.clone()).expect("fusion");
    let mut assist = FeatureAssist::new(&gpu, fusion.preprocessor(), OdometryConfig::default()).expect("features");
    assist.set_jump_limits(f64::from(config.icp.max_jump_m), f64::from(config.icp.max_jump_rad));
    for (i, truth) in poses.iter().enumerate() {
        let AssistedFrame { report, guess, host } = pollster::block_on(assist.process_frame(&gpu, &mut fusion, &room.frame(&K, &poses, i))).expect("frame");
        let error = poses[0].inverse().compose(truth).inverse().compose(&report.world_from_camera);
        let (t_cm, r_deg) = (error.translation_m.length() * 100.0, error.rotation_angle_rad().to_degrees());
        eprintln!("frame {i}: {:?}, guess {guess:?}, {host:?}, error {t_cm:.2} cm {r_deg:.2}°", report.state);
        assert!(t_cm < 1.0 && r_deg < 0.5, "frame {i}: {:?}, {t_cm} cm, {r_deg}°", report.state);
        if i == 7 {
            assert_eq!(report.state, TrackingState::Recovered, "the jump");
            assert!(matches!(guess, Some(Guess::Relocalised { keyframe: 6, .. })), "relocalised at the motion against frame 6: {guess:?}");
            assert_eq!(host.submits, 3, "the frame, the reseed's render, the frame again");
        } else {
            assert!(matches!(report.state, TrackingState::Tracked | TrackingState::Initialised), "frame {i}: {:?}", report.state);
            // Without the pair view, the estimate comes back in the frame's one small readback.
            assert_eq!((host.submits, host.host_waits, host.readbacks), (1, 1, 1), "frame {i}: {host:?}");
            assert!(host.readback_bytes < 4096, "frame {i}: {host:?}");
            assert_eq!(guess.is_some(), i > 0, "frame {i}: {guess:?}");
        }
    }
    assert_eq!(assist.stats().relocalisations_confirmed, 1, "{:?}", assist.stats());
    finish(&gpu);
}

/// A frame more than `MAX_UNSEEDED_GAP_S` after the last tracked one is tracked only from a
/// feature pose that ICP confirms. On the fine loop (5 cm and 2° a frame), tracked to frame 6:
/// frame 7 comes a second later one step on, its colour blanked (no keypoints): ICP from the
/// last pose would track it, but nothing else vouches for that after a gap, so it is lost
/// without tracking (Unverified, not submitted, nothing fused). Frame 8, a thirtieth of a
/// second later with its texture, is relocalised by its features against frame 6 and
/// confirmed by ICP: Recovered. Frame 9 is blank again but within the horizon of frame 8: ICP alone
/// tracks it, as it always did (the control: the same kind of frame the gate withheld is
/// trackable, so the loss came from the gap alone). Frame 10, blank, stamped two seconds
/// before the first (the clock jumped back), is withheld too.
#[test]
fn after_a_gap_only_a_feature_pose_that_icp_confirms_is_tracked() {
    use webfusion_core::fusion::LostReason;
    use webfusion_core::odometry::assist::MAX_UNSEEDED_GAP_S;
    let gpu = gpu();
    let room = SyntheticRoom::new(6.0, 3.0, 6.0);
    let poses: Vec<Se3> = room.path(180)[..11].to_vec();
    let frame_ns = 1_000_000_000 / 30;
    let gap_ns = 1_000_000_000;
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: 5000.0 };
    // Depth-only ICP: a blanked colour image would otherwise disagree with its textured
    // predecessor in the photometric rows.
    let mut config = FusionConfig::default();
    config.icp.rgb_weight = 0.0;
    let mut fusion = KinectFusion::new(&gpu, calibration, config.clone()).expect("fusion");
    let mut assist = FeatureAssist::new(&gpu, fusion.preprocessor(), OdometryConfig::default()).expect("features");
    assist.set_jump_limits(f64::from(config.icp.max_jump_m), f64::from(config.icp.max_jump_rad));
    let mut last_good = Se3::IDENTITY;
    for (i, truth) in poses.iter().enumerate() {
        let mut frame = room.frame(&K, &poses, i);
        let t_ns = match i {
            // A clock that jumped back (a splice, a looped replay) is as much a gap.
            10 => -2 * gap_ns,
            7.. => i as i64 * frame_ns + gap_ns,
            _ => i as i64 * frame_ns,
        };
        (frame.depth_timestamp_ns, frame.color_timestamp_ns) = (t_ns, t_ns);
        if i == 7 || i >= 9 {
            frame.color.rgb8.fill(128);
        }
        let AssistedFrame { report, guess, host } = pollster::block_on(assist.process_frame(&gpu, &mut fusion, &frame)).expect("frame");
        let error = poses[0].inverse().compose(truth).inverse().compose(&report.world_from_camera);
        let (t_cm, r_deg) = (error.translation_m.length() * 100.0, error.rotation_angle_rad().to_degrees());
        eprintln!("frame {i}: {:?}, guess {guess:?}, {host:?}, error {t_cm:.2} cm {r_deg:.2}°", report.state);
        if i == 7 || i == 10 {
            match report.state {
                TrackingState::Lost(LostReason::Unverified { gap_s }) if i == 7 => assert!(gap_s > MAX_UNSEEDED_GAP_S && (gap_s - 1.0 - 1.0 / 30.0).abs() < 1e-6, "gap {gap_s} s"),
                TrackingState::Lost(LostReason::Unverified { gap_s }) => assert!(gap_s < -MAX_UNSEEDED_GAP_S, "gap {gap_s} s"),
                other => panic!("frame {i}, far in time from the last tracked frame with no feature pose, was {other:?}"),
            }
            assert!(guess.is_none() && report.icp.is_empty(), "nothing tracked: {guess:?}, {:?}", report.icp);
            assert_eq!(report.world_from_camera, last_good, "the last good pose is reported");
            continue;
        }
        assert!(!report.state.is_lost() && t_cm < 1.0 && r_deg < 0.5, "frame {i}: {:?}, {t_cm} cm, {r_deg}°", report.state);
        match i {
            8 => assert!(report.state == TrackingState::Recovered && matches!(guess, Some(Guess::Relocalised { keyframe: 6, .. })), "frame 8 placed by its features against frame 6: {:?}, {guess:?}", report.state),
            9 => assert!(guess.is_none() && host.submits == 1, "frame 9 tracked by ICP alone in one submission: {guess:?}, {host:?}"),
            _ => {}
        }
        last_good = report.world_from_camera;
    }
    let stats = assist.stats();
    assert_eq!((stats.withheld, stats.relocalisations_confirmed), (2, 1), "{stats:?}");
    finish(&gpu);
}
