// SPDX-License-Identifier: MIT
//! `match_select`: the matches kept and lifted to 3D pairs, against the CPU twin exactly
//! (integer decisions, copied floats), on constructed matches whose every filter outcome is
//! known (spread over 700 slots, so all 256 invocations' ranges and the keep-best ties across
//! them count) and on two real frames, with negative controls.

use webfusion_core::cpu;
use webfusion_core::cpu::shared::NO_MATCH;
use webfusion_core::kernels::gpu_data::{FeaturePair, RigidEstimate};
use webfusion_core::kernels::match_select::MatchSelectParams;
use webfusion_core::odometry::Features;
use webfusion_core::odometry::matching::MatchConfig;
use webfusion_core::odometry::reference::matches as cpu_matches;
use webfusion_tests::{SENTINEL_F32, Slot, cast, finish, gpu, run_kernel_slots};

use super::pipeline::cpu_features;

/// The inputs of one run: forward and backward matches, and both frames' features.
pub(crate) struct Inputs<'a> {
    pub forward: &'a [[u32; 4]],
    pub backward: &'a [[u32; 4]],
    pub current: &'a Features,
    pub reference: &'a Features,
}

/// Runs match_select on the GPU and its twin: ((pairs, estimate) GPU, (pairs, estimate) twin).
pub(crate) fn run(p: &MatchSelectParams, i: &Inputs) -> ((Vec<FeaturePair>, RigidEstimate), (Vec<FeaturePair>, RigidEstimate)) {
    let gpu = gpu();
    let slots = p.slots as usize;
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.match_select,
        p,
        &[
            Slot::In(bytemuck::cast_slice(i.forward)),
            Slot::In(bytemuck::cast_slice(i.backward)),
            Slot::In(bytemuck::cast_slice(&i.current.keypoints)),
            Slot::In(bytemuck::cast_slice(&i.current.points)),
            Slot::In(bytemuck::cast_slice(&i.reference.keypoints)),
            Slot::In(bytemuck::cast_slice(&i.reference.points)),
            Slot::Out(slots * size_of::<FeaturePair>()),
            Slot::Out(size_of::<RigidEstimate>()),
        ],
        [256, 1, 1],
    );
    finish(&gpu);
    let mut pairs = vec![FeaturePair::default(); slots];
    let mut estimate = RigidEstimate::default();
    cpu::match_select(p, i.forward, i.backward, &i.current.keypoints, &i.current.points, &i.reference.keypoints, &i.reference.points, &mut pairs, &mut estimate);
    ((cast(&out[0]), cast::<RigidEstimate>(&out[1])[0]), (pairs, estimate))
}

/// The kept pairs (the first `estimate.pairs`) equal bit for bit.
fn compare(what: &str, g: &(Vec<FeaturePair>, RigidEstimate), c: &(Vec<FeaturePair>, RigidEstimate)) -> Result<(), String> {
    if g.1 != c.1 {
        return Err(format!("{what}: estimate {:?} vs twin {:?}", g.1, c.1));
    }
    let n = c.1.pairs as usize;
    let bits = |p: &FeaturePair| (p.src.map(f32::to_bits), p.dst.map(f32::to_bits), p.slots);
    match (0..n).find(|&k| bits(&g.0[k]) != bits(&c.0[k])) {
        Some(k) => Err(format!("{what}: pair {k}: {:?} vs twin {:?}", g.0[k], c.0[k])),
        None => Ok(()),
    }
}

/// compare() passes, and fails for a pair with another slot, a moved point, a sentinel and a
/// count off by one.
fn assert_exact_with_controls(what: &str, g: &(Vec<FeaturePair>, RigidEstimate), c: &(Vec<FeaturePair>, RigidEstimate)) {
    compare(what, g, c).unwrap();
    assert!(c.1.pairs > 0, "{what}: a control needs pairs");
    let mut slot = g.clone();
    slot.0[0].slots[1] ^= 1;
    let mut moved = g.clone();
    moved.0[0].dst[2] += 1e-6;
    let mut sentinel = g.clone();
    sentinel.0[(c.1.pairs - 1) as usize].src[0] = SENTINEL_F32;
    let mut count = g.clone();
    count.1.pairs += 1;
    for (case, bad) in [("another slot", slot), ("a moved point", moved), ("a sentinel", sentinel), ("a count off by one", count)] {
        assert!(compare(what, &bad, c).is_err(), "{what}: the comparison accepted {case}");
    }
}

