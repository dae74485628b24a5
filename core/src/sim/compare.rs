// SPDX-License-Identifier: MIT
//! Simulated depth against real depth (seed 000 §6.3): per frame, A = the simulation and B =
//! the real sensor at the same pose, over the pixels valid in both,
//! - the thesis's error metric: % of pixels with |A − B| / B > 10 %;
//! - the thesis's "new pixels": 100 · (A_valid − B_valid) / B_valid;
//! - coverage: % of B's valid pixels that A renders;
//! - mean and median |A − B| (mm), and per distance of B (0.25 m bins) the signed error's
//!   median and spread (1.4826 · MAD, a Gaussian's σ robust to outliers), so a noise model can be
//!   checked against reality.
//!
//! Both images are raw depth along z (0: no return) in their own units per metre.

/// Width of a distance bin, metres.
pub const DISTANCE_BIN_M: f64 = 0.25;
/// Distance bins (0 to 8 m).
pub const DISTANCE_BINS: usize = 32;
/// Relative error above which a pixel counts as wrong (the thesis's 10 %).
pub const REL_ERROR_THRESHOLD: f64 = 0.1;
/// Signed errors are histogrammed in 1 mm bins over ±this many mm (beyond: clamped).
const SIGNED_RANGE_MM: i64 = 500;
/// |A − B| is histogrammed in 0.1 mm bins up to this many mm (beyond: clamped).
const ABS_RANGE_MM: f64 = 2000.0;

/// The metrics of one frame (or of a whole run).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DepthComparison {
    /// % of the pixels valid in both with |A − B| / B > 10 %.
    pub pixels_rel_error_over_10pct_percent: f64,
    /// 100 · (A_valid − B_valid) / B_valid.
    pub new_valid_pixels_percent: f64,
    /// % of B's valid pixels valid in A too.
    pub coverage_percent: f64,
    /// Mean |A − B| over the pixels valid in both, mm.
    pub mean_abs_error_mm: f64,
    /// Median |A − B| over the pixels valid in both, mm (0.1 mm resolution).
    pub median_abs_error_mm: f64,
    /// Pixels valid in A (simulated).
    pub sim_valid: u64,
    /// Pixels valid in B (real).
    pub real_valid: u64,
    /// Pixels valid in both.
    pub both_valid: u64,
}

/// One distance bin's statistics of the signed error A − B.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DistanceBin {
    /// Lower edge (of B's depth), metres.
    pub from_m: f64,
    /// Pixels in the bin.
    pub pixels: u64,
    /// Mean |A − B|, mm.
    pub mean_abs_error_mm: f64,
    /// Median of A − B, mm.
    pub median_error_mm: f64,
    /// 1.4826 · median |A − B − median|: the spread, mm.
    pub robust_sigma_mm: f64,
    /// % of the bin's pixels over the 10 % relative error.
    pub rel_error_over_10pct_percent: f64,
}

/// Pixel statistics of any number of frames.
#[derive(Clone, Debug)]
pub struct Accumulator {
    sim_valid: u64,
    real_valid: u64,
    both_valid: u64,
    over: u64,
    abs_sum_mm: f64,
    abs_histogram: Vec<u64>,
    bins: Vec<BinAccumulator>,
}

#[derive(Clone, Debug)]
struct BinAccumulator {
    pixels: u64,
    over: u64,
    abs_sum_mm: f64,
    signed_histogram: Vec<u64>,
}

impl Default for Accumulator {
    fn default() -> Self {
        Self {
            sim_valid: 0,
            real_valid: 0,
            both_valid: 0,
            over: 0,
            abs_sum_mm: 0.0,
            abs_histogram: vec![0; (ABS_RANGE_MM * 10.0) as usize + 1],
            bins: vec![BinAccumulator { pixels: 0, over: 0, abs_sum_mm: 0.0, signed_histogram: vec![0; 2 * SIGNED_RANGE_MM as usize + 1] }; DISTANCE_BINS],
        }
    }
}

/// The value below which `fraction` of a histogram's mass lies (bin `i` holds `value(i)`).
fn histogram_quantile(histogram: &[u64], fraction: f64, value: impl Fn(usize) -> f64) -> f64 {
    let total: u64 = histogram.iter().sum();
    if total == 0 {
        return f64::NAN;
    }
    let target = (fraction * total as f64).ceil().max(1.0) as u64;
    let mut seen = 0;
    for (i, &n) in histogram.iter().enumerate() {
        seen += n;
        if seen >= target {
            return value(i);
        }
    }
    value(histogram.len() - 1)
}

