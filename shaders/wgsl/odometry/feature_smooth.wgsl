// SPDX-License-Identifier: MIT
//! Each invocation smooths one pixel of an image along one axis with the 5-tap binomial kernel
//! [1 4 6 4 1]/16 (σ ≈ 1 px), edges clamped. Run along x, then along y on the x pass's output,
//! it is the 5×5 binomial smoothing of the intensity image that the descriptors' binary tests and
//! the orientation read, so that one pixel's noise flips few bits (BRIEF's pre-smoothing,
//! Calonder et al. 2010): the kernel is separable, and two passes of 5 taps cost 10 reads a pixel
//! instead of 25. Mirrors core/src/cpu/odometry/feature_smooth.rs.

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

fn binomial5(k: i32) -> f32 {
    let a = abs(k);
    return select(select(1.0, 4.0, a == 1), 6.0, a == 0);
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = vec2<i32>(i32(params.width_px), i32(params.height_px));
    let p = vec2<i32>(gid.xy);
    if p.x >= size.x || p.y >= size.y {
        return;
    }
    let step = select(vec2<i32>(1, 0), vec2<i32>(0, 1), params.axis == 1u);
    var sum = 0.0;
    for (var k = -2; k <= 2; k++) {
        let q = clamp(p + k * step, vec2<i32>(0), size - vec2<i32>(1));
        sum += binomial5(k) * intensity[q.y * size.x + q.x];
    }
    smoothed[p.y * size.x + p.x] = sum * (1.0 / 16.0);
}
