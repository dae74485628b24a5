// SPDX-License-Identifier: MIT
//! `webfusion compare`: simulated depth (A, `simulate`'s directory) against real depth (B, a
//! TUM directory or recording) at the same timestamps: seed 000's two metrics, coverage and
//! absolute errors per frame and overall, a difference image per frame and an error-vs-distance
//! chart (`core::sim::compare`).

use std::path::PathBuf;

use anyhow::Context as _;
use serde_json::json;
use webfusion_core::io::format_timestamp_s;
use webfusion_core::sim::compare::{Accumulator, DepthComparison, DistanceBin, compare_depth, difference_image};
use webfusion_core::source::FrameSource;

use crate::calib::CalibrationArgs;

/// |A − B| at the warm end of the difference images' colour map, mm.
const DIFFERENCE_IMAGE_MAX_MM: f32 = 100.0;

#[derive(clap::Args)]
pub(crate) struct CompareArgs {
    /// The real frames (B): a TUM directory or a `.wfr` recording.
    #[arg(long)]
    real: PathBuf,
    /// The simulated frames (A): a directory `simulate` wrote (or any TUM directory).
    #[arg(long)]
    sim: PathBuf,
    /// Write a difference image per frame (`diff/<timestamp>.png`: |A − B| from dark blue at 0
    /// to yellow at 10 cm; red: only the real frame has a return; white: only the simulation),
    /// the chart `error_vs_distance.png` and `compare.json` here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write the metrics as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Largest depth-timestamp difference of a pair, milliseconds.
    #[arg(long, default_value_t = 20.0)]
    max_difference_ms: f64,
    /// Calibration of the real frames (their depth scale), when the source does not carry it.
    #[command(flatten)]
    calibration: CalibrationArgs,
}

fn metrics_json(m: &DepthComparison) -> serde_json::Value {
    json!({
        "pixels_rel_error_over_10pct_percent": m.pixels_rel_error_over_10pct_percent,
        "new_valid_pixels_percent": m.new_valid_pixels_percent,
        "coverage_percent": m.coverage_percent,
        "mean_abs_error_mm": m.mean_abs_error_mm,
        "median_abs_error_mm": m.median_abs_error_mm,
        "sim_valid_pixels": m.sim_valid,
        "real_valid_pixels": m.real_valid,
        "both_valid_pixels": m.both_valid,
    })
}

fn bin_json(b: &DistanceBin) -> serde_json::Value {
    json!({
        "from_m": b.from_m,
        "to_m": b.from_m + webfusion_core::sim::compare::DISTANCE_BIN_M,
        "pixels": b.pixels,
        "mean_abs_error_mm": b.mean_abs_error_mm,
        "median_error_mm": b.median_error_mm,
        "robust_sigma_mm": b.robust_sigma_mm,
        "rel_error_over_10pct_percent": b.rel_error_over_10pct_percent,
    })
}

/// Pairs each simulated frame with the real frame nearest in depth time within `max_ns`
/// (inclusive), closest pairs first, each frame used once (the TUM tools' rule,
/// [`webfusion_core::io::tum::associate`]); sorted by simulated frame.
fn pair_frames(sim_ns: &[i64], real_ns: &[i64], max_ns: i64) -> Vec<(usize, usize)> {
    webfusion_core::io::tum::associate(sim_ns, real_ns, max_ns.saturating_add(1))
}

