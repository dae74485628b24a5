// SPDX-License-Identifier: MIT
//! The feature chain on the GPU, recorded after the preprocessor in one submission:
//! detection (`fast_score`, `corner_candidates`, `keypoint_select` per level), description (`feature_smooth`,
//! `orb_describe` per level), matching against the reference frame (`hamming_match`,
//! current → reference and back, then `match_select`'s filters and 3D pairs) and the robust
//! motion estimate (`ransac_hypotheses`, `ransac_refine`). Three keypoint sets rotate through three roles: the
//! reference (a keyframe, or the last tracked frame), the previous tracked frame (matched and
//! estimated too, in the same submission, when [`FeatureExtractor::matching_previous`] asks
//! for it and it is not the reference) and the frame being written;
//! [`FeatureExtractor::accept`] promotes the current frame.
//!
//! Keyframes for relocalisation are copies of a processed frame's keypoints and descriptors
//! ([`FeatureExtractor::store_keyframe`]); [`FeatureExtractor::match_keyframes`] matches the
//! last processed frame against up to [`RELOCALISATION_CANDIDATES`] of them in one submission.
//!
//! The host reads each frame's keypoints, matches and estimate back in one readback; it
//! computes nothing of the estimate itself.

use web_time::Instant;

use super::tracker::{MotionEstimate, OdometryConfig, focal_px, motion_from_estimate};
use super::{Features, LevelLayout, descriptor_pattern, slot_count};
use crate::cpu::odometry::estimate::RANSAC_MAX_HYPOTHESES;
use crate::cpu::shared::DESCRIPTOR_WORDS;
use crate::engine::{FrameEncoder, ReadbackRing, StageTimer};
use crate::fusion::FEATURE_STAGES;
use crate::kernels::gpu_data::{FeaturePair, RigidEstimate};
use crate::kernels::{corner_candidates, fast_score, feature_smooth, hamming_match, keypoint_select, match_select, orb_describe, ransac_hypotheses, ransac_refine};
use crate::preprocess::DepthPreprocessor;
use crate::{Error, Gpu, Result, RgbdFrame};

/// The stages a frame is timed by, in order: the update (upload and preprocessing), then the
/// stages it records into a dense frame too ([`FEATURE_STAGES`]).
pub const STAGES: [&str; 5] = ["update", FEATURE_STAGES[0], FEATURE_STAGES[1], FEATURE_STAGES[2], FEATURE_STAGES[3]];

/// Keyframes matched per [`FeatureExtractor::match_keyframes`].
pub const RELOCALISATION_CANDIDATES: usize = 4;

/// Keypoint sets on the GPU: reference, previous, current.
const SETS: usize = 3;

/// Bytes read back per slot: keypoint, feature, point, forward and backward match (16 each),
/// the pair (48) and its inlier flag (4).
const SLOT_BYTES: u64 = 5 * 16 + PAIR_BYTES + 4;
/// Bytes of one [`FeaturePair`].
const PAIR_BYTES: u64 = size_of::<FeaturePair>() as u64;
/// Bytes of one [`RigidEstimate`].
pub const ESTIMATE_BYTES: u64 = size_of::<RigidEstimate>() as u64;

struct Set {
    keypoints: wgpu::Buffer,
    points: wgpu::Buffer,
    descriptors: wgpu::Buffer,
    features: wgpu::Buffer,
}

/// A keyframe's copy of a set: what matching and the estimate read.
struct StoredSet {
    keypoints: wgpu::Buffer,
    points: wgpu::Buffer,
    descriptors: wgpu::Buffer,
}

/// Where one estimate goes (the frame's against its reference, or one relocalisation
/// candidate's): its pairs, estimate and inlier flags, and the RANSAC bind groups that read and
/// write them.
struct EstimateTarget {
    pairs: wgpu::Buffer,
    estimate: wgpu::Buffer,
    inlier_flags: wgpu::Buffer,
    hypotheses: wgpu::BindGroup,
    refine: wgpu::BindGroup,
}

/// The estimate's buffers shared by every target (its steps run one target at a time).
struct EstimateScratch {
    hypotheses: wgpu::Buffer,
    costs: wgpu::Buffer,
    residuals: wgpu::Buffer,
}

impl EstimateScratch {
    fn new(gpu: &Gpu, slots: usize) -> Self {
        let h = RANSAC_MAX_HYPOTHESES as usize;
        Self {
            hypotheses: gpu.storage_buffer::<[[f32; 4]; 4]>("core.ransac_hypotheses.hypotheses", h),
            costs: gpu.storage_buffer::<f32>("core.ransac_hypotheses.costs", h),
            residuals: gpu.storage_buffer::<f32>("core.ransac_refine.residuals", slots),
        }
    }

