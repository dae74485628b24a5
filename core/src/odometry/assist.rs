// SPDX-License-Identifier: MIT
//! Feature odometry beside a dense tracker (ICP): each frame's initial guess from its features
//! matched against the last frame the dense tracker accepted, and relocalisation against
//! stored keyframes once tracking is lost.
//!
//! [`FeatureAssist::process_frame`] takes a frame through both trackers:
//!
//! - **tracking**: one submission with no host wait inside it. The feature pass is recorded
//!   into the dense frame after the shared preprocessing
//!   ([`KinectFusion::submit_frame_with`]); its motion against the last accepted frame, when
//!   RANSAC accepts it, becomes the dense tracker's starting pose on the GPU (`feature_guess`:
//!   a [`Guess::Motion`]) instead of its motion model. The host reads the frame's report and
//!   its features after the submission. A motion beyond the dense tracker's plausible
//!   inter-frame jump ([`FeatureAssist::set_jump_limits`]) makes ICP's jump check reject the
//!   frame; the host then proposes that motion as a relocalisation (below) and tracks the
//!   frame again from there (a second submission, for a rare frame).
//! - **lost** (the host knows it from the last frame's report): the frame is matched against the last accepted frame and against up to
//!   [`RELOCALISATION_CANDIDATES`] stored keyframes (nearest to the last good pose first, the
//!   next ones on the next lost frame, so a long loss cycles through the whole store); the
//!   candidate with the most RANSAC inliers (at least `min_inliers`) is a
//!   [`Guess::Relocalised`]: the dense tracker re-renders its model at that pose and tracks
//!   the frame from there. Choosing among the candidates needs their estimates on the host,
//!   so a lost frame's features are a submission of their own, waited for. The relocalisation
//!   stands only when the dense tracker then tracks the frame (its own inlier, conditioning
//!   and jump checks, the jump now measured from the relocalised pose); otherwise the tracker
//!   is reseeded back at the last good pose, so a false relocalisation leaves nothing behind.
//!
//! - **after a gap** (more than [`MAX_UNSEEDED_GAP_S`] since the last accepted frame: frames
//!   dropped, a stalled stream, a long loss): the frame goes the lost way, features first, and
//!   is tracked only from a feature pose that ICP then confirms. Without one it is not
//!   submitted at all: Lost ([`LostReason::Unverified`]), nothing tracked, nothing fused. ICP
//!   from the last pose is what a frame 1/30 s later needs, and its jump check is what tells
//!   its true fits from false ones; after a gap the camera may have moved further than the
//!   check's limits, and ICP can converge to a false fit within them (fr3_teddy with frames
//!   30..70 dropped was "tracked" 28 cm off).
//!
//! A tracked frame becomes a keyframe when no stored keyframe lies within
//! [`KEYFRAME_SPACING_M`] and [`KEYFRAME_SPACING_RAD`] of it. The spacing keeps every view of
//! the covered region within half of it (5 cm, 5°) of a keyframe, well inside the viewpoint
//! change binary descriptors tolerate (rotated BRIEF holds its matches to about 30°; Rublee et
//! al. 2011), while a camera sweeping a room adds one every few frames, not every frame. The
//! store holds [`KEYFRAME_CAPACITY`]; when full, the most redundant keyframe (the one whose
//! nearest other keyframe is closest) gives way, so the store keeps its spread over the room.

use super::gpu::{ESTIMATE_BYTES, FeatureExtractor, RELOCALISATION_CANDIDATES};
use super::tracker::{MotionEstimate, OdometryConfig};
use super::Features;
use crate::fusion::{FrameReport, KinectFusion, LostReason, PassSummary, TrackingState};
use crate::kernels::feature_guess::{self, FeatureGuessParams, RigidEstimate};
use crate::preprocess::DepthPreprocessor;
use crate::{Error, Gpu, GpuCounts, Result, RgbdFrame, Se3};

