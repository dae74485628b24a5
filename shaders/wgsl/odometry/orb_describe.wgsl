// SPDX-License-Identifier: MIT
//! Each invocation describes one keypoint slot of one pyramid level (rBRIEF, Rublee et al.
//! 2011, with our own sampling pattern, `odometry::descriptor_pattern`): the keypoint's
//! orientation θ = atan2(m01, m10) from the intensity centroid of the disc of `patch_radius_px`
//! around it (Rosin 1999), then 256 binary tests, bit i = I(R(θ) a_i) < I(R(θ) b_i), on the
//! smoothed level image sampled bilinearly at the pattern's point pairs rotated by θ (not
//! quantised to 12° steps as ORB's lookup tables do). The slot's feature is its position in
//! full-resolution pixels, θ and its level; an empty slot (score 0) gets a zero descriptor and
//! an invalid feature. Mirrors core/src/cpu/odometry/orb_describe.rs.
#import invalid
#import features

struct OrbDescribeParams {
    // The level's size.
    width_px: u32,
    height_px: u32,
    // This level's slots: slot_offset .. slot_offset + slot_count.
    slot_offset: u32,
    slot_count: u32,
    // Radius of the orientation disc, level pixels (the keypoints keep this far from the edges).
    patch_radius_px: u32,
}

@group(0) @binding(0) var<uniform> params: OrbDescribeParams;
// The smoothed level image.
@group(0) @binding(1) var<storage, read> smoothed: array<f32>;
// Per slot: (x, y, level, score), level pixels.
@group(0) @binding(2) var<storage, read> keypoints: array<vec4<f32>>;
// The 256 test pairs (ax, ay, bx, by), pixels, within the disc of radius 13.
@group(0) @binding(3) var<storage, read> pattern: array<vec4<f32>>;
// Out: DESCRIPTOR_WORDS words per slot, bit i of the descriptor in word i / 32, bit i % 32.
@group(0) @binding(4) var<storage, read_write> descriptors: array<u32>;
// Out: per slot, (x, y) in full-resolution pixels, θ radians, level.
@group(0) @binding(5) var<storage, read_write> features: array<vec4<f32>>;

// Bilinear sample of the smoothed image at (x, y) level pixels (pixel centres at integers);
// (x, y) stays at least a pixel inside the image.
fn sample_smoothed(x: f32, y: f32) -> f32 {
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let w = params.width_px;
    let i = u32(y0) * w + u32(x0);
    let top = smoothed[i] * (1.0 - fx) + smoothed[i + 1u] * fx;
    let bottom = smoothed[i + w] * (1.0 - fx) + smoothed[i + w + 1u] * fx;
    return top * (1.0 - fy) + bottom * fy;
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.slot_count {
        return;
    }
    let slot = params.slot_offset + gid.x;
    let kp = keypoints[slot];
    if !(kp.w > 0.0) {
        for (var i = 0u; i < DESCRIPTOR_WORDS; i++) {
            descriptors[slot * DESCRIPTOR_WORDS + i] = 0u;
        }
        features[slot] = invalid_vec4();
        return;
    }
    let x = u32(kp.x);
    let y = u32(kp.y);
    let w = params.width_px;
    // Intensity centroid over the disc.
    let r = i32(params.patch_radius_px);
    var m10 = 0.0;
    var m01 = 0.0;
    for (var dy = -r; dy <= r; dy++) {
        let row = u32(i32(y) + dy) * w;
        for (var dx = -r; dx <= r; dx++) {
            if dx * dx + dy * dy > r * r {
                continue;
            }
            let value = smoothed[row + u32(i32(x) + dx)];
            m10 += f32(dx) * value;
            m01 += f32(dy) * value;
        }
    }
    var theta = 0.0;
    if m10 != 0.0 || m01 != 0.0 {
        theta = atan2(m01, m10);
    }
    let c = cos(theta);
    let s = sin(theta);
    for (var word = 0u; word < DESCRIPTOR_WORDS; word++) {
        var bits = 0u;
        for (var b = 0u; b < 32u; b++) {
            let pair = pattern[word * 32u + b];
            let ia = sample_smoothed(kp.x + c * pair.x - s * pair.y, kp.y + s * pair.x + c * pair.y);
            let ib = sample_smoothed(kp.x + c * pair.z - s * pair.w, kp.y + s * pair.z + c * pair.w);
            if ia < ib {
                bits |= 1u << b;
            }
        }
        descriptors[slot * DESCRIPTOR_WORDS + word] = bits;
    }
    let scale = f32(1u << u32(kp.z));
    features[slot] = vec4<f32>((kp.x + 0.5) * scale - 0.5, (kp.y + 0.5) * scale - 0.5, theta, kp.z);
}
