// SPDX-License-Identifier: MIT
// Keypoints and binary descriptors (seed 002's feature odometry). Mirrors the twins in
// core/src/cpu/shared.rs.

// FAST's arc: 9 contiguous pixels of the 16 on the circle (FAST-9, the most repeatable).
const FAST_ARC: u32 = 9u;
// 32-bit words per descriptor (256 binary tests).
const DESCRIPTOR_WORDS: u32 = 8u;
// Binary tests per descriptor.
const DESCRIPTOR_BITS: u32 = 256u;
// An empty keypoint slot's or unmatched query's index.
const NO_MATCH: u32 = 0xffffffffu;

// Offset of circle pixel `k` (0..16, clockwise from the top in image coordinates: x right,
// y down) on the Bresenham circle of radius 3.
fn fast_circle_offset(k: u32) -> vec2<i32> {
    var circle = array<vec2<i32>, 16>(
        vec2<i32>(0, -3), vec2<i32>(1, -3), vec2<i32>(2, -2), vec2<i32>(3, -1),
        vec2<i32>(3, 0), vec2<i32>(3, 1), vec2<i32>(2, 2), vec2<i32>(1, 3),
        vec2<i32>(0, 3), vec2<i32>(-1, 3), vec2<i32>(-2, 2), vec2<i32>(-3, 1),
        vec2<i32>(-3, 0), vec2<i32>(-3, -1), vec2<i32>(-2, -2), vec2<i32>(-1, -3),
    );
    return circle[k];
}