/// Translation between keyframes, metres.
pub const KEYFRAME_SPACING_M: f64 = 0.10;
/// Rotation between keyframes, radians (10°).
pub const KEYFRAME_SPACING_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;
/// Keyframes kept (each holds one frame's keypoint slots on the GPU: about 58 KB at 640×480).
pub const KEYFRAME_CAPACITY: usize = 64;
/// Longest time since the last accepted frame after which the dense tracker may still start
/// from that frame's pose without a feature pose, seconds. ICP's jump check (its result within
/// 20 cm and 25° of the last pose, [`crate::fusion::DEFAULT_MAX_JUMP_M`] and
/// [`crate::fusion::DEFAULT_MAX_JUMP_RAD`]) is what tells a true fit from a false one that
/// converged elsewhere; a hand-held camera at typical speeds (the TUM RGB-D benchmark's fr1
/// sequences: 0.2-0.4 m/s, 25-50°/s) covers those limits in about half a second, after which
/// the check no longer separates them. Frames a stream drops now and then (every 3rd kept:
/// 0.1 s; ten in a row: 0.37 s) stay within it.
pub const MAX_UNSEEDED_GAP_S: f64 = 0.5;

/// A feature-based starting pose for the dense tracker.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Guess {
    /// The frame's camera-to-world pose from its motion against the last accepted frame: start
    /// tracking there.
    Motion(Se3),
    /// After a loss, the frame's camera-to-world pose from a stored keyframe (or the last
    /// accepted frame): reseed the tracker there and verify.
    Relocalised {
        /// The camera-to-world pose.
        world_from_camera: Se3,
        /// The source frame index of the keyframe it came from.
        keyframe: u64,
        /// RANSAC inliers against it.
        inliers: usize,
    },
}

/// One frame taken through both trackers by [`FeatureAssist::process_frame`].
#[derive(Clone, Debug, PartialEq)]
pub struct AssistedFrame {
    /// The dense tracker's report of the frame.
    pub report: FrameReport,
    /// The feature guess it was tracked from (`None`: the dense tracker's own motion model).
    pub guess: Option<Guess>,
    /// What the frame asked of the GPU: while tracking one submission and one wait (for the
    /// report, after the submission); more for a relocalisation.
    pub host: GpuCounts,
}

/// Counts over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AssistStats {
    /// Frames given a motion guess.
    pub guesses: usize,
    /// Relocalisations proposed after a loss.
    pub relocalisations: usize,
    /// Of those, the ones the dense tracker confirmed.
    pub relocalisations_confirmed: usize,
    /// Lost frames followed by a tracked one that had a feature guess.
    pub recoveries: usize,
    /// Keyframes added (including the ones that replaced others).
    pub keyframes_added: usize,
    /// Frames more than [`MAX_UNSEEDED_GAP_S`] after the last accepted one that no feature
    /// pose placed: lost without tracking ([`LostReason::Unverified`]).
    pub withheld: usize,
}

/// A frame the dense tracker accepted (the reference, or a keyframe): its features, pose,
/// source index and depth timestamp.
struct Keyframe {
    features: Features,
    world_from_camera: Se3,
    frame: u64,
    timestamp_ns: i64,
}

/// Feature odometry as the dense tracker's assistant.
pub struct FeatureAssist {
    extractor: FeatureExtractor,
    /// The last accepted frame.
    reference: Option<Keyframe>,
    keyframes: Vec<Keyframe>,
    lost_streak: usize,
    /// The dense tracker's largest plausible inter-frame motion (metres, radians).
    jump_limits: Option<(f64, f64)>,
    stats: AssistStats,
    /// Host milliseconds of each frame through [`Self::process_frame`] (features and dense
    /// tracking together: while tracking they are one submission).
    ms: Vec<f64>,
    /// The last frame against the last accepted one, for display.
    last_pair: Option<PairView>,
    /// `feature_guess`'s parameters.
    guess_params: wgpu::Buffer,
    /// Read each tracked frame's keypoints and matches back for [`Self::last_pair`].
    pair_view: bool,
}

