// SPDX-License-Identifier: MIT
// Counter-based random numbers: the same stream on every GPU, in the browser and in the CPU
// twins (core/src/cpu/shared.rs), so a seeded simulation is reproducible anywhere. The hash is
// the PCG permutation of one 32-bit state (O'Neill 2014; recommended for GPU use by Jarzynski
// and Olano, "Hash Functions for GPU Rendering", JCGT 2020).

// One PCG step: a well-mixed 32-bit permutation of `v`.
fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Advances `state` and returns a uniform number in (0, 1) (24 bits, never 0 or 1).
fn random_uniform(state: ptr<function, u32>) -> f32 {
    *state = pcg_hash(*state);
    return (f32(*state >> 8u) + 0.5) * (1.0 / 16777216.0);
}

// Two independent standard normal numbers (Box-Muller), advancing `state` twice.
fn random_gauss2(state: ptr<function, u32>) -> vec2<f32> {
    let u1 = random_uniform(state);
    let u2 = random_uniform(state);
    let r = sqrt(-2.0 * log(u1));
    let phi = 6.2831855 * u2;
    return vec2<f32>(r * cos(phi), r * sin(phi));
}
