// SPDX-License-Identifier: MIT
// Invalid samples (no depth, no vertex, no normal) are stored as a quiet NaN. WGSL lets an
// implementation assume arithmetic never meets NaN, so validity is tested on the bit pattern
// and NaN is never produced by arithmetic nor by a const-expression (which WGSL forbids).

const INVALID_BITS: u32 = 0x7fc00000u;
const EXPONENT_MASK: u32 = 0x7f800000u;

// The invalid marker. The `var` keeps the bitcast out of const-evaluation.
fn invalid_f32() -> f32 {
    var bits = INVALID_BITS;
    return bitcast<f32>(bits);
}

fn invalid_vec4() -> vec4<f32> {
    let n = invalid_f32();
    return vec4<f32>(n, n, n, n);
}

// True for finite values; false for NaN (invalid) and infinities.
fn is_valid_f32(x: f32) -> bool {
    return (bitcast<u32>(x) & EXPONENT_MASK) != EXPONENT_MASK;
}

// `is_valid_f32` of each component.
fn is_valid_vec4(v: vec4<f32>) -> vec4<bool> {
    return (bitcast<vec4<u32>>(v) & vec4<u32>(EXPONENT_MASK)) != vec4<u32>(EXPONENT_MASK);
}