/// One frame matched against the last accepted frame, as seed 002's step-by-step view shows it:
/// both frames' keypoints, the matches the filters kept, which of them RANSAC took as inliers,
/// and the time of each stage.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PairView {
    /// The current frame's source index.
    pub frame: u64,
    /// The reference (last accepted) frame's source index.
    pub reference_frame: u64,
    /// The current frame's keypoints: (x, y in full-resolution pixels, orientation radians,
    /// pyramid level).
    pub current: Vec<[f32; 4]>,
    /// The reference frame's keypoints, likewise.
    pub reference: Vec<[f32; 4]>,
    /// Kept matches: (index into `current`, index into `reference`, RANSAC inlier).
    pub matches: Vec<(u32, u32, bool)>,
    /// Milliseconds of [`PAIR_STAGES`] (GPU timestamps; NaN without them).
    pub stages_ms: [f64; 5],
}

/// The stages of a [`PairView`], seed 002's: the feature submission's ([`super::gpu::STAGES`]).
pub const PAIR_STAGES: [&str; 5] = super::gpu::STAGES;

impl PairView {
    fn new(frame: u64, reference_frame: u64, current: &Features, reference: &Features, estimate: &MotionEstimate, stages_ms: [f64; 5]) -> Self {
        // Slot → position among the frame's keypoints.
        let compact = |f: &Features| {
            let mut position = vec![u32::MAX; f.slots()];
            let mut kept = Vec::new();
            for slot in (0..f.slots()).filter(|&i| f.is_keypoint(i)) {
                position[slot] = kept.len() as u32;
                kept.push(f.features[slot]);
            }
            (position, kept)
        };
        let ((cur_at, cur), (ref_at, refs)) = (compact(current), compact(reference));
        let inliers: std::collections::HashSet<usize> = estimate.rigid.as_ref().map(|r| r.inliers.iter().copied().collect()).unwrap_or_default();
        let matches = estimate
            .matched
            .iter()
            .enumerate()
            .filter_map(|(i, m)| {
                // A frame kept without its keypoints (read back only with the pair view) has none.
                let (q, t) = (*cur_at.get(m.query as usize)?, *ref_at.get(m.train as usize)?);
                (q != u32::MAX && t != u32::MAX).then_some((q, t, inliers.contains(&i)))
            })
            .collect();
        Self { frame, reference_frame, current: cur, reference: refs, matches, stages_ms }
    }
}

impl std::fmt::Debug for FeatureAssist {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FeatureAssist").field("keyframes", &self.keyframes.len()).field("lost_streak", &self.lost_streak).field("stats", &self.stats).finish_non_exhaustive()
    }
}

/// Distance between two poses for ranking keyframes: metres plus radians at 1 m.
fn pose_distance(a: &Se3, b: &Se3) -> f64 {
    let d = a.inverse().compose(b);
    d.translation_m.length() + d.rotation_angle_rad()
}

fn within_spacing(a: &Se3, b: &Se3) -> bool {
    let d = a.inverse().compose(b);
    d.translation_m.length() < KEYFRAME_SPACING_M && d.rotation_angle_rad() < KEYFRAME_SPACING_RAD
}

impl FeatureAssist {
    /// Feature odometry reading `preprocessor` (the dense pipeline's: the feature pass uploads
    /// and preprocesses each frame, and the dense pipeline then skips both).
    pub fn new(gpu: &Gpu, preprocessor: &DepthPreprocessor, config: OdometryConfig) -> Result<Self> {
        let guess_params = gpu.uniform_buffer("core.assist.guess_params", &FeatureGuessParams { min_inliers: config.ransac.min_inliers as u32, ..Default::default() });
        let extractor = FeatureExtractor::new(gpu, preprocessor, config)?;
        Ok(Self { extractor, reference: None, keyframes: Vec::new(), lost_streak: 0, jump_limits: None, stats: AssistStats::default(), ms: Vec::new(), last_pair: None, guess_params, pair_view: false })
    }

    /// The dense tracker's largest plausible inter-frame translation and rotation: a feature
    /// motion beyond either is proposed as a relocalisation (a reseed), not a guess the jump
    /// check would reject.
    pub fn set_jump_limits(&mut self, max_m: f64, max_rad: f64) {
        self.jump_limits = Some((max_m, max_rad));
    }