#[test]
fn constructed_matches_keep_exactly_what_each_filter_allows() {
    // 700 slots: slot q matches reference slot q; its distance and second distance cycle so
    // that some pass and some fail each filter; every 7th is not mutual, every 11th has an
    // invalid point, every 13th has no match.
    let slots = 700usize;
    let mut current = Features::with_slots(slots);
    let mut reference = Features::with_slots(slots);
    let mut forward = vec![[NO_MATCH, 257, 257, 0]; slots];
    let mut backward = vec![[NO_MATCH, 257, 257, 0]; slots];
    for q in 0..slots {
        current.keypoints[q] = [q as f32, 1.0, (q % 3) as f32, 10.0];
        reference.keypoints[q] = [q as f32, 2.0, ((q + 1) % 3) as f32, 10.0];
        current.points[q] = [0.001 * q as f32, -0.5, 1.0 + 0.002 * q as f32, 1.0];
        reference.points[q] = [0.001 * q as f32 + 0.01, -0.5, 1.0 + 0.002 * q as f32, 1.0];
        if q % 11 == 5 {
            current.points[q][2] = f32::NAN;
        }
        if q % 13 == 0 {
            continue;
        }
        let d1 = (q * 7 % 120) as u32;
        let d2 = d1 + 5 + (q % 40) as u32;
        forward[q] = [q as u32, d1, d2, 0];
        backward[q] = [if q % 7 == 3 { (q as u32 + 1) % slots as u32 } else { q as u32 }, d1, d2, 0];
    }
    let inputs = Inputs { forward: &forward, backward: &backward, current: &current, reference: &reference };
    for config in [
        MatchConfig::default(),
        MatchConfig { mutual: false, ..MatchConfig::default() },
        MatchConfig { margin_bits: Some(28), ..MatchConfig::default() },
        MatchConfig { keep_best_fraction: Some(0.2), ..MatchConfig::default() },
        MatchConfig { keep_best_fraction: Some(0.37), ratio: 0.95, max_distance_bits: 256, mutual: false, ..MatchConfig::default() },
    ] {
        let p = config.select_params(slots as u32);
        let (g, c) = run(&p, &inputs);
        let what = format!("{config:?}");
        assert_exact_with_controls(&what, &g, &c);
        // The expected set, from the definitions.
        let candidate = |q: usize| {
            let [t, d1, d2, _] = forward[q];
            t != NO_MATCH
                && d1 <= config.max_distance_bits
                && (d1 as f32) < config.ratio * d2 as f32
                && d2 - d1 >= config.margin_bits.unwrap_or(0)
                && (!config.mutual || backward[t as usize][0] == q as u32)
                && !current.points[q][2].is_nan()
        };
        let mut expected: Vec<usize> = (0..slots).filter(|&q| candidate(q)).collect();
        if let Some(f) = config.keep_best_fraction {
            let keep = (expected.len() as f32 * f).ceil() as usize;
            let mut by_distance = expected.clone();
            by_distance.sort_by_key(|&q| (forward[q][1], q));
            by_distance.truncate(keep);
            by_distance.sort();
            expected = by_distance;
        }
        let got: Vec<usize> = g.0[..g.1.pairs as usize].iter().map(|p| p.slots[0] as usize).collect();
        assert_eq!(got, expected, "{what}");
        eprintln!("{what}: {} pairs", got.len());
        let k = expected[0];
        assert_eq!(g.0[0].src, [current.points[k][0], current.points[k][1], current.points[k][2], current.keypoints[k][2]], "{what}: the pair's point and level");
        assert_eq!(g.0[0].slots, [k as u32, k as u32, forward[k][1], 0]);
    }
}

#[test]
fn two_real_frames_select_like_the_twin() {
    let (a, b) = (cpu_features(0), cpu_features(1));
    let (forward, backward) = (cpu_matches(&b, &a), cpu_matches(&a, &b));
    let inputs = Inputs { forward: &forward, backward: &backward, current: &b, reference: &a };
    let (g, c) = run(&MatchConfig::default().select_params(b.slots() as u32), &inputs);
    assert_exact_with_controls("frames 1 -> 0", &g, &c);
    eprintln!("{} pairs of {} keypoints", g.1.pairs, b.keypoint_count());
    // Measured: 75 pairs of 479 keypoints; RANSAC needs 20 inliers.
    assert!(g.1.pairs >= 40, "consecutive frames keep enough pairs to estimate from");
}
