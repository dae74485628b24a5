// SPDX-License-Identifier: MIT
//! `webfusion odometry`: seed 002's feature-based visual odometry (`core::odometry`):
//! keypoints, descriptors, matching, RANSAC and the rigid fit on the GPU in one submission per
//! frame; the host reads the estimate back and chains the poses.
//!
//! Each frame is matched against a keyframe and against the previous tracked frame (a second
//! matching and estimate on the GPU), and the two paths to the keyframe are fused by their
//! covariances (`core::odometry::keyframe`); when they disagree the path through the previous
//! frame is kept and the frame becomes the next keyframe, as it does when the keyframe's match
//! fails. `--frame-to-frame` is 002's method: each frame against the previous one only.
//!
//! - `DIR/trajectory.txt`: the camera-to-world pose of every frame at its depth timestamp (TUM
//!   format; the world is the first frame's camera). A frame whose motion against both
//!   references is rejected is matched against the tracked frames before them (the newest
//!   four others, [`RecentFrames`]; the accepted estimate with the most inliers relocalises it
//!   and it becomes the keyframe, counted as `relocalised`). A frame that fails that too keeps
//!   the last tracked pose and the next frame is matched against the same references; after
//!   two rejected in a row, the second becomes the keyframe at that pose (a restart: the
//!   motion missed is lost, counted as `reanchored`).
//! - `DIR/stats.json`: per-stage times (002's: update, detection, description, matching,
//!   estimation, total; median and p95) and per frame the keypoint, match and inlier counts.

use std::collections::VecDeque;
use std::path::PathBuf;

use anyhow::Context as _;
use webfusion_core::{Gpu, GpuOptions};
use webfusion_core::Se3;
use webfusion_core::io::trajectory::{TimedPose, write_tum_trajectory};
use webfusion_core::odometry::gpu::{FeatureExtractor, RELOCALISATION_CANDIDATES, STAGES};
use webfusion_core::odometry::keyframe::{Disagreement, Fused, UncertainPose, fuse};
use webfusion_core::odometry::matching::MatchConfig;
use webfusion_core::odometry::tracker::OdometryConfig;
use webfusion_core::odometry::FeatureConfig;
use webfusion_core::preprocess::{DepthPreprocessor, PreprocessConfig};

use crate::calib::CalibrationArgs;
use crate::timing::{StageTimes, Stopwatch, summarize};

#[derive(clap::Args)]
pub(crate) struct OdometryArgs {
    /// TUM RGB-D directory or `.wfr` recording.
    #[arg(default_value = crate::DEFAULT_SAMPLE)]
    source: PathBuf,
    /// Output directory (created; `trajectory.txt` in it must not exist yet).
    #[arg(long)]
    out: PathBuf,
    /// Frames to track, `A..B` (end exclusive); default all.
    #[arg(long)]
    frames: Option<String>,
    /// Keep only every N-th frame of the range (fast motion as a slower camera would see it).
    #[arg(long, default_value_t = 1)]
    every: usize,
    /// Leave out the frames `A..B` (a gap in the stream).
    #[arg(long)]
    drop: Option<String>,
    #[command(flatten)]
    calibration: CalibrationArgs,
    /// Keypoints wanted per frame.
    #[arg(long, default_value_t = FeatureConfig::default().target_keypoints)]
    keypoints: u32,
    /// Lowe's ratio for the match filter.
    #[arg(long, default_value_t = MatchConfig::default().ratio)]
    ratio: f32,
    /// Keep matches that are not mutual nearest neighbours.
    #[arg(long)]
    no_mutual: bool,
    /// Seed 002's "outstanding" filter: second-nearest − nearest ≥ this many bits (002's 100
    /// L2 on SIFT is about 28 bits here).
    #[arg(long)]
    margin_bits: Option<u32>,
    /// Seed 002's keep-best fraction of the matches (002: 0.2).
    #[arg(long)]
    keep_best: Option<f32>,
    /// Match each frame against the previous tracked frame only (seed 002's odometry) instead
    /// of against a keyframe and the previous frame, fused.
    #[arg(long)]
    frame_to_frame: bool,
    /// Also start a new keyframe when the keyframe's inliers fall below this fraction of those
    /// its first tracked frame had; 0: only when its estimate fails or disagrees with the
    /// path through the previous frame.
    #[arg(long, default_value_t = 0.0)]
    keyframe_overlap: f64,
    /// Skip damaged frames of a recording (counted) instead of stopping at the first.
    #[arg(long)]
    skip_corrupt: bool,
}

