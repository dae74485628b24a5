// SPDX-License-Identifier: MIT
// Dense symmetric positive-definite solves in f32, for the Gauss-Newton steps of the ICP
// tracker (track_solve) and of the feature estimate (ransac_refine). Mirrors
// core/src/cpu/shared.rs::cholesky_solve6.

// The solution of a 6 × 6 system, or ok = false.
struct Solve6 {
    x: array<f32, 6>,
    ok: bool,
}

// Solves s x = y for the symmetric s (row-major, 6 × 6) by Cholesky, s = L Lᵀ, then L g = y
// and Lᵀ x = g; not ok when a pivot is not above `min_pivot` (s is not positive definite to
// f32 precision: callers scale s so that its diagonal is about 1).
fn cholesky_solve6(s: array<f32, 36>, y: array<f32, 6>, min_pivot: f32) -> Solve6 {
    var out: Solve6;
    var l: array<f32, 36>;
    for (var j = 0u; j < 6u; j++) {
        var diag = s[j * 7u];
        for (var k = 0u; k < j; k++) {
            diag -= l[j * 6u + k] * l[j * 6u + k];
        }
        if !(diag > min_pivot) {
            out.ok = false;
            return out;
        }
        let ljj = sqrt(diag);
        l[j * 7u] = ljj;
        for (var i = j + 1u; i < 6u; i++) {
            var v = s[i * 6u + j];
            for (var k = 0u; k < j; k++) {
                v -= l[i * 6u + k] * l[j * 6u + k];
            }
            l[i * 6u + j] = v / ljj;
        }
    }
    var g: array<f32, 6>;
    for (var i = 0u; i < 6u; i++) {
        var v = y[i];
        for (var k = 0u; k < i; k++) {
            v -= l[i * 6u + k] * g[k];
        }
        g[i] = v / l[i * 7u];
    }
    for (var ii = 0u; ii < 6u; ii++) {
        let i = 5u - ii;
        var v = g[i];
        for (var k = i + 1u; k < 6u; k++) {
            v -= l[k * 6u + i] * out.x[k];
        }
        out.x[i] = v / l[i * 7u];
    }
    out.ok = true;
    return out;
}
