// SPDX-License-Identifier: MIT
//! The feature pipeline as composed (`odometry::gpu::FeatureExtractor`: preprocessing,
//! detection, description and matching in one submission, three keypoint sets rotating through
//! their roles) against the CPU chain of twins (`odometry::reference::extract` and
//! `hamming_match`) on four frames of the sample. The GPU's preprocessing is held to its twin
//! within tolerances (bilateral filter), so a keypoint at a threshold may fall either way: at
//! least 98 % of the slots and of the matches must be identical.

use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::odometry::gpu::FeatureExtractor;
use webfusion_core::odometry::reference::matches as cpu_matches;
use webfusion_core::odometry::{FeatureConfig, Features, reference};
use webfusion_core::preprocess::{DepthPreprocessor, PreprocessConfig};
use webfusion_tests::{compare_u32_mostly, finish, gpu, sample_frame};

/// The sample's frame `index` through the CPU chain of twins.
pub(crate) fn cpu_features(index: usize) -> Features {
    let (calibration, frame) = sample_frame(index);
    let pre = preprocess(&calibration, &PreprocessConfig::default(), &frame);
    let levels: Vec<&[f32]> = pre.levels.iter().map(|l| l.intensity.as_slice()).collect();
    reference::extract(&FeatureConfig::default(), &calibration.intrinsics, &levels, &pre.levels[0].depth_m)
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

#[test]
fn the_composed_pipeline_matches_the_twins_through_its_set_rotation() {
    let gpu = gpu();
    let calibration = sample_frame(0).0;
    let preprocessor = DepthPreprocessor::new(&gpu, calibration, PreprocessConfig::default()).expect("preprocessor");
    let mut extractor = FeatureExtractor::new(&gpu, &preprocessor, FeatureConfig::default()).expect("extractor");
    let c: Vec<Features> = (0..4).map(cpu_features).collect();
    let process = |extractor: &mut FeatureExtractor, index: usize| pollster::block_on(extractor.process(&gpu, &preprocessor, &sample_frame(index).1)).expect("process");

    // Frame 0: no reference, no matches.
    let f0 = process(&mut extractor, 0);
    assert!(f0.forward.is_empty());
    assert_keypoints_close("frame 0", &f0.features, &c[0]);
    extractor.accept(true);
    // Frame 1 against 0, then rejected: the reference stays frame 0.
    let f1 = process(&mut extractor, 1);
    assert_keypoints_close("frame 1", &f1.features, &c[1]);
    assert_matches_close("1 -> 0", &f1.forward, &cpu_matches(&c[1], &c[0]));
    assert_matches_close("0 -> 1", &f1.backward, &cpu_matches(&c[0], &c[1]));
    // Frame 2 against 0; the previous tracked frame is the reference itself: no rematch.
    let f2 = process(&mut extractor, 2);
    assert_matches_close("2 -> 0", &f2.forward, &cpu_matches(&c[2], &c[0]));
    assert!(pollster::block_on(extractor.rematch_previous(&gpu)).expect("rematch").is_none());
    // Frame 2 tracked but not a keyframe: frame 3 is matched against 0, and on request 2.
    extractor.accept(false);
    let f3 = process(&mut extractor, 3);
    assert_keypoints_close("frame 3", &f3.features, &c[3]);
    assert_matches_close("3 -> 0", &f3.forward, &cpu_matches(&c[3], &c[0]));
    let (forward, backward) = pollster::block_on(extractor.rematch_previous(&gpu)).expect("rematch").expect("a previous frame");
    assert_matches_close("3 -> 2", &forward, &cpu_matches(&c[3], &c[2]));
    assert_matches_close("2 -> 3", &backward, &cpu_matches(&c[2], &c[3]));
    finish(&gpu);
}