/// Consecutive rejected frames (relocalisation included) after which the last one becomes the
/// reference, at the last tracked pose: one bad frame (blur) is skipped and the next is matched
/// to the same references; two in a row mean the stream has moved on.
const REANCHOR_AFTER: usize = 2;

/// The keyframe frames are matched against: its source index and camera-to-world pose, the
/// previous tracked frame relative to it with that relative pose's covariance (their features
/// stay on the GPU), and the inliers of its first tracked frame (for `--keyframe-overlap`).
struct Keyframe {
    index: usize,
    world_from_keyframe: Se3,
    from_previous: UncertainPose,
    first_inliers: Option<usize>,
}

impl Keyframe {
    /// Frame `index`, at `world_from_keyframe`, as the new keyframe.
    fn at(index: usize, world_from_keyframe: Se3) -> Self {
        Self { index, world_from_keyframe, from_previous: UncertainPose::exact(Se3::IDENTITY), first_inliers: None }
    }
}

/// Tracked frames whose features are kept for relocalisation: the candidates of one
/// submission ([`RELOCALISATION_CANDIDATES`]) besides the keyframe and the previous frame,
/// which the rejected estimates already tried.
const RECENT_FRAMES: usize = RELOCALISATION_CANDIDATES + 2;

/// The newest tracked frames, each in its own keyframe slot of the extractor
/// ([`FeatureExtractor::store_keyframe`]), for relocalising a frame that neither the keyframe
/// nor the previous frame could be matched to: a reference that is itself poor (motion blur,
/// few keypoints) is the usual cause, and the frames tracked just before it saw the same view.
#[derive(Default)]
struct RecentFrames {
    /// (keyframe slot, source frame index, camera-to-world pose), oldest first.
    frames: VecDeque<(usize, usize, Se3)>,
}

impl RecentFrames {
    /// The source index of the newest frame kept (the previous tracked frame).
    fn newest(&self) -> Option<usize> {
        self.frames.back().map(|f| f.1)
    }

    /// Keeps the last processed frame (source `index`, at `world_from_camera`), in place of the
    /// oldest once full.
    fn remember(&mut self, gpu: &Gpu, extractor: &mut FeatureExtractor, index: usize, world_from_camera: Se3) -> anyhow::Result<()> {
        let slot = match self.frames.len() {
            n if n < RECENT_FRAMES => n,
            _ => self.frames.pop_front().map(|f| f.0).context("a full store has an oldest frame")?,
        };
        extractor.store_keyframe(gpu, slot)?;
        self.frames.push_back((slot, index, world_from_camera));
        Ok(())
    }

    /// Matches the last processed frame (of `keypoints` keypoints) against the newest kept
    /// frames other than `tried`, in one submission, and returns the accepted estimate with the
    /// most RANSAC inliers: (camera-to-world pose, the frame it came from, inliers).
    async fn relocalise(&self, gpu: &Gpu, extractor: &mut FeatureExtractor, tried: &[Option<usize>], keypoints: usize, seed: u32) -> anyhow::Result<Option<(Se3, usize, usize)>> {
        let candidates: Vec<(usize, usize, Se3)> = self.frames.iter().rev().filter(|f| !tried.contains(&Some(f.1))).take(RELOCALISATION_CANDIDATES).copied().collect();
        if candidates.is_empty() {
            return Ok(None);
        }
        let slots: Vec<usize> = candidates.iter().map(|f| f.0).collect();
        let estimates = extractor.match_keyframes(gpu, &slots, keypoints, seed).await?;
        Ok(candidates.iter().zip(estimates).filter_map(|(&(_, frame, world_from_ref), e)| Some((world_from_ref.compose(&e.reference_from_current()?), frame, e.inliers()))).max_by_key(|c| c.2))
    }
}