    /// Forgets the reference, the keyframes and the counts (the dense tracker was reset: a new
    /// world frame). The keyframes' GPU buffers are kept for reuse.
    pub fn reset(&mut self) {
        self.extractor.reset();
        self.reference = None;
        self.keyframes.clear();
        self.lost_streak = 0;
        self.stats = AssistStats::default();
        self.ms.clear();
        self.last_pair = None;
    }

    /// The counts so far.
    pub fn stats(&self) -> AssistStats {
        self.stats
    }

    /// Host milliseconds of each frame through [`Self::process_frame`], features and dense
    /// tracking together (while tracking they share one submission; per-stage GPU times are in
    /// the report's [`crate::fusion::StageTimesMs::features`]).
    pub fn frame_ms(&self) -> &[f64] {
        &self.ms
    }

    /// Whether tracked frames read their keypoints and matches back (about 160 KB a frame at
    /// 640×480) for [`Self::last_pair`]; off, a tracked frame reads back only the estimate,
    /// with the dense frame's report. Off by default.
    pub fn keep_pair_view(&mut self, on: bool) {
        self.pair_view = on;
    }

    /// The last frame matched against the last accepted one (`None` before the second frame,
    /// and while tracking without [`Self::keep_pair_view`]).
    pub fn last_pair(&self) -> Option<&PairView> {
        self.last_pair.as_ref()
    }

    /// Keyframes held.
    pub fn keyframes(&self) -> usize {
        self.keyframes.len()
    }

    /// Takes `frame` through both trackers (see the module docs): features and dense tracking in
    /// one submission while tracking, relocalisation after a loss; then the frame's outcome
    /// updates the reference and the keyframes. Waits for the frame's report.
    pub async fn process_frame(&mut self, gpu: &Gpu, fusion: &mut KinectFusion, frame: &RgbdFrame) -> Result<AssistedFrame> {
        let started = web_time::Instant::now();
        let before = gpu.counters.snapshot();
        // Seconds since the last accepted frame, when beyond what ICP alone may bridge. A clock
        // that jumped back as far (a splice, a replay that looped) is a gap too: nothing says
        // the camera moved continuously.
        let gap_s = self.reference.as_ref().map(|r| (frame.depth_timestamp_ns - r.timestamp_ns) as f64 * 1e-9).filter(|g| g.abs() > MAX_UNSEEDED_GAP_S);
        let (mut assisted, features) =
            if self.lost_streak == 0 && gap_s.is_none() { self.track(gpu, fusion, frame).await? } else { self.recover(gpu, fusion, frame, gap_s).await? };
        assisted.host = gpu.counters.snapshot() - before;
        if self.lost_streak > 0 && assisted.report.state == TrackingState::Tracked {
            // The frames lost before it were withheld (never submitted): the dense tracker saw
            // no loss, but the stream did.
            assisted.report.state = TrackingState::Recovered;
        }
        self.verdict(gpu, fusion, features, assisted.guess, &assisted.report, frame.depth_timestamp_ns)?;
        self.ms.push(started.elapsed().as_secs_f64() * 1e3);
        Ok(assisted)
    }