    fn target(&self, gpu: &Gpu, label: &str, slots: usize, params: &wgpu::Buffer) -> EstimateTarget {
        let pairs = gpu.storage_buffer::<FeaturePair>(&format!("core.match_select.pairs[{label}]"), slots);
        let estimate = gpu.storage_buffer::<RigidEstimate>(&format!("core.match_select.estimate[{label}]"), 1);
        let inlier_flags = gpu.storage_buffer::<u32>(&format!("core.ransac_refine.inlier_flags[{label}]"), slots);
        let hypotheses = ransac_hypotheses::Bindings { params, pairs: &pairs, estimate: &estimate, hypotheses: &self.hypotheses, costs: &self.costs }.bind_group(gpu);
        let refine = ransac_refine::Bindings { params, hypotheses: &self.hypotheses, costs: &self.costs, pairs: &pairs, estimate: &estimate, residuals: &self.residuals, inlier_flags: &inlier_flags }.bind_group(gpu);
        EstimateTarget { pairs, estimate, inlier_flags, hypotheses, refine }
    }
}

/// What matching reads of a keypoint set: a frame's set or a keyframe's copy.
#[derive(Clone, Copy)]
struct MatchSide<'a> {
    keypoints: &'a wgpu::Buffer,
    points: &'a wgpu::Buffer,
    descriptors: &'a wgpu::Buffer,
}

impl Set {
    fn side(&self) -> MatchSide<'_> {
        MatchSide { keypoints: &self.keypoints, points: &self.points, descriptors: &self.descriptors }
    }
}

impl StoredSet {
    fn side(&self) -> MatchSide<'_> {
        MatchSide { keypoints: &self.keypoints, points: &self.points, descriptors: &self.descriptors }
    }
}

/// The bind groups that match a current set against a reference set: `hamming_match` both
/// ways into (forward, backward), and `match_select` of those into an estimate target.
struct PairMatching {
    forward: wgpu::BindGroup,
    backward: wgpu::BindGroup,
    select: wgpu::BindGroup,
}

impl PairMatching {
    fn new(gpu: &Gpu, match_params: &wgpu::Buffer, select_params: &wgpu::Buffer, current: MatchSide<'_>, reference: MatchSide<'_>, [forward, backward]: [&wgpu::Buffer; 2], target: &EstimateTarget) -> Self {
        let (c, r) = (current, reference);
        Self {
            forward: hamming_match::Bindings { params: match_params, query_keypoints: c.keypoints, query_descriptors: c.descriptors, train_keypoints: r.keypoints, train_descriptors: r.descriptors, matches: forward }.bind_group(gpu),
            backward: hamming_match::Bindings { params: match_params, query_keypoints: r.keypoints, query_descriptors: r.descriptors, train_keypoints: c.keypoints, train_descriptors: c.descriptors, matches: backward }.bind_group(gpu),
            select: match_select::Bindings {
                params: select_params,
                forward,
                backward,
                current_keypoints: c.keypoints,
                current_points: c.points,
                reference_keypoints: r.keypoints,
                reference_points: r.points,
                pairs: &target.pairs,
                estimate: &target.estimate,
            }
            .bind_group(gpu),
        }
    }
}

struct Level {
    layout: LevelLayout,
    _params: Vec<wgpu::Buffer>,
    fast: wgpu::BindGroup,
    candidates: wgpu::BindGroup,
    /// The smoothing along x (intensity -> smoothed_x), then along y (-> smoothed).
    smooth: [wgpu::BindGroup; 2],
    /// Per set written.
    select: [wgpu::BindGroup; SETS],
    describe: [wgpu::BindGroup; SETS],
}

/// One frame's features, matches and motion against the reference, as read back.
#[derive(Clone, Debug)]
pub struct FrameFeatures {
    /// Keypoints, features and points (descriptors stay on the GPU).
    pub features: Features,
    /// Per current slot: (reference slot, distance, second distance, 0); empty without a
    /// reference.
    pub forward: Vec<[u32; 4]>,
    /// Per reference slot: (current slot, distance, second distance, 0).
    pub backward: Vec<[u32; 4]>,
    /// The motion against the reference (`None` without a reference).
    pub motion: Option<MotionEstimate>,
    /// The motion against the previous tracked frame, when the extractor matches it
    /// ([`FeatureExtractor::matching_previous`]) and it is not the reference.
    pub motion_previous: Option<MotionEstimate>,
    /// GPU milliseconds per stage of [`STAGES`] (`None` without timestamp queries).
    pub gpu_ms: Option<[f64; 5]>,
    /// Host milliseconds from upload to the readback's arrival.
    pub wall_ms: f64,
}

/// What a feature readback carries besides its bytes.
struct FeatureTag {
    /// The frame was matched against a reference (its matches and estimate were copied).
    has_reference: bool,
    /// The frame was matched against the previous tracked frame too (its estimate was copied
    /// after the reference's).
    has_previous: bool,
    /// The stages timed into the slot, when the frame was the extractor's own submission.
    stages: Option<Vec<&'static str>>,
    /// When the frame began.
    started: Instant,
}

