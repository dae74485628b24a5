// SPDX-License-Identifier: MIT
//! The feature pipeline as composed (`odometry::gpu::FeatureExtractor`: preprocessing,
//! detection, description, matching and the motion estimate in one submission, three keypoint
//! sets rotating through their roles) against the CPU chain of twins
//! (`odometry::reference::extract`, `hamming_match` and `tracker::estimate_motion`) on four
//! frames of the sample. The GPU's preprocessing is held to its twin within tolerances
//! (intensity), so a keypoint at a threshold may fall either way: at least 98 % of the
//! slots and of the matches must be identical, and the motions agree within 2 mm and 0.2°
//! (the same method on nearly the same pairs).

use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::odometry::gpu::FeatureExtractor;
use webfusion_core::odometry::reference::matches as cpu_matches;
use webfusion_core::odometry::tracker::{MotionEstimate, OdometryConfig, estimate_motion};
use webfusion_core::odometry::{FeatureConfig, Features, reference};
use webfusion_core::preprocess::{DepthPreprocessor, PreprocessConfig};
use webfusion_tests::{compare_u32_mostly, finish, gpu, sample_frame};

/// The sample's frame `index` through the CPU chain of twins.
pub(crate) fn cpu_features(index: usize) -> Features {
    let (calibration, frame) = sample_frame(index);
    let pre = preprocess(&calibration, &PreprocessConfig::default(), &frame);
    let levels: Vec<&[f32]> = pre.levels.iter().map(|l| l.intensity.as_slice()).collect();
    reference::extract(&FeatureConfig::default(), &calibration.intrinsics, &levels, &pre.depth_unfiltered_m)
}

/// Keypoint slots (position, level, whether held) at most 2 % different.
fn assert_keypoints_close(what: &str, g: &Features, c: &Features) {
    let key = |f: &Features| f.keypoints.iter().map(|k| if k[3] > 0.0 { (k[1] as u32) << 16 | k[0] as u32 } else { u32::MAX }).collect::<Vec<u32>>();
    let differ = compare_u32_mostly(what, &key(g), &key(c), 20).unwrap();
    eprintln!("{what}: {differ} of {} slots differ", g.slots());
    // Negative control: every keypoint moved by a pixel.
    let moved: Vec<u32> = key(g).iter().map(|&k| if k == u32::MAX { k } else { k + 1 }).collect();
    assert!(compare_u32_mostly(what, &moved, &key(c), 20).is_err(), "{what}: moved keypoints passed");
}

fn assert_matches_close(what: &str, g: &[[u32; 4]], c: &[[u32; 4]]) {
    let nearest = |m: &[[u32; 4]]| m.iter().map(|m| m[0]).collect::<Vec<u32>>();
    let differ = compare_u32_mostly(what, &nearest(g), &nearest(c), 20).unwrap();
    eprintln!("{what}: {differ} of {} nearest neighbours differ", g.len());
    let shifted: Vec<u32> = nearest(g).iter().map(|&t| t.wrapping_add(1)).collect();
    assert!(compare_u32_mostly(what, &shifted, &nearest(c), 20).is_err(), "{what}: shifted matches passed");
}

/// Both accepted, within 2 mm and 0.2°, inlier counts within 10 %; and a motion moved by 5 mm
/// fails the same check (negative control).
fn assert_motions_close(what: &str, g: &MotionEstimate, c: &MotionEstimate) {
    let close = |g: &MotionEstimate| -> Result<(f64, f64), String> {
        let (Some(gm), Some(cm)) = (g.reference_from_current(), c.reference_from_current()) else { return Err(format!("{what}: accepted {} vs twin {}", g.rigid.is_some(), c.rigid.is_some())) };
        let d = cm.inverse().compose(&gm);
        let (t_mm, r_deg) = (d.translation_m.length() * 1e3, d.rotation_angle_rad().to_degrees());
        let (gi, ci) = (g.inliers() as f64, c.inliers() as f64);
        if t_mm <= 2.0 && r_deg <= 0.2 && (gi - ci).abs() <= 0.1 * ci + 1.0 { Ok((t_mm, r_deg)) } else { Err(format!("{what}: {t_mm} mm, {r_deg}° apart; inliers {gi} vs {ci}")) }
    };
    let (t_mm, r_deg) = close(g).unwrap();
    eprintln!("{what}: {} pairs, {} inliers (twin {}, {}); {t_mm:.3} mm {r_deg:.4}° apart", g.matches, g.inliers(), c.matches, c.inliers());
    let mut moved = g.clone();
    if let Some(r) = moved.rigid.as_mut() {
        r.dst_from_src.translation_m.x += 0.005;
    }
    assert!(close(&moved).is_err(), "{what}: a motion 5 mm off passed");
}

#[test]
fn the_composed_pipeline_matches_the_twins_through_its_set_rotation() {
    let gpu = gpu();
    let calibration = sample_frame(0).0;
    let preprocessor = DepthPreprocessor::new(&gpu, calibration, PreprocessConfig::default()).expect("preprocessor");
    let config = OdometryConfig::default();
    let mut extractor = FeatureExtractor::new(&gpu, &preprocessor, config).expect("extractor").matching_previous();
    let c: Vec<Features> = (0..4).map(cpu_features).collect();
    let process = |extractor: &mut FeatureExtractor, index: usize| pollster::block_on(extractor.process(&gpu, &preprocessor, &sample_frame(index).1, index as u32)).expect("process");
    let k0 = calibration.intrinsics;
    let cpu_motion = |current: usize, reference: usize| estimate_motion(&config, &k0, &c[current], &c[reference], &cpu_matches(&c[current], &c[reference]), &cpu_matches(&c[reference], &c[current]), current as u32);

    // Frame 0: no reference, no matches.
    let f0 = process(&mut extractor, 0);
    assert!(f0.forward.is_empty() && f0.motion.is_none() && f0.motion_previous.is_none());
    assert_keypoints_close("frame 0", &f0.features, &c[0]);
    extractor.accept(true);
    // Frame 1 against 0, then rejected: the reference stays frame 0.
    let f1 = process(&mut extractor, 1);
    assert_keypoints_close("frame 1", &f1.features, &c[1]);
    assert_matches_close("1 -> 0", &f1.forward, &cpu_matches(&c[1], &c[0]));
    assert_matches_close("0 -> 1", &f1.backward, &cpu_matches(&c[0], &c[1]));
    assert_motions_close("motion 1 -> 0", f1.motion.as_ref().expect("a motion"), &cpu_motion(1, 0));
    // Frame 2 against 0; the previous tracked frame is the reference itself: no second path.
    let f2 = process(&mut extractor, 2);
    assert_matches_close("2 -> 0", &f2.forward, &cpu_matches(&c[2], &c[0]));
    assert!(f2.motion_previous.is_none());
    // Frame 2 tracked but not a keyframe: frame 3 is matched against 0 and, in the same
    // submission, against 2 (the reference's matches are the ones read back).
    extractor.accept(false);
    let f3 = process(&mut extractor, 3);
    assert_keypoints_close("frame 3", &f3.features, &c[3]);
    assert_matches_close("3 -> 0", &f3.forward, &cpu_matches(&c[3], &c[0]));
    assert_motions_close("motion 3 -> 0", f3.motion.as_ref().expect("a motion"), &cpu_motion(3, 0));
    assert_matches_close("0 -> 3", &f3.backward, &cpu_matches(&c[0], &c[3]));
    assert_motions_close("motion 3 -> 2", f3.motion_previous.as_ref().expect("a motion against the previous frame"), &cpu_motion(3, 2));
    finish(&gpu);
}