    /// A frame while tracking: the feature pass, `feature_guess` and the dense frame in one
    /// submission, the estimate read back with the frame's report ([`PassSummary`]); a motion
    /// beyond the jump limits that ICP lost is relocalised and tracked again. Returns the frame
    /// and its features (read back only with the pair view).
    async fn track(&mut self, gpu: &Gpu, fusion: &mut KinectFusion, frame: &RgbdFrame) -> Result<(AssistedFrame, Features)> {
        let started = web_time::Instant::now();
        self.extractor.begin(gpu, frame.index as u32);
        let with_reference = self.reference.is_some();
        let guess_bindings = with_reference.then(|| feature_guess::Bindings { params: &self.guess_params, estimate: self.extractor.estimate_buffer(), state: fusion.tracker().state_buffer() }.bind_group(gpu));
        let (extractor, pair_view) = (&self.extractor, self.pair_view);
        let mut slot = Ok(None);
        let submission = fusion
            .submit_frame_with(gpu, frame, &mut |fe, summary: &PassSummary<'_>| {
                if pair_view {
                    slot = extractor.encode_frame(gpu, fe).map(Some);
                } else {
                    extractor.encode_features(gpu, fe);
                }
                if let Some(bindings) = &guess_bindings {
                    gpu.kernels.feature_guess.dispatch_in(&mut fe.stage("estimation"), bindings, [1, 1, 1]);
                }
                summary.copy_from(fe.encoder(), extractor.estimate_buffer(), ESTIMATE_BYTES);
            })
            .await?;
        if let Some(slot) = slot? {
            self.extractor.frame_submitted(gpu, slot, submission, None, started);
        }
        let mut report = report_of(gpu, fusion, frame.index).await?;
        let summary = report.pass_summary.get(..ESTIMATE_BYTES as usize).ok_or_else(|| Error::Poll(format!("frame {}: its report carries no feature estimate", frame.index)))?;
        let estimate: RigidEstimate = bytemuck::pod_read_unaligned(summary);
        let result = if pair_view { Some(self.extractor.finish_frame(gpu).await?) } else { None };
        if let (Some(result), Some(reference)) = (&result, &self.reference) {
            let stages_ms = report.gpu_ms.map_or([f64::NAN; 5], |t| [t.preprocess, t.features[0], t.features[1], t.features[2], t.features[3]]);
            self.last_pair = result.motion.as_ref().map(|m| PairView::new(frame.index, reference.frame, &result.features, &reference.features, m, stages_ms));
        }
        let accepted = (with_reference && estimate.accepted == 1).then(|| (Se3::from_cols_f32(&estimate.dst_from_src), estimate.inliers as usize));
        let mut guess = accepted.and_then(|(ref_from_cur, inliers)| self.candidate(ref_from_cur, inliers)).map(|(world_from_camera, keyframe, inliers, beyond)| {
            if beyond { Guess::Relocalised { world_from_camera, keyframe, inliers } } else { Guess::Motion(world_from_camera) }
        });
        match guess {
            Some(Guess::Relocalised { world_from_camera, .. }) if report.state.is_lost() => {
                // ICP started at the motion and its jump check rejected it: track the frame
                // again from the relocalised pose, where the check measures from.
                fusion.reseed(gpu, &world_from_camera)?;
                fusion.submit_preprocessed_frame(gpu, frame).await?;
                report = report_of(gpu, fusion, frame.index).await?;
                self.stats.relocalisations += 1;
            }
            Some(Guess::Relocalised { world_from_camera, .. }) => {
                // Tracked from the motion after all: it was a guess.
                guess = Some(Guess::Motion(world_from_camera));
                self.stats.guesses += 1;
            }
            Some(Guess::Motion(_)) => self.stats.guesses += 1,
            None => {}
        }
        Ok((AssistedFrame { report, guess, host: GpuCounts::default() }, result.map(|r| r.features).unwrap_or_default()))
    }

    /// A motion `ref_from_cur` (with `inliers` RANSAC inliers) against the reference, as a pose:
    /// (camera-to-world pose, the reference's frame index, inliers, beyond the jump limits).
    fn candidate(&self, ref_from_cur: Se3, inliers: usize) -> Option<(Se3, u64, usize, bool)> {
        let reference = self.reference.as_ref()?;
        let beyond = self.jump_limits.is_some_and(|(m, rad)| ref_from_cur.translation_m.length() > m || ref_from_cur.rotation_angle_rad() > rad);
        Some((reference.world_from_camera.compose(&ref_from_cur), reference.frame, inliers, beyond))
    }

    /// A frame after a loss or a gap: its features alone (waited for), matched against the last
    /// accepted frame and this loss's window of keyframes; the most inliers win and the dense
    /// tracker is reseeded there before it tracks the frame. With none, the dense tracker tries
    /// from the last good pose, unless the frame came `unverified_gap_s` seconds after it (more
    /// than [`MAX_UNSEEDED_GAP_S`]): then it is not submitted at all and reported lost
    /// ([`LostReason::Unverified`]). Returns the frame and its features.
    async fn recover(&mut self, gpu: &Gpu, fusion: &mut KinectFusion, frame: &RgbdFrame, unverified_gap_s: Option<f64>) -> Result<(AssistedFrame, Features)> {
        let seed = frame.index as u32;
        let result = self.extractor.process(gpu, fusion.preprocessor(), frame, seed).await?;
        let stages_ms = result.gpu_ms.unwrap_or([f64::NAN; 5]);
        if let (Some(reference), Some(motion)) = (&self.reference, &result.motion) {
            self.last_pair = Some(PairView::new(frame.index, reference.frame, &result.features, &reference.features, motion, stages_ms));
        }
        let against_reference = result.motion.as_ref().and_then(|m| Some((m.reference_from_current()?, m.inliers())));
        let mut best = against_reference.and_then(|(ref_from_cur, inliers)| self.candidate(ref_from_cur, inliers)).map(|(pose, keyframe, inliers, _)| (inliers, pose, keyframe));
        for (inliers, pose, keyframe) in self.match_keyframes(gpu, result.features.keypoint_count(), seed).await? {
            if best.as_ref().is_none_or(|b| inliers > b.0) {
                best = Some((inliers, pose, keyframe));
            }
        }
        let guess = best.map(|(inliers, world_from_camera, keyframe)| Guess::Relocalised { world_from_camera, keyframe, inliers });
        if let (None, Some(gap_s), Some(reference)) = (guess, unverified_gap_s, &self.reference) {
            self.stats.withheld += 1;
            let report = FrameReport {
                index: frame.index,
                world_from_camera: reference.world_from_camera,
                state: TrackingState::Lost(LostReason::Unverified { gap_s }),
                icp: Vec::new(),
                gpu_ms: None,
                encode_ms: 0.0,
                latency_ms: 0.0,
                host: GpuCounts::default(),
                map: None,
                pass_summary: Vec::new(),
            };
            return Ok((AssistedFrame { report, guess, host: GpuCounts::default() }, result.features));
        }
        if let Some(Guess::Relocalised { world_from_camera, .. }) = guess {
            self.stats.relocalisations += 1;
            fusion.reseed(gpu, &world_from_camera)?;
        }
        fusion.submit_preprocessed_frame(gpu, frame).await?;
        let report = report_of(gpu, fusion, frame.index).await?;
        Ok((AssistedFrame { report, guess, host: GpuCounts::default() }, result.features))
    }

    /// The accepted estimates of the last processed frame against this loss's window of
    /// keyframes: (inliers, camera-to-world pose, keyframe's frame index).
    async fn match_keyframes(&mut self, gpu: &Gpu, keypoints: usize, seed: u32) -> Result<Vec<(usize, Se3, u64)>> {
        let Some(last_good) = self.reference.as_ref().map(|r| r.world_from_camera) else { return Ok(Vec::new()) };
        let reference_frame = self.reference.as_ref().map(|r| r.frame);
        let mut order: Vec<usize> = (0..self.keyframes.len()).filter(|&k| Some(self.keyframes[k].frame) != reference_frame).collect();
        if order.is_empty() {
            return Ok(Vec::new());
        }
        order.sort_by(|&a, &b| pose_distance(&last_good, &self.keyframes[a].world_from_camera).total_cmp(&pose_distance(&last_good, &self.keyframes[b].world_from_camera)));
        let windows = order.len().div_ceil(RELOCALISATION_CANDIDATES);
        // The nearest window first (on the first lost frame, or on a frame after a gap while
        // tracking), the next ones on later lost frames.
        let start = (self.lost_streak.saturating_sub(1) % windows) * RELOCALISATION_CANDIDATES;
        let window: Vec<usize> = order[start..(start + RELOCALISATION_CANDIDATES).min(order.len())].to_vec();
        let estimates = self.extractor.match_keyframes(gpu, &window, keypoints, seed).await?;
        Ok(window
            .iter()
            .zip(estimates)
            .filter_map(|(&k, e)| {
                let kf = &self.keyframes[k];
                Some((e.inliers(), kf.world_from_camera.compose(&e.reference_from_current()?), kf.frame))
            })
            .collect())
    }

    /// `fusion`'s report of the frame just processed (its `features` and the `guess` it was
    /// tracked from): tracked (it becomes the reference, and a keyframe where the store has none
    /// near it) or lost. A relocalisation the report does not confirm is undone: `fusion` is
    /// reseeded at the last good pose, so it leaves nothing behind.
    fn verdict(&mut self, gpu: &Gpu, fusion: &mut KinectFusion, features: Features, guess: Option<Guess>, report: &FrameReport, timestamp_ns: i64) -> Result<()> {
        let frame = report.index;
        let relocalised = matches!(guess, Some(Guess::Relocalised { .. }));
        let world_from_camera = &report.world_from_camera;
        if report.state.is_lost() {
            self.lost_streak += 1;
            if relocalised && let Some(r) = &self.reference {
                fusion.reseed(gpu, &r.world_from_camera)?;
            }
            return Ok(());
        }
        if self.lost_streak > 0 && guess.is_some() {
            self.stats.recoveries += 1;
        }
        if relocalised {
            self.stats.relocalisations_confirmed += 1;
        }
        self.lost_streak = 0;
        self.extractor.accept(true);
        if !self.keyframes.iter().any(|k| within_spacing(&k.world_from_camera, world_from_camera)) {
            self.add_keyframe(gpu, Keyframe { features: features.clone(), world_from_camera: *world_from_camera, frame, timestamp_ns })?;
        }
        self.reference = Some(Keyframe { features, world_from_camera: *world_from_camera, frame, timestamp_ns });
        Ok(())
    }

    fn add_keyframe(&mut self, gpu: &Gpu, keyframe: Keyframe) -> Result<()> {
        let slot = if self.keyframes.len() < KEYFRAME_CAPACITY { self.keyframes.len() } else { most_redundant(&self.keyframes) };
        self.extractor.store_keyframe(gpu, slot)?;
        if slot == self.keyframes.len() {
            self.keyframes.push(keyframe);
        } else {
            self.keyframes[slot] = keyframe;
        }
        self.stats.keyframes_added += 1;
        Ok(())
    }
}

