// SPDX-License-Identifier: MIT
//! Each invocation smooths one pixel of an intensity image with the 5×5 binomial kernel
//! ([1 4 6 4 1]/16 in each direction, σ ≈ 1 px), edges clamped: the image the descriptors'
//! binary tests and the orientation read, so that one pixel's noise flips few bits (BRIEF's
//! pre-smoothing, Calonder et al. 2010). Mirrors core/src/cpu/odometry/feature_smooth.rs.

struct FeatureSmoothParams {
    width_px: u32,
    height_px: u32,
}

@group(0) @binding(0) var<uniform> params: FeatureSmoothParams;
// Intensity, row-major.
@group(0) @binding(1) var<storage, read> intensity: array<f32>;
// Out: the smoothed intensity.
@group(0) @binding(2) var<storage, read_write> smoothed: array<f32>;

fn binomial5(k: i32) -> f32 {
    let a = abs(k);
    return select(select(1.0, 4.0, a == 1), 6.0, a == 0);
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = i32(params.width_px);
    let h = i32(params.height_px);
    if i32(gid.x) >= w || i32(gid.y) >= h {
        return;
    }
    var sum = 0.0;
    for (var dy = -2; dy <= 2; dy++) {
        let y = clamp(i32(gid.y) + dy, 0, h - 1);
        var row = 0.0;
        for (var dx = -2; dx <= 2; dx++) {
            let x = clamp(i32(gid.x) + dx, 0, w - 1);
            row += binomial5(dx) * intensity[y * w + x];
        }
        sum += binomial5(dy) * row;
    }
    smoothed[i32(gid.y) * w + i32(gid.x)] = sum * (1.0 / 256.0);
}