/// `A..B` as a range (end exclusive).
pub(crate) fn parse_range(spec: &str, what: &str) -> anyhow::Result<std::ops::Range<usize>> {
    let (a, b) = spec.split_once("..").with_context(|| format!("{what} {spec:?}: expected A..B"))?;
    let start: usize = a.parse().with_context(|| format!("{what} start {a:?}"))?;
    let end: usize = b.parse().with_context(|| format!("{what} end {b:?}"))?;
    anyhow::ensure!(start < end, "{what} {spec}: empty");
    Ok(start..end)
}

pub(crate) fn run(options: &GpuOptions, args: &OdometryArgs) -> anyhow::Result<()> {
    anyhow::ensure!((0.0..1.0).contains(&args.keyframe_overlap), "--keyframe-overlap must be in [0, 1), got {}", args.keyframe_overlap);
    let config = OdometryConfig {
        features: FeatureConfig { target_keypoints: args.keypoints, ..FeatureConfig::default() },
        matching: MatchConfig { ratio: args.ratio, mutual: !args.no_mutual, margin_bits: args.margin_bits, keep_best_fraction: args.keep_best, ..MatchConfig::default() },
        ..OdometryConfig::default()
    };
    config.validate()?;
    let mut source = crate::open(&args.source, &args.calibration)?;
    let frames = crate::selected_frames(crate::frame_range(args.frames.as_deref(), source.frame_count())?, args.every, args.drop.as_deref())?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let trajectory_path = args.out.join("trajectory.txt");
    anyhow::ensure!(!trajectory_path.exists(), "{} exists: choose another --out", trajectory_path.display());
    let gpu = crate::gpu(options)?;
    let calibration = source.calibration();
    // Odometry reads the intensity pyramid and the raw metric depth, not the filtered depth
    // pyramid or the vertex and normal maps: only the image stages run (`images_only`).
    let preprocessor = DepthPreprocessor::new(&gpu, calibration, PreprocessConfig { gradient_smoothing: None, ..PreprocessConfig::default() })?;
    let mut extractor = FeatureExtractor::new(&gpu, &preprocessor, config)?.images_only();
    if !args.frame_to_frame {
        // Keyframe odometry's second path, through the previous tracked frame, is matched and
        // estimated in each frame's own submission.
        extractor = extractor.matching_previous();
    }
    // None before the first frame.
    let mut keyframe: Option<Keyframe> = None;
    let mut recent = RecentFrames::default();
    let mut trajectory = Vec::new();
    let mut times = StageTimes::default();
    let mut frames_json = Vec::new();
    let mut skipped = Vec::new();
    let (mut tracked, mut lost, mut via_previous, mut reanchored, mut fused, mut disagreed, mut relocalisations) = (0usize, 0usize, 0usize, 0usize, 0usize, 0usize, 0usize);
    let mut consecutive_rejected = 0usize;
    let (mut keypoint_counts, mut match_counts, mut inlier_counts) = (Vec::new(), Vec::new(), Vec::new());
    // χ² of the two paths of every fused frame (χ²(6) when the covariances are right).
    let mut fused_chi2: Vec<f64> = Vec::new();
    for index in frames {
        let Some(frame) = crate::read_or_skip(source.as_mut(), index, args.skip_corrupt, &mut skipped)? else { continue };
        let total = Stopwatch::start();
        let seed = index as u32;
        let result = pollster::block_on(extractor.process(&gpu, &preprocessor, &frame, seed)).with_context(|| format!("features of frame {index}"))?;
        let keypoints = result.features.keypoint_count();
        let mut entry = serde_json::json!({ "index": index, "keypoints": keypoints });
        let pose = match keyframe.as_mut() {
            Some(kf) => {
                let direct = result.motion.clone().context("the extractor holds a reference, so it estimated a motion")?;
                // With keyframes, the path through the previous tracked frame too (none while
                // the keyframe is the previous frame; frame to frame, the reference is always
                // the previous frame).
                let through_previous = result.motion_previous.clone().filter(|e| e.rigid.is_some());
                let reported = if direct.rigid.is_some() { &direct } else { through_previous.as_ref().unwrap_or(&direct) };
                entry["matches"] = reported.matches.into();
                entry["inliers"] = reported.inliers().into();
                entry["rmse_mm"] = reported.rigid.as_ref().map(|r| r.rmse_m * 1e3).into();
                entry["noise_scale"] = reported.rigid.as_ref().map(|r| r.noise_scale).into();
                entry["tracked"] = reported.rigid.is_some().into();
                match_counts.push(reported.matches as f64);
                inlier_counts.push(reported.inliers() as f64);
                // The current camera relative to the keyframe: directly, and through the
                // previous frame (with its covariance grown by the chain's when the step has
                // one).
                let kf_direct = direct.rigid.as_ref().map(|r| (r.dst_from_src, r.covariance));
                let kf_chained = through_previous.as_ref().and_then(|e| e.rigid.as_ref()).map(|r| {
                    entry["inliers_previous"] = r.inliers.len().into();
                    let uncertain = r.covariance.map(|covariance| kf.from_previous.then(&UncertainPose { pose: r.dst_from_src, covariance }));
                    (kf.from_previous.pose.compose(&r.dst_from_src), uncertain)
                });
                // keyframe_from_current, with its covariance when the keyframe is kept (`None`:
                // the current frame becomes the next keyframe), and what it came from.
                let outcome = match (kf_direct, kf_chained) {
                    (Some((pose, Some(covariance))), Some((_, Some(chained)))) => match fuse(&UncertainPose { pose, covariance }, &chained) {
                        Ok(Fused { pose: f, chi2 }) => {
                            fused += 1;
                            entry["chi2"] = chi2.into();
                            fused_chi2.push(chi2);
                            Some((f.pose, Some(f), "fused"))
                        }
                        Err(Disagreement { chi2 }) => {
                            // One of them is wrong: the shorter baseline is kept.
                            disagreed += 1;
                            entry["chi2"] = chi2.into();
                            Some((chained.pose, None, "previous (disagreed)"))
                        }
                    },
                    (Some((pose, covariance)), _) => Some((pose, covariance.map(|covariance| UncertainPose { pose, covariance }), "keyframe")),
                    (None, Some((chained, _))) => {
                        via_previous += 1;
                        Some((chained, None, "previous"))
                    }
                    (None, None) => None,
                };
                match outcome {
                    Some((kf_from_cur, keep, against)) => {
                        tracked += 1;
                        consecutive_rejected = 0;
                        entry["against"] = against.into();
                        let first = *kf.first_inliers.get_or_insert(direct.inliers());
                        let renew = args.frame_to_frame || (direct.inliers() as f64) < args.keyframe_overlap * first as f64;
                        let keep = keep.filter(|_| !renew);
                        extractor.accept(keep.is_none());
                        let pose = kf.world_from_keyframe.compose(&kf_from_cur);
                        match keep {
                            Some(kf_from_cur) => kf.from_previous = kf_from_cur,
                            None => *kf = Keyframe::at(index, pose),
                        }
                        recent.remember(&gpu, &mut extractor, index, pose)?;
                        pose
                    }
                    None => {
                        let last_tracked = kf.world_from_keyframe.compose(&kf.from_previous.pose);
                        // Neither the keyframe nor the previous frame: the recent tracked
                        // frames before them (a blurred reference is the usual cause).
                        let tried = [Some(kf.index), recent.newest()];
                        let relocalise = Stopwatch::start();
                        let relocalised = pollster::block_on(recent.relocalise(&gpu, &mut extractor, &tried, keypoints, seed))?;
                        times.record("relocalise (wall)", relocalise.ms());
                        match relocalised {
                            Some((pose, from_frame, inliers)) => {
                                tracked += 1;
                                relocalisations += 1;
                                consecutive_rejected = 0;
                                entry["tracked"] = true.into();
                                entry["against"] = "recent".into();
                                entry["relocalised"] = serde_json::json!({ "frame": from_frame, "inliers": inliers });
                                extractor.accept(true);
                                *kf = Keyframe::at(index, pose);
                                recent.remember(&gpu, &mut extractor, index, pose)?;
                                pose
                            }
                            None => {
                                entry["tracked"] = false.into();
                                lost += 1;
                                consecutive_rejected += 1;
                                if consecutive_rejected >= REANCHOR_AFTER {
                                    // The stream has moved on from the reference (a gap, a cut):
                                    // restart from this frame at the last pose; the motion
                                    // missed is lost.
                                    extractor.accept(true);
                                    *kf = Keyframe::at(index, last_tracked);
                                    consecutive_rejected = 0;
                                    reanchored += 1;
                                    entry["reanchored"] = true.into();
                                    recent.remember(&gpu, &mut extractor, index, last_tracked)?;
                                }
                                last_tracked
                            }
                        }
                    }
                }
            }
            None => {
                extractor.accept(true);
                keyframe = Some(Keyframe::at(index, Se3::IDENTITY));
                recent.remember(&gpu, &mut extractor, index, Se3::IDENTITY)?;
                Se3::IDENTITY
            }
        };
        keypoint_counts.push(keypoints as f64);
        match result.gpu_ms {
            Some(ms) => STAGES.iter().zip(ms).for_each(|(name, ms)| times.record(name, ms)),
            // Without timestamp queries only the whole submission can be timed.
            None => times.record("update..estimation (wall)", result.wall_ms),
        }
        times.record("total", total.ms());
        trajectory.push(TimedPose { timestamp_ns: frame.depth_timestamp_ns, world_from_camera: pose });
        frames_json.push(entry);
        eprint!("\rframe {index}: {keypoints} keypoints, {tracked} tracked, {lost} rejected   ");
    }
    eprintln!();
    anyhow::ensure!(!trajectory.is_empty(), "no frame of {} was read", source.name());
    write_tum_trajectory(&trajectory_path, &trajectory)?;
    let median = |v: &[f64]| if v.is_empty() { 0.0 } else { summarize(v).median_ms };
    let stats = serde_json::json!({
        "source": source.name(),
        "frames": trajectory.len(),
        "tracked": tracked,
        "rejected": lost,
        "tracked_against_previous": via_previous,
        "reanchored": reanchored,
        "relocalised": relocalisations,
        "fused": fused,
        "disagreed": disagreed,
        "fused_chi2_mean": (!fused_chi2.is_empty()).then(|| fused_chi2.iter().sum::<f64>() / fused_chi2.len() as f64),
        "frame_to_frame": args.frame_to_frame,
        "keyframe_overlap": args.keyframe_overlap,
        "every": args.every,
        "gpu_timestamps": gpu.has_timestamps,
        "stages_ms": times.to_json(),
        "median_keypoints": median(&keypoint_counts),
        "median_matches": median(&match_counts),
        "median_inliers": median(&inlier_counts),
        "slots": extractor.slots(),
        "per_frame": frames_json,
    });
    let stats_path = args.out.join("stats.json");
    std::fs::write(&stats_path, serde_json::to_string_pretty(&stats)?).with_context(|| format!("writing {}", stats_path.display()))?;
    times.print();
    println!(
        "{} frames: {tracked} tracked ({relocalisations} relocalised), {lost} rejected ({reanchored} restarts); median {:.0} keypoints, {:.0} matches, {:.0} inliers{}",
        trajectory.len(),
        median(&keypoint_counts),
        median(&match_counts),
        median(&inlier_counts),
        crate::skipped_note(&skipped)
    );
    println!("wrote {} and {}", trajectory_path.display(), stats_path.display());
    Ok(())
}