/// `fusion`'s report of frame `index`, waiting for it (the last one: a frame tracked again
/// after a relocalisation reports twice).
async fn report_of(gpu: &Gpu, fusion: &mut KinectFusion, index: u64) -> Result<FrameReport> {
    fusion.flush(gpu).await?.into_iter().rev().find(|r| r.index == index).ok_or_else(|| Error::Poll(format!("frame {index} produced no report")))
}

/// The keyframe whose nearest other keyframe is closest (the first of such a pair).
fn most_redundant(keyframes: &[Keyframe]) -> usize {
    let nearest = |i: usize| keyframes.iter().enumerate().filter(|(j, _)| *j != i).map(|(_, k)| pose_distance(&keyframes[i].world_from_camera, &k.world_from_camera)).fold(f64::INFINITY, f64::min);
    (0..keyframes.len()).min_by(|&a, &b| nearest(a).total_cmp(&nearest(b))).unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3};

    fn kf(x: f64, yaw: f64, frame: u64) -> Keyframe {
        Keyframe { features: Features::default(), world_from_camera: Se3::new(DQuat::from_rotation_y(yaw), DVec3::new(x, 0.0, 0.0)), frame, timestamp_ns: 0 }
    }

    #[test]
    fn keyframe_spacing_needs_both_distances_small() {
        let a = kf(0.0, 0.0, 0).world_from_camera;
        assert!(within_spacing(&a, &kf(0.05, 0.1, 1).world_from_camera));
        assert!(!within_spacing(&a, &kf(0.12, 0.0, 1).world_from_camera));
        assert!(!within_spacing(&a, &kf(0.0, 0.2, 1).world_from_camera));
    }

    #[test]
    fn the_most_redundant_keyframe_is_one_of_the_closest_pair() {
        let store = vec![kf(0.0, 0.0, 0), kf(1.0, 0.0, 1), kf(1.02, 0.0, 2), kf(2.0, 0.0, 3)];
        assert!([1, 2].contains(&most_redundant(&store)));
        let spread = vec![kf(0.0, 0.0, 0), kf(0.5, 0.0, 1), kf(2.0, 0.0, 2)];
        assert!([0, 1].contains(&most_redundant(&spread)));
    }
}
