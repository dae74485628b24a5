// SPDX-License-Identifier: MIT
//! Each invocation smooths four pixels of an image that follow one another along one axis
//! ((4x .. 4x + 3, y) along x, (x, 4y .. 4y + 3) along y), one per component of its vectors,
//! with the 5-tap binomial kernel [1 4 6 4 1]/16 (σ ≈ 1 px), edges clamped. Run along x, then
//! along y on the x pass's output, it is the 5×5 binomial smoothing of the intensity image that
//! the descriptors' binary tests and the orientation read, so that one pixel's noise flips few
//! bits (BRIEF's pre-smoothing, Calonder et al. 2010): the kernel is separable, and two passes
//! of 5 taps cost 10 reads a pixel instead of 25; the four pixels' windows share their taps, 8
//! reads for four pixels instead of 20 (on CPU adapters a read is a scalar load per lane and
//! costs more than the arithmetic). Each pixel sums its own taps in the same order as the
//! twin. Mirrors core/src/cpu/odometry/feature_smooth.rs.
struct FeatureSmoothParams {
    width_px: u32,
    height_px: u32,
    // 0: along x (within rows); 1: along y (within columns).
    axis: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: FeatureSmoothParams;
// The image, row-major: the intensity (x pass) or the x pass's output (y pass).
@group(0) @binding(1) var<storage, read> intensity: array<f32>;
// Out: the image smoothed along `axis`.
@group(0) @binding(2) var<storage, read_write> smoothed: array<f32>;

// The binomial weight of each tap offset k in -2..2, 0 outside.
fn binomial5(k: vec4<i32>) -> vec4<f32> {
    let a = abs(k);
    return select(select(select(vec4<f32>(0.0), vec4<f32>(1.0), a == vec4<i32>(2)), vec4<f32>(4.0), a == vec4<i32>(1)), vec4<f32>(6.0), a == vec4<i32>(0));
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = vec2<i32>(i32(params.width_px), i32(params.height_px));
    let along_y = params.axis == 1u;
    let step = select(vec2<i32>(1, 0), vec2<i32>(0, 1), along_y);
    // The first of the invocation's four pixels.
    let first = select(vec2<i32>(4 * i32(gid.x), i32(gid.y)), vec2<i32>(i32(gid.x), 4 * i32(gid.y)), along_y);
    if first.x >= size.x || first.y >= size.y {
        return;
    }
    // Tap t (first + t * step) is offset t - j from pixel j.
    var sum = vec4<f32>(0.0);
    for (var t = -2; t <= 5; t++) {
        let q = clamp(first + t * step, vec2<i32>(0), size - vec2<i32>(1));
        sum += binomial5(vec4<i32>(t) - vec4<i32>(0, 1, 2, 3)) * intensity[q.y * size.x + q.x];
    }
    let out = sum * (1.0 / 16.0);
    for (var j = 0; j < 4; j++) {
        let p = first + j * step;
        if p.x < size.x && p.y < size.y {
            smoothed[p.y * size.x + p.x] = out[j];
        }
    }
}