pub(crate) fn run(args: &CompareArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.max_difference_ms.is_finite() && args.max_difference_ms > 0.0, "--max-difference-ms must be positive");
    let mut real = crate::open(&args.real, &args.calibration)?;
    let mut sim = crate::open_with(&args.sim, None)?;
    let (rk, sk) = (real.calibration().intrinsics, sim.calibration().intrinsics);
    anyhow::ensure!((rk.width_px, rk.height_px) == (sk.width_px, sk.height_px), "the real frames are {}x{} but the simulated ones {}x{}: simulate at the real camera's size", rk.width_px, rk.height_px, sk.width_px, sk.height_px);
    // Pixels compared must look along the same rays: half a pixel of misalignment anywhere in
    // the image (a focal length off by Δf moves a pixel r px from the centre by r Δf / f).
    let radius_px = f64::from(rk.width_px.max(rk.height_px));
    let misalignment_px = (f64::from((rk.fx_px - sk.fx_px).abs()) * radius_px / f64::from(rk.fx_px)).max(f64::from((rk.fy_px - sk.fy_px).abs()) * radius_px / f64::from(rk.fy_px)) + f64::from((rk.cx_px - sk.cx_px).abs().max((rk.cy_px - sk.cy_px).abs()));
    anyhow::ensure!(
        misalignment_px <= 0.5,
        "the real camera's intrinsics ({}, {}, {}, {}) are not the simulation's ({}, {}, {}, {}): pixels would be compared up to {misalignment_px:.1} px apart; simulate with --intrinsics {},{},{},{}",
        rk.fx_px, rk.fy_px, rk.cx_px, rk.cy_px, sk.fx_px, sk.fy_px, sk.cx_px, sk.cy_px, rk.fx_px, rk.fy_px, rk.cx_px, rk.cy_px
    );
    let real_units = f64::from(real.calibration().depth_units_per_metre);
    let sim_units = f64::from(sim.calibration().depth_units_per_metre);
    // Depth timestamps: read each frame once (a recording's index knows them only by reading).
    let stamps = |s: &mut dyn FrameSource| -> anyhow::Result<Vec<i64>> { (0..s.frame_count()).map(|i| s.frame_timestamp_ns(i).with_context(|| format!("frame {i} of {}", s.name()))).collect() };
    let real_ns = stamps(real.as_mut())?;
    let sim_ns = stamps(sim.as_mut())?;
    let pairs = pair_frames(&sim_ns, &real_ns, (args.max_difference_ms * 1e6) as i64);
    anyhow::ensure!(!pairs.is_empty(), "no simulated frame has a real frame within {} ms ({} simulated, {} real)", args.max_difference_ms, sim_ns.len(), real_ns.len());
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out.join("diff")).with_context(|| format!("creating {}", out.display()))?;
    }
    let mut total = Accumulator::default();
    let mut per_frame = Vec::with_capacity(pairs.len());
    let mut frame_metrics = Vec::with_capacity(pairs.len());
    for &(i, j) in &pairs {
        let a = sim.read_frame(i).with_context(|| format!("simulated frame {i}"))?;
        let b = real.read_frame(j).with_context(|| format!("real frame {j}"))?;
        let m = compare_depth(&a.depth.units, sim_units, &b.depth.units, real_units);
        total.add(&a.depth.units, sim_units, &b.depth.units, real_units);
        if let Some(out) = &args.out {
            let rgb = difference_image(&a.depth.units, sim_units, &b.depth.units, real_units, DIFFERENCE_IMAGE_MAX_MM);
            let image = webfusion_core::ColorImage::new(sk.width_px, sk.height_px, rgb)?;
            let path = out.join("diff").join(format!("{}.png", format_timestamp_s(a.depth_timestamp_ns)));
            std::fs::write(&path, webfusion_core::codec::png::encode_rgb8(&image)?).with_context(|| format!("writing {}", path.display()))?;
        }
        let mut entry = metrics_json(&m);
        entry["sim_timestamp"] = json!(format_timestamp_s(a.depth_timestamp_ns));
        entry["real_timestamp"] = json!(format_timestamp_s(b.depth_timestamp_ns));
        per_frame.push(entry);
        frame_metrics.push(m);
    }
    let overall = total.metrics();
    let bins = total.distance_bins();
    let n = frame_metrics.len() as f64;
    let mean_of = |f: fn(&DepthComparison) -> f64| frame_metrics.iter().map(f).filter(|v| v.is_finite()).sum::<f64>() / n;
    let mut report = metrics_json(&overall);
    report["frames"] = json!(pairs.len());
    report["unpaired_sim_frames"] = json!(sim_ns.len() - pairs.len());
    report["mean_over_frames"] = json!({
        "pixels_rel_error_over_10pct_percent": mean_of(|m| m.pixels_rel_error_over_10pct_percent),
        "new_valid_pixels_percent": mean_of(|m| m.new_valid_pixels_percent),
        "coverage_percent": mean_of(|m| m.coverage_percent),
        "mean_abs_error_mm": mean_of(|m| m.mean_abs_error_mm),
    });
    report["error_vs_distance"] = json!(bins.iter().map(bin_json).collect::<Vec<_>>());
    report["per_frame"] = json!(per_frame);
    report["real"] = json!(args.real.display().to_string());
    report["sim"] = json!(args.sim.display().to_string());
    println!(
        "{} frame pairs: {:.2} % of pixels over 10 % relative error, {:+.1} % new valid pixels, coverage {:.2} %, |A - B| mean {:.1} mm, median {:.1} mm (pixels pooled; per-frame means: {:.2} %, {:+.1} %, {:.2} %)",
        pairs.len(),
        overall.pixels_rel_error_over_10pct_percent,
        overall.new_valid_pixels_percent,
        overall.coverage_percent,
        overall.mean_abs_error_mm,
        overall.median_abs_error_mm,
        mean_of(|m| m.pixels_rel_error_over_10pct_percent),
        mean_of(|m| m.new_valid_pixels_percent),
        mean_of(|m| m.coverage_percent),
    );
    for b in &bins {
        println!("  {:4.2}-{:4.2} m: {:>8} px, mean |e| {:6.1} mm, median e {:+6.1} mm, spread {:5.1} mm, over 10 %: {:5.2} %", b.from_m, b.from_m + webfusion_core::sim::compare::DISTANCE_BIN_M, b.pixels, b.mean_abs_error_mm, b.median_error_mm, b.robust_sigma_mm, b.rel_error_over_10pct_percent);
    }
    let text = serde_json::to_string_pretty(&report)?;
    if let Some(out) = &args.out {
        let mid = |b: &DistanceBin| b.from_m + 0.5 * webfusion_core::sim::compare::DISTANCE_BIN_M;
        let series = [
            crate::plot::Series { label: "MEAN |A-B|", color: [30, 80, 220], points: bins.iter().map(|b| (mid(b), b.mean_abs_error_mm)).collect() },
            crate::plot::Series { label: "SPREAD (1.48 MAD)", color: [20, 160, 60], points: bins.iter().map(|b| (mid(b), b.robust_sigma_mm)).collect() },
            crate::plot::Series { label: "MEDIAN A-B", color: [230, 120, 0], points: bins.iter().map(|b| (mid(b), b.median_error_mm)).collect() },
        ];
        let png = crate::plot::line_chart_png("SIM VS REAL: ERROR BY REAL DEPTH", "REAL DEPTH (M)", "ERROR (MM)", &series)?;
        std::fs::write(out.join("error_vs_distance.png"), png).with_context(|| format!("writing {}", out.join("error_vs_distance.png").display()))?;
        std::fs::write(out.join("compare.json"), &text).with_context(|| format!("writing {}", out.join("compare.json").display()))?;
    }
    if let Some(path) = &args.json {
        std::fs::write(path, &text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_pair_by_nearest_depth_time_once_each() {
        let ms = 1_000_000;
        let sim = [0, 33 * ms, 66 * ms, 500 * ms];
        let real = [ms, 30 * ms, 40 * ms, 70 * ms];
        // 500 ms has no partner; 33 takes 30 (3 ms) over 40 (7 ms).
        assert_eq!(pair_frames(&sim, &real, 20 * ms), vec![(0, 0), (1, 1), (2, 3)]);
        assert!(pair_frames(&sim, &real, ms / 2).is_empty());
        // The bound is inclusive: 33 ms and 30 ms pair at exactly 3 ms.
        assert_eq!(pair_frames(&sim[1..2], &real[1..2], 3 * ms), vec![(0, 0)]);
    }
}