fn percent(part: f64, whole: f64) -> f64 {
    if whole > 0.0 { 100.0 * part / whole } else { f64::NAN }
}

impl Accumulator {
    /// Adds a frame: `sim` and `real` raw depth of one size, in `sim_units_per_metre` and
    /// `real_units_per_metre`.
    ///
    /// # Panics
    /// If the images differ in size (the caller checks: a typed error there).
    pub fn add(&mut self, sim: &[u16], sim_units_per_metre: f64, real: &[u16], real_units_per_metre: f64) {
        assert_eq!(sim.len(), real.len(), "images of one size");
        for (&a, &b) in sim.iter().zip(real) {
            self.sim_valid += u64::from(a > 0);
            self.real_valid += u64::from(b > 0);
            if a == 0 || b == 0 {
                continue;
            }
            let a_m = f64::from(a) / sim_units_per_metre;
            let b_m = f64::from(b) / real_units_per_metre;
            let e_mm = (a_m - b_m) * 1e3;
            let over = (a_m - b_m).abs() / b_m > REL_ERROR_THRESHOLD;
            self.both_valid += 1;
            self.over += u64::from(over);
            self.abs_sum_mm += e_mm.abs();
            self.abs_histogram[((e_mm.abs() * 10.0).round().min(ABS_RANGE_MM * 10.0)) as usize] += 1;
            let bin = &mut self.bins[((b_m / DISTANCE_BIN_M) as usize).min(DISTANCE_BINS - 1)];
            bin.pixels += 1;
            bin.over += u64::from(over);
            bin.abs_sum_mm += e_mm.abs();
            bin.signed_histogram[((e_mm.round() as i64).clamp(-SIGNED_RANGE_MM, SIGNED_RANGE_MM) + SIGNED_RANGE_MM) as usize] += 1;
        }
    }

    /// The metrics of everything added (pixel-weighted).
    pub fn metrics(&self) -> DepthComparison {
        DepthComparison {
            pixels_rel_error_over_10pct_percent: percent(self.over as f64, self.both_valid as f64),
            new_valid_pixels_percent: percent(self.sim_valid as f64 - self.real_valid as f64, self.real_valid as f64),
            coverage_percent: percent(self.both_valid as f64, self.real_valid as f64),
            mean_abs_error_mm: if self.both_valid > 0 { self.abs_sum_mm / self.both_valid as f64 } else { f64::NAN },
            median_abs_error_mm: histogram_quantile(&self.abs_histogram, 0.5, |i| i as f64 / 10.0),
            sim_valid: self.sim_valid,
            real_valid: self.real_valid,
            both_valid: self.both_valid,
        }
    }

    /// The error per distance of the real depth (bins with pixels only).
    pub fn distance_bins(&self) -> Vec<DistanceBin> {
        self.bins
            .iter()
            .enumerate()
            .filter(|(_, b)| b.pixels > 0)
            .map(|(i, b)| {
                let signed = |j: usize| j as f64 - SIGNED_RANGE_MM as f64;
                let median = histogram_quantile(&b.signed_histogram, 0.5, signed);
                // |e − median| histogram, from the signed one.
                let mut deviation = vec![0u64; 2 * SIGNED_RANGE_MM as usize + 1];
                for (j, &n) in b.signed_histogram.iter().enumerate() {
                    deviation[(signed(j) - median).abs().round() as usize] += n;
                }
                DistanceBin {
                    from_m: i as f64 * DISTANCE_BIN_M,
                    pixels: b.pixels,
                    mean_abs_error_mm: b.abs_sum_mm / b.pixels as f64,
                    median_error_mm: median,
                    robust_sigma_mm: 1.4826 * histogram_quantile(&deviation, 0.5, |j| j as f64),
                    rel_error_over_10pct_percent: percent(b.over as f64, b.pixels as f64),
                }
            })
            .collect()
    }
}