/// Detects, describes and matches keypoints on the GPU.
pub struct FeatureExtractor {
    config: OdometryConfig,
    /// The focal length of the estimate's noise model, pixels.
    f_px: f32,
    slots: usize,
    levels: Vec<Level>,
    sets: [Set; SETS],
    forward: wgpu::Buffer,
    backward: wgpu::Buffer,
    /// At `current * SETS + reference`: the frame's matching of two different sets
    /// ([`PairMatching`]) into `forward`, `backward` and `estimate`.
    matching: Vec<Option<PairMatching>>,
    match_params: wgpu::Buffer,
    /// At `current * SETS + previous`: the same into buffers of their own (the reference's
    /// matches are read back) and `previous_estimate`.
    matching_previous: Vec<Option<PairMatching>>,
    select_params: wgpu::Buffer,
    /// RANSAC's parameters for the frame's estimate and for relocalisation candidates (their
    /// seeds are written before each submission).
    ransac_params: wgpu::Buffer,
    candidate_ransac_params: wgpu::Buffer,
    /// Held for the bind groups that use it.
    _scratch: EstimateScratch,
    estimate: EstimateTarget,
    /// The estimate against the previous tracked frame (same RANSAC seed as the frame's).
    previous_estimate: EstimateTarget,
    /// Whether frames are matched against the previous tracked frame too.
    match_previous: bool,
    /// The previous matching's forward and backward matches.
    _previous_matches: [wgpu::Buffer; 2],
    candidate_estimates: Vec<EstimateTarget>,
    _pattern: wgpu::Buffer,
    readback: ReadbackRing<FeatureTag>,
    /// Stored keyframes, by keyframe slot.
    keyframes: Vec<StoredSet>,
    /// Per relocalisation candidate: forward and backward matches.
    candidate_matches: Vec<[wgpu::Buffer; 2]>,
    candidate_readback: ReadbackRing<()>,
    timer: Option<StageTimer>,
    /// Whether [`Self::process`] runs only the preprocessing stages the features read (the
    /// preprocessor is this extractor's alone; [`Self::images_only`]).
    images_only: bool,
    /// The set the last frame was written to.
    current: usize,
    /// The reference's set.
    reference: Option<usize>,
    /// The previous tracked frame's set.
    previous: Option<usize>,
}

impl std::fmt::Debug for FeatureExtractor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FeatureExtractor").field("config", &self.config).field("slots", &self.slots).field("reference", &self.reference).field("previous", &self.previous).finish_non_exhaustive()
    }
}

