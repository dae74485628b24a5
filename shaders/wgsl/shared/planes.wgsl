// SPDX-License-Identifier: MIT
// Plane segmentation's shared sizes, markers and normal-histogram mapping (seed 003 §4.3.1).
// Mirrors core/src/planes/mod.rs (the sizes) and core/src/cpu/planes/normal_histogram.rs,
// normal_peaks.rs (the mapping).

// Side of the normal histogram, bins.
const NORMAL_BINS: u32 = 32u;
// Bins of each distance histogram.
const DISTANCE_BINS: u32 = 1024u;
// Most normal peaks per round, and distance peaks (planes) per normal peak.
const MAX_NORMAL_PEAKS: u32 = 8u;
const MAX_DISTANCE_PEAKS: u32 = 8u;
// Most planes a frame's plane list holds.
const MAX_PLANES: u32 = 64u;
// Pixels per chunk of the per-plane sums (plane_sums' workgroup share), and u32 words of each
// chunk's mask of the planes it holds (one bit per plane key below MAX_PLANES).
const PLANE_SUMS_CHUNK_PX: u32 = 4096u;
const CHUNK_MASK_WORDS: u32 = 2u;
// A pixel without a plane.
const NO_LABEL: u32 = 0xffffffffu;
const PLANES_PI: f32 = 3.14159265358979;

// The normal-histogram bin of one component of a normal on the n_z ≥ 0 hemisphere:
// ⌊acos(c) / π · NORMAL_BINS⌋.
fn normal_bin_1d(c: f32) -> u32 {
    return min(u32(acos(clamp(c, -1.0, 1.0)) / PLANES_PI * f32(NORMAL_BINS)), NORMAL_BINS - 1u);
}

// The normal-histogram bin (x, y) of a unit normal: on the hemisphere n_z ≥ 0 (one with
// n_z < 0 is negated first).
fn normal_bin(n: vec3<f32>) -> vec2<u32> {
    let h = select(n, -n, n.z < 0.0);
    return vec2<u32>(normal_bin_1d(h.x), normal_bin_1d(h.y));
}

// The unit normal (n_z ≥ 0) at continuous bin coordinates, bin i spanning [i, i + 1).
fn bin_normal(b: vec2<f32>) -> vec3<f32> {
    let step = PLANES_PI / f32(NORMAL_BINS);
    let x = cos(b.x * step);
    let y = cos(b.y * step);
    let z = sqrt(max(1.0 - x * x - y * y, 0.0));
    return vec3<f32>(x, y, z) / sqrt(x * x + y * y + z * z);
}
