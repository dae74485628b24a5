// SPDX-License-Identifier: MIT
//! `webfusion eval`: absolute trajectory error (ATE) and relative pose error (RPE) of an
//! estimated trajectory against ground truth, both TUM trajectory files, with the conventions of
//! the TUM benchmark and `evo` (see `webfusion_core::eval`; `scripts/evo_check.sh` compares the
//! numbers with `evo_ape`/`evo_rpe`).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use webfusion_core::eval::{AteOptions, AteReport, DEFAULT_DELTA_FRAMES, ErrorStats, RpeOptions, RpeReport, associate, ate, rpe};
use webfusion_core::io::{TimedPose, format_timestamp_s, read_tum_trajectory};

/// Nanoseconds per millisecond.
const NS_PER_MS: f64 = 1e6;
/// Centimetres per metre, for the second column of the report.
const CM_PER_M: f64 = 100.0;
/// Default `--max-difference-ms`: the TUM benchmark's 20 ms (`associate.py --max_difference 0.02`).
const DEFAULT_MAX_DIFFERENCE_MS: f64 = 20.0;
/// Largest `--max-difference-ms` accepted (one hour): beyond it association is meaningless.
const MAX_MAX_DIFFERENCE_MS: f64 = 3.6e6;

/// Arguments of `webfusion eval`.
#[derive(Clone, Debug, clap::Args)]
pub(crate) struct EvalArgs {
    /// Ground-truth trajectory, TUM format (`timestamp tx ty tz qx qy qz qw`), e.g. a TUM
    /// dataset's groundtruth.txt.
    #[arg(long, value_name = "FILE")]
    pub(crate) gt: PathBuf,

    /// Estimated trajectory, TUM format.
    #[arg(long, value_name = "FILE")]
    pub(crate) est: PathBuf,

    /// Largest |t_gt - t_est| for two poses to be associated, milliseconds (pairs are taken
    /// greedily by smallest difference, each pose once, as the benchmark's associate.py).
    #[arg(long, value_name = "MS", default_value_t = DEFAULT_MAX_DIFFERENCE_MS, value_parser = parse_max_difference_ms)]
    pub(crate) max_difference_ms: f64,

    /// Measure the ATE without first aligning the estimate to the ground truth (Umeyama, SE(3)).
    #[arg(long)]
    pub(crate) no_align: bool,

    /// Correct the scale too: Sim(3) alignment for the ATE (evo's -as; scale only with
    /// --no-align) and scaled estimated translations for the RPE.
    #[arg(long)]
    pub(crate) correct_scale: bool,

    /// RPE pose distance, in associated poses (frames).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_DELTA_FRAMES, value_parser = parse_delta_frames)]
    pub(crate) delta_frames: usize,

    /// RPE over every pair (i, i+N) rather than (0, N), (N, 2N), ... (evo's --all_pairs; the
    /// same for N = 1).
    #[arg(long)]
    pub(crate) all_pairs: bool,

    /// Also write every statistic, per-pair errors and the alignment as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub(crate) json: Option<PathBuf>,
}

fn parse_max_difference_ms(text: &str) -> Result<f64, String> {
    let ms: f64 = text.parse().map_err(|e| format!("{text:?} is not a number of milliseconds: {e}"))?;
    if !(0.0..=MAX_MAX_DIFFERENCE_MS).contains(&ms) {
        return Err(format!("{text} ms is outside 0..={MAX_MAX_DIFFERENCE_MS} ms"));
    }
    Ok(ms)
}

fn parse_delta_frames(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(frames) if frames >= 1 => Ok(frames),
        _ => Err(format!("{text:?} is not a whole number of frames >= 1")),
    }
}