impl FeatureExtractor {
    /// An extractor reading `preprocessor`'s intensity pyramid and level-0 depth.
    pub fn new(gpu: &Gpu, preprocessor: &DepthPreprocessor, odometry: OdometryConfig) -> Result<Self> {
        odometry.validate()?;
        let config = odometry.features;
        let k0 = preprocessor.levels[0].intrinsics;
        let layout = config.layout(&k0);
        if layout.is_empty() {
            return Err(Error::InvalidConfig(format!("features: a {}x{} image has no room for keypoints", k0.width_px, k0.height_px)));
        }
        if layout.len() > preprocessor.levels.len() {
            return Err(Error::InvalidConfig(format!("features: {} levels wanted, the preprocessor has {}", layout.len(), preprocessor.levels.len())));
        }
        let slots = slot_count(&layout);
        let set = |i: usize| Set {
            keypoints: gpu.storage_buffer::<[f32; 4]>(&format!("core.features[{i}].keypoints"), slots),
            points: gpu.storage_buffer::<[f32; 4]>(&format!("core.features[{i}].points"), slots),
            descriptors: gpu.storage_buffer::<u32>(&format!("core.features[{i}].descriptors"), slots * DESCRIPTOR_WORDS),
            features: gpu.storage_buffer::<[f32; 4]>(&format!("core.features[{i}].features"), slots),
        };
        let sets = [set(0), set(1), set(2)];
        let pattern = gpu.storage_buffer::<[f32; 4]>("core.orb_describe.pattern", 256);
        gpu.write_buffer(&pattern, &descriptor_pattern());
        // Keypoints are lifted from the raw metric depth (before the bilateral filter): its noise
        // is what the Kinect model that weighs the pairs describes and what the border filter's
        // 4σ test is calibrated for; `keypoint_select` averages it along each keypoint's ray.
        let depth_m = preprocessor.depth_unfiltered_m.as_ref().unwrap_or(&preprocessor.levels[0].depth_m);
        let levels = layout
            .iter()
            .map(|l| {
                let n = (l.width_px * l.height_px) as usize;
                let image = &preprocessor.levels[l.level as usize].intensity;
                let score = gpu.storage_buffer::<f32>(&format!("core.fast_score.score[{}]", l.level), n);
                let candidate = gpu.storage_buffer::<f32>(&format!("core.corner_candidates.candidate[{}]", l.level), n);
                let candidates_p = gpu.uniform_buffer("core.corner_candidates.params", &l.candidates_params(&k0));
                let candidates = corner_candidates::Bindings { params: &candidates_p, score: &score, depth_m, candidate: &candidate }.bind_group(gpu);
                let smoothed_x = gpu.storage_buffer::<f32>(&format!("core.feature_smooth.smoothed_x[{}]", l.level), n);
                let smoothed = gpu.storage_buffer::<f32>(&format!("core.feature_smooth.smoothed[{}]", l.level), n);
                let fast_p = gpu.uniform_buffer("core.fast_score.params", &l.fast_params(&config));
                let smooth_p = [0, 1].map(|axis| gpu.uniform_buffer("core.feature_smooth.params", &feature_smooth::FeatureSmoothParams { width_px: l.width_px, height_px: l.height_px, axis, ..Default::default() }));
                let select_p = gpu.uniform_buffer("core.keypoint_select.params", &l.select_params(&config, &k0));
                let describe_p = gpu.uniform_buffer("core.orb_describe.params", &l.describe_params(&config));
                let fast = fast_score::Bindings { params: &fast_p, intensity: image, score: &score }.bind_group(gpu);
                let smooth = [
                    feature_smooth::Bindings { params: &smooth_p[0], intensity: image, smoothed: &smoothed_x }.bind_group(gpu),
                    feature_smooth::Bindings { params: &smooth_p[1], intensity: &smoothed_x, smoothed: &smoothed }.bind_group(gpu),
                ];
                let select = [0, 1, 2].map(|s: usize| keypoint_select::Bindings { params: &select_p, score: &candidate, depth_m, keypoints: &sets[s].keypoints, points: &sets[s].points }.bind_group(gpu));
                let describe = [0, 1, 2].map(|s: usize| {
                    orb_describe::Bindings { params: &describe_p, smoothed: &smoothed, keypoints: &sets[s].keypoints, pattern: &pattern, descriptors: &sets[s].descriptors, features: &sets[s].features }.bind_group(gpu)
                });
                let [smooth_x_p, smooth_y_p] = smooth_p;
                Level { layout: *l, _params: vec![fast_p, candidates_p, smooth_x_p, smooth_y_p, select_p, describe_p, score, candidate, smoothed_x, smoothed], fast, candidates, smooth, select, describe }
            })
            .collect();
        let forward = gpu.storage_buffer::<[u32; 4]>("core.hamming_match.forward", slots);
        let backward = gpu.storage_buffer::<[u32; 4]>("core.hamming_match.backward", slots);
        let match_params = gpu.uniform_buffer("core.hamming_match.params", &hamming_match::HammingMatchParams { query_count: slots as u32, train_count: slots as u32 });
        let select_params = gpu.uniform_buffer("core.match_select.params", &odometry.matching.select_params(slots as u32));
        let ransac_params = gpu.uniform_buffer("core.ransac.params", &odometry.ransac.params(focal_px(&k0), 0));
        let candidate_ransac_params = gpu.uniform_buffer("core.ransac.candidate_params", &odometry.ransac.params(focal_px(&k0), 0));
        let scratch = EstimateScratch::new(gpu, slots);
        let estimate = scratch.target(gpu, "frame", slots, &ransac_params);
        let previous_estimate = scratch.target(gpu, "previous", slots, &ransac_params);
        let previous_matches = ["forward", "backward"].map(|d| gpu.storage_buffer::<[u32; 4]>(&format!("core.hamming_match.previous.{d}"), slots));
        let candidate_estimates = (0..RELOCALISATION_CANDIDATES).map(|c| scratch.target(gpu, &format!("candidate{c}"), slots, &candidate_ransac_params)).collect();
        // Bind groups of the frame's matching of every ordered pair of different sets, against
        // the reference and against the previous tracked frame.
        let pair_matchings = |matches: [&wgpu::Buffer; 2], target: &EstimateTarget| -> Vec<Option<PairMatching>> {
            (0..SETS * SETS)
                .map(|i| {
                    let (cur, other) = (i / SETS, i % SETS);
                    (cur != other).then(|| PairMatching::new(gpu, &match_params, &select_params, sets[cur].side(), sets[other].side(), matches, target))
                })
                .collect()
        };
        let matching = pair_matchings([&forward, &backward], &estimate);
        let [previous_forward, previous_backward] = &previous_matches;
        let matching_previous = pair_matchings([previous_forward, previous_backward], &previous_estimate);
        // Per frame: the slots' parts, the reference's estimate, the previous frame's, the
        // timestamps.
        let readback = ReadbackRing::new(gpu, "core.features", SLOT_BYTES * slots as u64 + ESTIMATE_BYTES + (ESTIMATE_BYTES + (PAIR_BYTES + 4) * slots as u64) + StageTimer::BYTES, 1);
        let timer = StageTimer::new(gpu, "core.features");
        let candidate_matches = (0..RELOCALISATION_CANDIDATES)
            .map(|c| ["forward", "backward"].map(|d| gpu.storage_buffer::<[u32; 4]>(&format!("core.hamming_match.candidate[{c}].{d}"), slots)))
            .collect();
        let candidate_readback = ReadbackRing::new(gpu, "core.features.candidates", (ESTIMATE_BYTES + (PAIR_BYTES + 4) * slots as u64) * RELOCALISATION_CANDIDATES as u64, 1);
        Ok(Self {
            config: odometry,
            f_px: focal_px(&k0),
            slots,
            levels,
            sets,
            forward,
            backward,
            matching,
            match_params,
            select_params,
            matching_previous,
            ransac_params,
            candidate_ransac_params,
            _scratch: scratch,
            estimate,
            previous_estimate,
            match_previous: false,
            _previous_matches: previous_matches,
            candidate_estimates,
            _pattern: pattern,
            readback,
            keyframes: Vec::new(),
            candidate_matches,
            candidate_readback,
            timer,
            images_only: false,
            current: 0,
            reference: None,
            previous: None,
        })
    }

