// SPDX-License-Identifier: MIT
//! The tracker's 6x6 normal equations summed and solved in f64 on the host: the reference the
//! GPU's f32 solve (`track_solve`) is tested against, and a diagnostic for tools.

use nalgebra::{Matrix6, SymmetricEigen, Vector6};

use crate::kernels::track_reduce::SUM_FLOATS;

/// The point-to-plane (plus photometric) system summed in f64 from `track_reduce`'s partials.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalEquations {
    /// JᵀJ.
    pub jtj: Matrix6<f64>,
    /// Jᵀr.
    pub jtr: Vector6<f64>,
    /// Σ r² of the point-to-plane rows, metres².
    pub residual_sq_sum: f64,
    /// Point-to-plane correspondences.
    pub inliers: u64,
    /// Photometric pairs.
    pub rgb_pairs: u64,
}

impl NormalEquations {
    /// Adds the per-workgroup blocks of [`SUM_FLOATS`] floats.
    pub fn from_partial_sums(partials: &[f32]) -> Self {
        let mut sum = [0.0f64; SUM_FLOATS];
        for block in partials.chunks_exact(SUM_FLOATS) {
            for (s, &v) in sum.iter_mut().zip(block) {
                *s += f64::from(v);
            }
        }
        let mut jtj = Matrix6::zeros();
        let mut k = 0;
        for i in 0..6 {
            for j in i..6 {
                jtj[(i, j)] = sum[k];
                jtj[(j, i)] = sum[k];
                k += 1;
            }
        }
        let jtr = Vector6::from_fn(|i, _| sum[21 + i]);
        Self { jtj, jtr, residual_sq_sum: sum[27], inliers: sum[28].round() as u64, rgb_pairs: sum[30].round() as u64 }
    }

    /// RMS point-to-plane residual, metres.
    pub fn rms_residual_m(&self) -> f64 {
        if self.inliers == 0 { 0.0 } else { (self.residual_sq_sum / self.inliers as f64).sqrt() }
    }

    /// JᵀJ as the GPU's solve scales it: rotation columns and rows times `rotation_scale_m`,
    /// then the whole matrix to trace 6; `None` when the trace is not positive.
    pub fn scaled(&self, rotation_scale_m: f64) -> Option<Matrix6<f64>> {
        let d = Vector6::new(rotation_scale_m, rotation_scale_m, rotation_scale_m, 1.0, 1.0, 1.0);
        let m = Matrix6::from_fn(|i, j| self.jtj[(i, j)] * d[i] * d[j]);
        let trace = m.trace();
        (trace > 0.0 && trace.is_finite()).then(|| m * (6.0 / trace))
    }

    /// Largest over smallest eigenvalue of the scaled JᵀJ (what the GPU's conditioning check
    /// uses, in f64), infinite when singular.
    pub fn scaled_condition(&self, rotation_scale_m: f64) -> f64 {
        let Some(s) = self.scaled(rotation_scale_m) else { return f64::INFINITY };
        let eig = SymmetricEigen::new(s).eigenvalues;
        let (lo, hi) = (eig.min(), eig.max());
        if lo > 0.0 { hi / lo } else { f64::INFINITY }
    }

    /// Largest over smallest eigenvalue of the unscaled JᵀJ (rotation rows in radians,
    /// translation in metres).
    pub fn condition(&self) -> f64 {
        let eig = SymmetricEigen::new(self.jtj).eigenvalues;
        let (lo, hi) = (eig.min(), eig.max());
        if lo > 0.0 { hi / lo } else { f64::INFINITY }
    }

    /// The twist (ω, t) minimising Σ (r + J ξ)², by Cholesky in f64; `None` if JᵀJ is not
    /// positive definite.
    pub fn solve(&self) -> Option<Vector6<f64>> {
        let chol = self.jtj.cholesky()?;
        let x = chol.solve(&(-self.jtr));
        x.iter().all(|v| v.is_finite()).then_some(x)
    }
}