/// Runs `webfusion eval`.
pub(crate) fn run(args: &EvalArgs) -> anyhow::Result<()> {
    let gt = read_trajectory(&args.gt, "ground truth")?;
    let est = read_trajectory(&args.est, "estimate")?;
    // In range: parse_max_difference_ms bounds it to 0..=3.6e12 ns.
    let max_difference_ns = (args.max_difference_ms * NS_PER_MS).round() as u64;
    let delta_frames = args.delta_frames;
    let context = || {
        format!(
            "evaluating estimate {} against ground truth {} (max time difference {} ms)",
            args.est.display(),
            args.gt.display(),
            args.max_difference_ms
        )
    };

    let pairs = associate(&gt, &est, max_difference_ns);
    if pairs.is_empty() {
        bail!(
            "no pose of estimate {} ({}) is within {} ms of one of ground truth {} ({}): wrong files, or clocks that differ?",
            args.est.display(),
            time_span(&est),
            args.max_difference_ms,
            args.gt.display(),
            time_span(&gt),
        );
    }
    let ate_options = AteOptions { max_difference_ns, align: !args.no_align, correct_scale: args.correct_scale };
    let ate_report = ate(&gt, &est, &ate_options).with_context(context)?;
    let rpe_options = RpeOptions { max_difference_ns, delta_frames, all_pairs: args.all_pairs, correct_scale: args.correct_scale };
    let rpe_report = rpe(&gt, &est, &rpe_options).with_context(context)?;

    print_report(args, &gt, &est, &ate_report, &rpe_report)?;
    if let Some(path) = &args.json {
        let json = to_json(args, &gt, &est, &ate_report, &rpe_report);
        let text = serde_json::to_string_pretty(&json).context("serialising the report")?;
        std::fs::write(path, text + "\n").with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn read_trajectory(path: &Path, what: &str) -> anyhow::Result<Vec<TimedPose>> {
    let poses = read_tum_trajectory(path).with_context(|| format!("reading {what} trajectory"))?;
    if poses.is_empty() {
        bail!("{what} trajectory {} has no poses (expected lines `timestamp tx ty tz qx qy qz qw`)", path.display());
    }
    Ok(poses)
}

fn time_span(poses: &[TimedPose]) -> String {
    let first = poses.iter().map(|p| p.timestamp_ns).min().unwrap_or_default();
    let last = poses.iter().map(|p| p.timestamp_ns).max().unwrap_or_default();
    format!("{} poses, t = {} .. {} s", poses.len(), format_timestamp_s(first), format_timestamp_s(last))
}

fn alignment_label(args: &EvalArgs) -> &'static str {
    match (args.no_align, args.correct_scale) {
        (false, false) => "SE(3) Umeyama",
        (false, true) => "Sim(3) Umeyama",
        (true, true) => "scale only",
        (true, false) => "none",
    }
}

/// Prints the report; a closed stdout (`| head`) ends the output quietly instead of panicking.
fn print_report(args: &EvalArgs, gt: &[TimedPose], est: &[TimedPose], ate_report: &AteReport, rpe_report: &RpeReport) -> anyhow::Result<()> {
    let mut out = String::new();
    write_report(&mut out, args, gt, est, ate_report, rpe_report)?;
    use std::io::Write as _;
    match std::io::stdout().lock().write_all(out.as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}

fn write_report(out: &mut String, args: &EvalArgs, gt: &[TimedPose], est: &[TimedPose], ate_report: &AteReport, rpe_report: &RpeReport) -> std::fmt::Result {
    use std::fmt::Write as _;
    writeln!(out, "ground truth: {} ({})", args.gt.display(), time_span(gt))?;
    writeln!(out, "estimate:     {} ({})", args.est.display(), time_span(est))?;
    writeln!(out, "associated:   {} pairs (max time difference {} ms)", ate_report.pairs.len(), args.max_difference_ms)?;
    let alignment = &ate_report.alignment;
    let t = alignment.gt_from_est.translation_m;
    writeln!(
        out,
        "alignment:    {}: gt_from_est rotation {:.4} deg, translation [{:.6}, {:.6}, {:.6}] m, scale {:.6}",
        alignment_label(args),
        alignment.gt_from_est.rotation_angle_rad().to_degrees(),
        t.x,
        t.y,
        t.z,
        alignment.scale
    )?;
    writeln!(out)?;
    writeln!(out, "ATE (translation part, {} pairs)", ate_report.error_m.count)?;
    writeln!(out, "  {:<8} {:>12} {:>12}", "", "m", "cm")?;
    for (name, value_m) in stats_rows(&ate_report.error_m) {
        writeln!(out, "  {name:<8} {value_m:>12.6} {:>12.4}", value_m * CM_PER_M)?;
    }
    writeln!(out)?;
    let pairing = if args.all_pairs { "all pairs" } else { "consecutive" };
    writeln!(out, "RPE (delta {} frame(s), {pairing}, {} relative poses)", args.delta_frames, rpe_report.translation_m.count)?;
    writeln!(out, "  {:<8} {:>12} {:>12} {:>14}", "", "trans m", "trans cm", "rotation deg")?;
    for ((name, value_m), (_, value_deg)) in stats_rows(&rpe_report.translation_m).into_iter().zip(stats_rows(&rpe_report.rotation_deg)) {
        writeln!(out, "  {name:<8} {value_m:>12.6} {:>12.4} {value_deg:>14.6}", value_m * CM_PER_M)?;
    }
    Ok(())
}

fn stats_rows(stats: &ErrorStats) -> [(&'static str, f64); 6] {
    [("rmse", stats.rmse), ("mean", stats.mean), ("median", stats.median), ("std", stats.std), ("min", stats.min), ("max", stats.max)]
}

fn stats_json(stats: &ErrorStats, unit: &str) -> serde_json::Value {
    let mut object = serde_json::Map::new();
    object.insert("count".to_owned(), stats.count.into());
    for (name, value) in stats_rows(stats) {
        object.insert(format!("{name}_{unit}"), value.into());
    }
    object.into()
}

fn to_json(args: &EvalArgs, gt: &[TimedPose], est: &[TimedPose], ate_report: &AteReport, rpe_report: &RpeReport) -> serde_json::Value {
    let alignment = &ate_report.alignment;
    let t = alignment.gt_from_est.translation_m;
    let q = alignment.gt_from_est.rotation;
    let ate_pairs: Vec<serde_json::Value> = ate_report
        .pairs
        .iter()
        .zip(&ate_report.per_pair_error_m)
        .map(|(pair, error_m)| {
            serde_json::json!({
                "gt_timestamp_s": format_timestamp_s(gt[pair.gt_ix].timestamp_ns),
                "est_timestamp_s": format_timestamp_s(est[pair.est_ix].timestamp_ns),
                "error_m": error_m,
            })
        })
        .collect();
    serde_json::json!({
        "gt": args.gt.display().to_string(),
        "est": args.est.display().to_string(),
        "gt_poses": gt.len(),
        "est_poses": est.len(),
        "max_difference_ms": args.max_difference_ms,
        "pairs": ate_report.pairs.len(),
        "ate": {
            "pose_relation": "translation_part",
            "alignment": alignment_label(args),
            "gt_from_est": {
                "translation_m": [t.x, t.y, t.z],
                "rotation_xyzw": [q.x, q.y, q.z, q.w],
                "scale": alignment.scale,
            },
            "stats": stats_json(&ate_report.error_m, "m"),
            "per_pair": ate_pairs,
        },
        "rpe": {
            "delta_frames": args.delta_frames,
            "all_pairs": args.all_pairs,
            "scale": rpe_report.scale,
            "relative_poses": rpe_report.relative_pairs.len(),
            "translation": stats_json(&rpe_report.translation_m, "m"),
            "rotation": stats_json(&rpe_report.rotation_deg, "deg"),
            "per_pair_translation_m": rpe_report.per_pair_translation_m,
            "per_pair_rotation_deg": rpe_report.per_pair_rotation_deg,
        },
    })
}