    /// The preprocessor is this extractor's alone: [`Self::process`] records only the stages
    /// the features read (no depth pyramid, vertex or normal maps). Not for a preprocessor
    /// shared with a dense tracker, which needs them.
    pub fn images_only(mut self) -> Self {
        self.images_only = true;
        self
    }

    /// Each frame is matched against the previous tracked frame too, when that is not the
    /// reference, and the motion estimated against it ([`FrameFeatures::motion_previous`]),
    /// in the frame's own submission: keyframe odometry's second path costs no host wait.
    pub fn matching_previous(mut self) -> Self {
        self.match_previous = true;
        self
    }

    /// The previous tracked frame's set, when the current frame is matched against it.
    fn previous_matched(&self) -> Option<usize> {
        self.previous.filter(|p| self.match_previous && self.reference.is_some() && Some(*p) != self.reference)
    }

    /// The settings.
    pub fn config(&self) -> &OdometryConfig {
        &self.config
    }

    /// Keypoint slots per frame.
    pub fn slots(&self) -> usize {
        self.slots
    }

    /// The frame's estimate against the reference (a `RigidEstimate`, written by
    /// `match_select` and `ransac_refine`), for a kernel that reads it in the same submission
    /// (`feature_guess`).
    pub fn estimate_buffer(&self) -> &wgpu::Buffer {
        &self.estimate.estimate
    }

    /// Whether a reference frame is held (the next frame is matched against it).
    pub fn has_reference(&self) -> bool {
        self.reference.is_some()
    }

    /// The last processed frame was tracked: it becomes the previous tracked frame, and the
    /// reference too when `as_reference` (a new keyframe; in frame-to-frame odometry always).
    pub fn accept(&mut self, as_reference: bool) {
        self.previous = Some(self.current);
        if as_reference || self.reference.is_none() {
            self.reference = Some(self.current);
        }
    }

    /// Forgets the reference and the previous frame.
    pub fn reset(&mut self) {
        self.reference = None;
        self.previous = None;
    }

    /// The set the next frame writes: one neither the reference nor the previous frame holds.
    fn free_set(&self) -> usize {
        (0..SETS).find(|s| Some(*s) != self.reference && Some(*s) != self.previous).expect("three sets, two roles")
    }

    /// Chooses the set the next frame is written to; [`Self::encode_features`] records into it.
    fn begin_frame(&mut self) {
        self.current = self.free_set();
    }

    /// Records, after [`Self::begin`], detection and description of the frame in the
    /// preprocessor's buffers, and its matching against the reference and the motion estimate
    /// ([`Self::estimate_buffer`]) when there is a reference; nothing is read back.
    pub fn encode_features(&self, gpu: &Gpu, fe: &mut FrameEncoder<'_>) {
        let s = self.current;
        {
            let mut pass = fe.stage("detection");
            for l in &self.levels {
                gpu.kernels.fast_score.dispatch_in(&mut pass, &l.fast, [l.layout.width_px, l.layout.height_px, 1]);
                gpu.kernels.corner_candidates.dispatch_in(&mut pass, &l.candidates, [l.layout.width_px, l.layout.height_px, 1]);
                gpu.kernels.keypoint_select.dispatch_in(&mut pass, &l.select[s], [l.layout.cells_x * l.layout.cells_y, 1, 1]);
            }
        }
        {
            let mut pass = fe.stage("description");
            for l in &self.levels {
                for (axis, smooth) in (0..).zip(&l.smooth) {
                    gpu.kernels.feature_smooth.dispatch_in(&mut pass, smooth, feature_smooth::invocations(l.layout.width_px, l.layout.height_px, axis));
                }
                gpu.kernels.orb_describe.dispatch_in(&mut pass, &l.describe[s], [l.layout.slot_count(), 1, 1]);
            }
        }
        {
            let mut pass = fe.stage("matching");
            if let Some(r) = self.reference {
                self.encode_matching(gpu, &mut pass, r);
            }
            if let Some(p) = self.previous_matched() {
                self.dispatch_matching(gpu, &mut pass, self.matching_previous[self.current * SETS + p].as_ref().expect("the current set is never the previous"));
            }
        }
        let mut pass = fe.stage("estimation");
        if self.reference.is_some() {
            self.encode_estimate(gpu, &mut pass, &self.estimate);
        }
        if self.previous_matched().is_some() {
            self.encode_estimate(gpu, &mut pass, &self.previous_estimate);
        }
    }

