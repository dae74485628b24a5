// SPDX-License-Identifier: MIT
//! `hamming_match`: brute-force nearest and second-nearest Hamming distances against the CPU
//! twin, exactly (integers), on descriptors with known distances and on two real frames'
//! keypoints.

use webfusion_core::cpu;
use webfusion_core::cpu::shared::NO_MATCH;
use webfusion_core::kernels::hamming_match::HammingMatchParams;
use webfusion_core::odometry::Features;
use webfusion_tests::{Slot, cast, compare_u32_mostly, finish, gpu, run_kernel_slots};

use super::pipeline::cpu_features;

fn run(query: &Features, train: &Features) -> (Vec<[u32; 4]>, Vec<[u32; 4]>) {
    let gpu = gpu();
    let p = HammingMatchParams { query_count: query.slots() as u32, train_count: train.slots() as u32 };
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.hamming_match,
        &p,
        &[
            Slot::In(bytemuck::cast_slice(&query.keypoints)),
            Slot::In(bytemuck::cast_slice(&query.descriptors)),
            Slot::In(bytemuck::cast_slice(&train.keypoints)),
            Slot::In(bytemuck::cast_slice(&train.descriptors)),
            Slot::Out(16 * query.slots()),
        ],
        [p.query_count, 1, 1],
    );
    finish(&gpu);
    let mut c = vec![[0u32; 4]; query.slots()];
    cpu::hamming_match(&p, &query.keypoints, &query.descriptors, &train.keypoints, &train.descriptors, &mut c);
    (cast(&out[0]), c)
}

fn assert_exact_with_controls(what: &str, g: &[[u32; 4]], c: &[[u32; 4]]) {
    let (g, c) = (g.as_flattened(), c.as_flattened());
    compare_u32_mostly(what, g, c, 0).unwrap();
    let hit = c.chunks(4).position(|m| m[0] != NO_MATCH).expect("a match");
    let mut other = g.to_vec();
    other[4 * hit] ^= 1;
    let mut farther = g.to_vec();
    farther[4 * hit + 1] += 1;
    let mut sentinel = g.to_vec();
    sentinel[4 * hit + 2] = webfusion_tests::SENTINEL_F32.to_bits();
    let mut shifted = g[4..].to_vec();
    shifted.extend_from_slice(&g[..4]);
    for (case, bad) in [("another train slot", other), ("a larger distance", farther), ("a sentinel", sentinel), ("a shifted output", shifted)] {
        assert!(compare_u32_mostly(what, &bad, c, 0).is_err(), "{what}: the comparison accepted {case}");
    }
}

#[test]
fn known_distances_give_the_nearest_and_second() {
    // Train: slot 0 all zeros, 1 empty, 2 with 3 bits set, 3 with 200 bits set.
    let mut train = Features::with_slots(4);
    for (i, bits) in [(0usize, 0u32), (2, 3), (3, 200)] {
        train.keypoints[i][3] = 1.0;
        for b in 0..bits {
            train.descriptors[8 * i + (b / 32) as usize] |= 1 << (b % 32);
        }
    }
    // Query: slot 0 = 1 bit set; slot 1 empty; slot 2 = 201 bits set.
    let mut query = Features::with_slots(3);
    query.keypoints[0][3] = 1.0;
    query.descriptors[0] = 1;
    query.keypoints[2][3] = 1.0;
    for b in 0..201u32 {
        query.descriptors[16 + (b / 32) as usize] |= 1 << (b % 32);
    }
    let (g, c) = run(&query, &train);
    assert_exact_with_controls("known", &g, &c);
    assert_eq!(g[0], [0, 1, 2, 0]);
    assert_eq!(g[1], [NO_MATCH, 257, 257, 0]);
    assert_eq!(g[2], [3, 1, 198, 0]);
}

#[test]
fn two_real_frames_match_like_the_twin() {
    let (a, b) = (cpu_features(0), cpu_features(1));
    let (g, c) = run(&b, &a);
    assert_exact_with_controls("frames 1 -> 0", &g, &c);
    // Consecutive frames: most keypoints find a close match.
    let close = c.iter().filter(|m| m[0] != NO_MATCH && m[1] < 40).count();
    eprintln!("{close} of {} keypoints within 40 bits", b.keypoint_count());
    assert!(close * 3 > b.keypoint_count(), "{close} close matches of {}", b.keypoint_count());
}

#[test]
fn ties_go_to_the_lowest_train_slot_across_tiles() {
    // 150 train slots (the kernel reads them in tiles of 64), every third one empty. Slots
    // 70.. hold the first query's descriptor (zero) exactly, the others are 5 bits away from it;
    // slot 149 alone is 1 bit from the second query, every other slot 2 or more.
    let n = 150;
    let mut train = Features::with_slots(n);
    for i in (0..n).filter(|i| i % 3 != 0) {
        train.keypoints[i][3] = 1.0;
        if i < 70 {
            train.descriptors[8 * i] = 0b1_1111;
        }
    }
    train.descriptors[8 * 149 + 7] = 1 << 31;
    let mut query = Features::with_slots(2);
    query.keypoints[0][3] = 1.0;
    query.keypoints[1][3] = 1.0;
    query.descriptors[8 + 7] = (1 << 31) | 1;
    let (g, c) = run(&query, &train);
    assert_exact_with_controls("ties", &g, &c);
    // The nearest is the lowest of the equal slots (70; 69 is empty), the second equally near.
    assert_eq!(g[0], [70, 0, 0, 0]);
    // Slot 149 (1 bit), then the zero descriptors of slots 70.. (2 bits), not a slot below 70
    // (7 bits).
    assert_eq!(g[1], [149, 1, 2, 0]);
}
