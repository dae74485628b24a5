// SPDX-License-Identifier: MIT
//! Each invocation scores one pixel of an intensity image as a FAST-9 corner (Rosten and
//! Drummond 2006): on the 16-pixel Bresenham circle of radius 3, the largest threshold t for
//! which 9 contiguous circle pixels are all brighter than the centre by more than t, or all
//! darker by more than t (FAST's own score, exact: the best arc's smallest difference). The
//! output is that score where it exceeds `threshold`, else 0; pixels within `border_px` of the
//! image's edge (the descriptor's patch would leave the image) score 0. Any 9 contiguous pixels
//! of the 16 include at least 2 of the 4 compass pixels (0, 4, 8, 12), so a pixel with fewer
//! than 2 compass pixels beyond the threshold on either side cannot score above it and is
//! rejected after 4 reads (FAST's high-speed test, exact). Mirrors
//! core/src/cpu/odometry/fast_score.rs.
#import features

struct FastScoreParams {
    width_px: u32,
    height_px: u32,
    // Pixels this close to an edge get no score.
    border_px: u32,
    // The smallest corner score kept, intensity units ([0, 1]).
    threshold: f32,
}

@group(0) @binding(0) var<uniform> params: FastScoreParams;
// Intensity, row-major, [0, 1].
@group(0) @binding(1) var<storage, read> intensity: array<f32>;
// Out: the corner score, 0 where there is no corner.
@group(0) @binding(2) var<storage, read_write> score: array<f32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = params.width_px;
    let h = params.height_px;
    if gid.x >= w || gid.y >= h {
        return;
    }
    let ix = gid.y * w + gid.x;
    let b = params.border_px;
    if gid.x < b || gid.y < b || gid.x + b >= w || gid.y + b >= h {
        score[ix] = 0.0;
        return;
    }
    let centre = intensity[ix];
    var brighter_compass = 0u;
    var darker_compass = 0u;
    for (var k = 0u; k < 16u; k += 4u) {
        let o = fast_circle_offset(k);
        let d = intensity[u32(i32(gid.y) + o.y) * w + u32(i32(gid.x) + o.x)] - centre;
        brighter_compass += select(0u, 1u, d > params.threshold);
        darker_compass += select(0u, 1u, -d > params.threshold);
    }
    if brighter_compass < 2u && darker_compass < 2u {
        score[ix] = 0.0;
        return;
    }
    // The circle's differences, brighter minus centre.
    var ring: array<f32, 16>;
    for (var k = 0u; k < 16u; k++) {
        let o = fast_circle_offset(k);
        let q = u32(i32(gid.y) + o.y) * w + u32(i32(gid.x) + o.x);
        ring[k] = intensity[q] - centre;
    }
    // The smallest difference over each arc of FAST_ARC = 9 starting at k, for both signs, by
    // doubling: arcs of 2, 4 and 8, then the arc's last pixel, k + FAST_ARC - 1 (16 x 4
    // comparisons a sign instead of 16 x 9; min is exact, so these are the arcs' minima bit for
    // bit). The doubling is written for FAST_ARC = 9 (FAST-9).
    var up: array<f32, 16>;
    var down: array<f32, 16>;
    for (var k = 0u; k < 16u; k++) {
        up[k] = min(ring[k], ring[(k + 1u) & 15u]);
        down[k] = min(-ring[k], -ring[(k + 1u) & 15u]);
    }
    var up4: array<f32, 16>;
    var down4: array<f32, 16>;
    for (var k = 0u; k < 16u; k++) {
        up4[k] = min(up[k], up[(k + 2u) & 15u]);
        down4[k] = min(down[k], down[(k + 2u) & 15u]);
    }
    var best = 0.0;
    for (var k = 0u; k < 16u; k++) {
        let last = ring[(k + FAST_ARC - 1u) & 15u];
        let brighter = min(min(up4[k], up4[(k + 4u) & 15u]), last);
        let darker = min(min(down4[k], down4[(k + 4u) & 15u]), -last);
        best = max(best, max(brighter, darker));
    }
    score[ix] = select(0.0, best, best > params.threshold);
}