    /// The seed of the next frame's RANSAC sample stream (its estimates against the reference
    /// and the previous frame): each frame draws its own samples, reproducibly.
    pub fn set_seed(&self, gpu: &Gpu, seed: u32) {
        gpu.write_buffer(&self.ransac_params, &[self.config.ransac.params(self.f_px, seed)]);
    }

    /// Matching of the current set against set `reference` and `match_select` into the frame's
    /// estimate target.
    fn encode_matching(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>, reference: usize) {
        self.dispatch_matching(gpu, pass, self.matching[self.current * SETS + reference].as_ref().expect("the current set is never a reference"));
    }

    /// Both matching directions (`hamming_match`, one invocation per slot) and `match_select`
    /// (one workgroup) of one pair of sets.
    fn dispatch_matching(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>, pair: &PairMatching) {
        let n = self.slots as u32;
        gpu.kernels.hamming_match.dispatch_in(pass, &pair.forward, [n, 1, 1]);
        gpu.kernels.hamming_match.dispatch_in(pass, &pair.backward, [n, 1, 1]);
        gpu.kernels.match_select.dispatch_in(pass, &pair.select, [gpu.kernels.match_select.kernel.workgroup_size[0], 1, 1]);
    }

    /// RANSAC and the refinement of `target`'s pairs (one workgroup per hypothesis, then one).
    fn encode_estimate(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>, target: &EstimateTarget) {
        let hypotheses = self.config.ransac.hypotheses.min(RANSAC_MAX_HYPOTHESES);
        let [wg, _, _] = gpu.kernels.ransac_hypotheses.kernel.workgroup_size;
        gpu.kernels.ransac_hypotheses.dispatch_in(pass, &target.hypotheses, [wg * hypotheses, 1, 1]);
        gpu.kernels.ransac_refine.dispatch_in(pass, &target.refine, [gpu.kernels.ransac_refine.kernel.workgroup_size[0], 1, 1]);
    }

    /// Bytes [`Self::copy_estimate`] copies.
    fn estimate_bytes(&self) -> u64 {
        ESTIMATE_BYTES + (PAIR_BYTES + 4) * self.slots as u64
    }

    /// Records copies of `target`'s estimate, pairs and inlier flags into `buffer` at `offset`
    /// (estimate, then `slots` pairs, then `slots` flags).
    fn copy_estimate(&self, encoder: &mut wgpu::CommandEncoder, target: &EstimateTarget, buffer: &wgpu::Buffer, offset: u64) {
        let n = self.slots as u64;
        encoder.copy_buffer_to_buffer(&target.estimate, 0, buffer, offset, ESTIMATE_BYTES);
        encoder.copy_buffer_to_buffer(&target.pairs, 0, buffer, offset + ESTIMATE_BYTES, PAIR_BYTES * n);
        encoder.copy_buffer_to_buffer(&target.inlier_flags, 0, buffer, offset + ESTIMATE_BYTES + PAIR_BYTES * n, 4 * n);
    }