/// The metrics of one frame pair.
pub fn compare_depth(sim: &[u16], sim_units_per_metre: f64, real: &[u16], real_units_per_metre: f64) -> DepthComparison {
    let mut a = Accumulator::default();
    a.add(sim, sim_units_per_metre, real, real_units_per_metre);
    a.metrics()
}

/// A difference image (RGB8): where both are valid, |A − B| on the depth colour map from 0
/// (dark blue) to `max_error_mm` (yellow); where only the real frame has a return, red; where
/// only the simulation has one, white; where neither, black.
pub fn difference_image(sim: &[u16], sim_units_per_metre: f64, real: &[u16], real_units_per_metre: f64, max_error_mm: f32) -> Vec<u8> {
    sim.iter()
        .zip(real)
        .flat_map(|(&a, &b)| match (a > 0, b > 0) {
            (true, true) => {
                let e_mm = ((f64::from(a) / sim_units_per_metre - f64::from(b) / real_units_per_metre).abs() * 1e3) as f32;
                // Offset by a hair so an exact match is the map's dark end, not "no return".
                let c = crate::cpu::shared::depth_colour(e_mm.max(1e-3), max_error_mm).to_le_bytes();
                [c[0], c[1], c[2]]
            }
            (false, true) => [220, 30, 30],
            (true, false) => [255, 255, 255],
            (false, false) => [0, 0, 0],
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_thesis_metrics_on_a_hand_made_pair() {
        // B (real, mm): 4 valid pixels. A (sim, TUM units): one missing, one 20 % off, two
        // exact, one new.
        let real = [1000u16, 2000, 3000, 4000, 0, 0];
        let sim = [5000u16, 12000, 15000, 0, 10000, 0];
        let m = compare_depth(&sim, 5000.0, &real, 1000.0);
        assert_eq!((m.sim_valid, m.real_valid, m.both_valid), (4, 4, 3));
        assert!((m.pixels_rel_error_over_10pct_percent - 100.0 / 3.0).abs() < 1e-9, "{m:?}");
        assert!((m.new_valid_pixels_percent - 0.0).abs() < 1e-9);
        assert!((m.coverage_percent - 75.0).abs() < 1e-9);
        assert!((m.mean_abs_error_mm - 400.0 / 3.0).abs() < 1e-9);
        assert!((m.median_abs_error_mm - 0.0).abs() < 1e-9);
        let bins = Accumulator::default();
        assert!(bins.distance_bins().is_empty());
        let image = difference_image(&sim, 5000.0, &real, 1000.0, 100.0);
        assert_eq!(&image[9..12], &[220, 30, 30], "real only: red");
        assert_eq!(&image[12..15], &[255, 255, 255], "sim only: white");
        assert_eq!(&image[15..18], &[0, 0, 0], "neither: black");
        assert_ne!(&image[0..3], &[0, 0, 0], "an exact match is not black");
    }

    #[test]
    fn the_distance_bins_recover_a_known_spread() {
        // Real depth 2.1 m everywhere; the simulation off by -49..=50 mm, once each: median 0,
        // median |e - 0| 25 mm, mean |e| 25 mm.
        let real = vec![10500u16; 100];
        let sim: Vec<u16> = (0..100).map(|i| (10500 + 5 * (i - 49)) as u16).collect();
        let mut a = Accumulator::default();
        a.add(&sim, 5000.0, &real, 5000.0);
        let bins = a.distance_bins();
        assert_eq!(bins.len(), 1);
        let b = bins[0];
        assert!((b.from_m - 2.0).abs() < 1e-12 && b.pixels == 100, "{b:?}");
        assert_eq!(b.median_error_mm, 0.0, "{b:?}");
        assert!((b.robust_sigma_mm - 1.4826 * 25.0).abs() < 1e-9, "{b:?}");
        assert!((b.mean_abs_error_mm - 25.0).abs() < 1e-9, "{b:?}");
        assert_eq!(b.rel_error_over_10pct_percent, 0.0);
        // Negative control: a 10x larger spread is seen as one.
        let wide: Vec<u16> = (0..100).map(|i| (10500 + 50 * (i - 49)) as u16).collect();
        let mut w = Accumulator::default();
        w.add(&wide, 5000.0, &real, 5000.0);
        assert!(w.distance_bins()[0].robust_sigma_mm > 5.0 * b.robust_sigma_mm);
    }
}
