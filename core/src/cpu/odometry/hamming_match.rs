// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/hamming_match.wgsl`.

use crate::cpu::shared::{DESCRIPTOR_BITS, DESCRIPTOR_WORDS, NO_MATCH};
use crate::kernels::hamming_match::HammingMatchParams;

/// Matches every query as the kernel's invocations do.
pub fn hamming_match(params: &HammingMatchParams, query_keypoints: &[[f32; 4]], query_descriptors: &[u32], train_keypoints: &[[f32; 4]], train_descriptors: &[u32], matches: &mut [[u32; 4]]) {
    for q in 0..params.query_count as usize {
        let (mut best, mut best_d, mut second_d) = (NO_MATCH, DESCRIPTOR_BITS + 1, DESCRIPTOR_BITS + 1);
        if query_keypoints[q][3] > 0.0 {
            let query = &query_descriptors[q * DESCRIPTOR_WORDS..(q + 1) * DESCRIPTOR_WORDS];
            for t in 0..params.train_count as usize {
                if !(train_keypoints[t][3] > 0.0) {
                    continue;
                }
                let train = &train_descriptors[t * DESCRIPTOR_WORDS..(t + 1) * DESCRIPTOR_WORDS];
                let d: u32 = query.iter().zip(train).map(|(a, b)| (a ^ b).count_ones()).sum();
                if d < best_d {
                    second_d = best_d;
                    best_d = d;
                    best = t as u32;
                } else if d < second_d {
                    second_d = d;
                }
            }
        }
        matches[q] = [best, best_d, second_d, 0];
    }
}