    /// The motion read back by [`Self::copy_estimate`] from `bytes`, for a current frame of
    /// `keypoints` keypoints.
    fn read_estimate(&self, bytes: &[u8], keypoints: usize) -> MotionEstimate {
        let n = self.slots;
        let e = ESTIMATE_BYTES as usize;
        let estimate: RigidEstimate = bytemuck::pod_read_unaligned(&bytes[..e]);
        let pairs: Vec<FeaturePair> = bytemuck::pod_collect_to_vec(&bytes[e..e + PAIR_BYTES as usize * n]);
        let flags: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[e + PAIR_BYTES as usize * n..e + (PAIR_BYTES as usize + 4) * n]);
        motion_from_estimate(keypoints, &estimate, &pairs, &flags, self.f_px)
    }

    /// Copies the last processed frame's keypoints and descriptors into keyframe slot `slot`
    /// (a slot past the last one grows the store by one; an existing one is overwritten).
    pub fn store_keyframe(&mut self, gpu: &Gpu, slot: usize) -> Result<()> {
        if slot > self.keyframes.len() {
            return Err(Error::InvalidConfig(format!("features: keyframe slot {slot} past the {} stored", self.keyframes.len())));
        }
        if slot == self.keyframes.len() {
            self.keyframes.push(StoredSet {
                keypoints: gpu.storage_buffer::<[f32; 4]>(&format!("core.features.keyframe[{slot}].keypoints"), self.slots),
                points: gpu.storage_buffer::<[f32; 4]>(&format!("core.features.keyframe[{slot}].points"), self.slots),
                descriptors: gpu.storage_buffer::<u32>(&format!("core.features.keyframe[{slot}].descriptors"), self.slots * DESCRIPTOR_WORDS),
            });
        }
        let (set, stored) = (&self.sets[self.current], &self.keyframes[slot]);
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.features.store_keyframe") });
        encoder.copy_buffer_to_buffer(&set.keypoints, 0, &stored.keypoints, 0, set.keypoints.size());
        encoder.copy_buffer_to_buffer(&set.points, 0, &stored.points, 0, set.points.size());
        encoder.copy_buffer_to_buffer(&set.descriptors, 0, &stored.descriptors, 0, set.descriptors.size());
        gpu.submit([encoder.finish()]);
        Ok(())
    }

    /// Matches the last processed frame (of `keypoints` keypoints) against the stored keyframes
    /// `slots` (at most [`RELOCALISATION_CANDIDATES`]) and estimates the motion against each
    /// (RANSAC seeded by `seed`; the keyframe in the reference's role), in one submission, and
    /// waits: one estimate per keyframe.
    pub async fn match_keyframes(&mut self, gpu: &Gpu, slots: &[usize], keypoints: usize, seed: u32) -> Result<Vec<MotionEstimate>> {
        if slots.len() > RELOCALISATION_CANDIDATES {
            return Err(Error::InvalidConfig(format!("features: {} keyframes asked for, at most {RELOCALISATION_CANDIDATES} per submission", slots.len())));
        }
        if let Some(&bad) = slots.iter().find(|&&k| k >= self.keyframes.len()) {
            return Err(Error::InvalidConfig(format!("features: keyframe slot {bad} past the {} stored", self.keyframes.len())));
        }
        gpu.write_buffer(&self.candidate_ransac_params, &[self.config.ransac.params(self.f_px, seed)]);
        let c = &self.sets[self.current];
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.features.match_keyframes") });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("matching"), timestamp_writes: None });
            for (i, &k) in slots.iter().enumerate() {
                let (kf, [forward, backward], target) = (&self.keyframes[k], &self.candidate_matches[i], &self.candidate_estimates[i]);
                let pair = PairMatching::new(gpu, &self.match_params, &self.select_params, c.side(), kf.side(), [forward, backward], target);
                self.dispatch_matching(gpu, &mut pass, &pair);
                self.encode_estimate(gpu, &mut pass, target);
            }
        }
        let (slot, buffer) = self.candidate_readback.free_slot().ok_or_else(|| Error::Poll("the keyframe estimates' readback is still in flight".into()))?;
        let per = self.estimate_bytes();
        for (i, target) in self.candidate_estimates.iter().take(slots.len()).enumerate() {
            self.copy_estimate(&mut encoder, target, buffer, i as u64 * per);
        }
        let submission = gpu.submit([encoder.finish()]);
        self.candidate_readback.start(gpu, slot, submission, ());
        let done = self.candidate_readback.wait_oldest(gpu).await?.ok_or_else(|| Error::Poll("the keyframe estimates' readback vanished".into()))?;
        Ok((0..slots.len()).map(|i| self.read_estimate(&done.bytes[i * per as usize..(i + 1) * per as usize], keypoints)).collect())
    }

    /// Uploads and preprocesses `frame`, extracts its features, matches them against the
    /// reference and estimates the motion (RANSAC seeded by `seed`), and waits for the result:
    /// one submission of its own ([`Self::begin`], [`Self::encode_frame`],
    /// [`Self::frame_submitted`], [`Self::finish_frame`]).
    pub async fn process(&mut self, gpu: &Gpu, preprocessor: &DepthPreprocessor, frame: &RgbdFrame, seed: u32) -> Result<FrameFeatures> {
        gpu.check_lost()?;
        let started = Instant::now();
        preprocessor.upload(gpu, frame)?;
        self.begin(gpu, seed);
        let mut fe = FrameEncoder::new(gpu, "core.features.frame", self.timer.as_ref());
        {
            let mut pass = fe.stage("update");
            if self.images_only {
                preprocessor.encode_images_in(gpu, &mut pass);
            } else {
                preprocessor.encode_in(gpu, &mut pass);
            }
        }
        let slot = self.encode_frame(gpu, &mut fe)?;
        let (_, buffer) = self.readback.free_slot().expect("encode_frame found this slot free");
        let (commands, stages) = fe.finish(Some((buffer, self.timestamps_offset())));
        let submission = gpu.submit([commands]);
        self.frame_submitted(gpu, slot, submission, Some(stages), started);
        self.finish_frame(gpu).await
    }

    /// Starts a frame: seeds its RANSAC sample stream with `seed` and picks the keypoint set it
    /// writes. [`Self::encode_frame`] then records it.
    pub fn begin(&mut self, gpu: &Gpu, seed: u32) {
        self.set_seed(gpu, seed);
        self.begin_frame();
    }

    /// Records, after [`Self::begin`] and the preprocessor's stages, the frame's features
    /// ([`Self::encode_features`]) and the copies of its keypoints, matches and estimate into a free
    /// readback slot, which it returns for [`Self::frame_submitted`].
    pub fn encode_frame(&self, gpu: &Gpu, fe: &mut FrameEncoder<'_>) -> Result<usize> {
        let (slot, buffer) = self.readback.free_slot().ok_or_else(|| Error::Poll("the feature readback is still in flight".into()))?;
        self.encode_features(gpu, fe);
        let n = self.slots as u64 * 16;
        let set = &self.sets[self.current];
        for (i, b) in [&set.keypoints, &set.features, &set.points, &self.forward, &self.backward].into_iter().enumerate() {
            fe.encoder().copy_buffer_to_buffer(b, 0, buffer, i as u64 * n, n);
        }
        self.copy_estimate(fe.encoder(), &self.estimate, buffer, 5 * n);
        if self.previous_matched().is_some() {
            self.copy_estimate(fe.encoder(), &self.previous_estimate, buffer, 5 * n + self.estimate_bytes());
        }
        Ok(slot)
    }

    /// Where [`Self::process`] has the frame's timestamps written in its readback slot.
    fn timestamps_offset(&self) -> u64 {
        5 * self.slots as u64 * 16 + 2 * self.estimate_bytes()
    }

    /// The submission that holds the frame [`Self::encode_frame`] recorded into `slot`: its
    /// readback starts. `stages` are the stages timed into the slot (only when the frame is
    /// this extractor's own submission); `started` is when the frame began, for its wall time.
    pub fn frame_submitted(&mut self, gpu: &Gpu, slot: usize, submission: wgpu::SubmissionIndex, stages: Option<Vec<&'static str>>, started: Instant) {
        let tag = FeatureTag { has_reference: self.reference.is_some(), has_previous: self.previous_matched().is_some(), stages, started };
        self.readback.start(gpu, slot, submission, tag);
    }

    /// The frame whose readback [`Self::frame_submitted`] started, once it arrives: at once
    /// when its submission is known done (a dense frame it shared was reported), otherwise
    /// after waiting for it.
    pub async fn finish_frame(&mut self, gpu: &Gpu) -> Result<FrameFeatures> {
        let arrived = self.readback.collect(gpu)?.pop();
        let done = match arrived {
            Some(done) => done,
            None => self.readback.wait_oldest(gpu).await?.ok_or_else(|| Error::Poll("no feature readback in flight".into()))?,
        };
        let (bytes, tag) = (&done.bytes, done.tag);
        let n = self.slots as u64 * 16;
        let part = |i: usize| &bytes[i * n as usize..(i + 1) * n as usize];
        let features = Features { keypoints: bytemuck::pod_collect_to_vec(part(0)), features: bytemuck::pod_collect_to_vec(part(1)), points: bytemuck::pod_collect_to_vec(part(2)), descriptors: Vec::new() };
        let (forward, backward) = if tag.has_reference { (bytemuck::pod_collect_to_vec(part(3)), bytemuck::pod_collect_to_vec(part(4))) } else { (Vec::new(), Vec::new()) };
        let motion = tag.has_reference.then(|| self.read_estimate(&bytes[5 * n as usize..], features.keypoint_count()));
        let motion_previous = tag.has_previous.then(|| self.read_estimate(&bytes[(5 * n + self.estimate_bytes()) as usize..], features.keypoint_count()));
        let gpu_ms = self.timer.as_ref().zip(tag.stages).map(|(timer, stages)| {
            let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes[self.timestamps_offset() as usize..][..16 * stages.len()]);
            let times = timer.stage_times(&stages, &ticks);
            let mut out = [0.0; 5];
            for t in times {
                if let Some(i) = STAGES.iter().position(|s| *s == t.name) {
                    out[i] += t.gpu_ms;
                }
            }
            out
        });
        Ok(FrameFeatures { features, forward, backward, motion, motion_previous, gpu_ms, wall_ms: tag.started.elapsed().as_secs_f64() * 1e3 })
    }
}
