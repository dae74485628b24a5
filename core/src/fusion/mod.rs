// SPDX-License-Identifier: MIT
//! KinectFusion (000-digest §1.3, §2.3) as a short composition of stages that own their
//! buffers and record into one command encoder per frame:
//!
//! ```text
//! preprocess   DepthPreprocessor     depth → filtered pyramid, vertices, normals, intensity
//! track        IcpTracker            ICP + photometric, solved on the GPU, outcome decided there
//! integrate    Mapper                TSDF fusion at the tracker's pose (skipped when lost)
//! predict      Predictor             raycast at that pose, coarser levels downsampled;
//!              IcpTracker            keep the frame as the next reference (when tracked)
//! readback     ReadbackRing          the TrackState and GPU timestamps, collected late
//! ```
//!
//! A frame is one submission with no host wait inside it: poses, convergence and the lost-frame
//! checks stay on the GPU, and the host learns each frame's outcome from one small readback
//! that completes a frame or more later ([`KinectFusion::submit_frame`],
//! [`KinectFusion::poll_reports`]). The same stages recombine into other pipelines:
//! [`pose_driven::PoseDrivenMapper`] fuses at given poses without tracking.
//!
//! Everything is async so the same code drives the browser (WebGPU) and native (Vulkan) builds.

pub mod mapper;
pub mod normal_equations;
pub mod pose_driven;
pub mod predictor;
pub mod tracker;

use std::collections::VecDeque;

use web_time::Instant;

pub use mapper::Mapper;
pub use normal_equations::NormalEquations;
pub use predictor::{DepthHint, Predictor, RaycastTarget};
pub use tracker::IcpTracker;

use crate::cpu::fusion::track_finish::outcome;
use crate::engine::{FrameEncoder, ReadbackRing, StageTime, StageTimer};
use crate::gpu::GpuCounts;
use crate::kernels::track_solve::TrackState;
use crate::preprocess::{DepthPreprocessor, PreprocessConfig};
use crate::map::{Map, MapStats};
use crate::tsdf::{TsdfConfig, TsdfStore};
use crate::{Error, Gpu, Result, RgbdCalibration, RgbdFrame, Se3};

pub use crate::pose::twist_exp;

/// Default ICP iterations per pyramid level, finest first: at most KinectFusion's 10/5/4; a
/// level stops as soon as it converges ([`DEFAULT_CONVERGED_UPDATE_M`]), so these are caps.
pub const DEFAULT_ICP_ITERATIONS: [u32; 3] = [10, 5, 4];
/// Default largest distance between corresponding points, metres.
pub const DEFAULT_ICP_DIST_THRESH_M: f32 = 0.10;
/// Default largest angle between corresponding normals, radians (20°).
pub const DEFAULT_ICP_ANGLE_THRESH_RAD: f32 = 20.0 * std::f32::consts::PI / 180.0;
/// Default smallest fraction of the finest level's pixels that must pair up for a frame to
/// count as tracked.
pub const DEFAULT_MIN_INLIER_FRACTION: f64 = 0.05;
/// Default largest condition number (largest over smallest eigenvalue) of a level's scaled
/// JᵀJ (rotation columns weighed by [`DEFAULT_ROTATION_SCALE_M`], normalised to trace 6 so its
/// eigenvalues average 1): the numerical gate. f32 resolves the eigenvalues of that matrix to
/// about 1e-6 (6 · 2⁻²³ of rounding per entry), so above 1e5 the smallest is a decade from
/// being lost in rounding: the system is rank-deficient for an f32 solve (a single plane, a
/// lone sphere's rotations), and its step is not taken.
pub const DEFAULT_MAX_CONDITION: f32 = 1e5;
/// Default largest condition number of the translation block of JᵀJ (its lower-right 3 × 3:
/// the surface normals' outer products, plus the photometric gradients'): the geometric gate.
/// A direction of translation no surface faces (along a corridor, across a single wall) still
/// picks up the normals' orientation noise: normals δ off put about δ² of a faced direction's
/// information into it. With δ ≈ 6° RMS (range-dependent Kinect normals), δ² ≈ 1 %: a
/// translation direction with less than 1 % of the best one's information, a condition number
/// above 100, is not observed, its step is not taken and, at the finest level, the frame is
/// lost as ill-conditioned. For calibration, not tuning: a synthetic open corridor measures
/// 2.0e2, the synthetic room 4.8; TUM fr1/rpy frames 7-14 and fr3/teddy up to 33 (photometric
/// gradients, which favour the image plane, included; 6 without them).
pub const DEFAULT_MAX_TRANSLATION_CONDITION: f32 = 100.0;
/// Default length that scales JᵀJ's rotation columns for the conditioning check, metres (1 m:
/// a radian weighs like a metre, the convention of KinectFusion-style gates).
pub const DEFAULT_ROTATION_SCALE_M: f32 = 1.0;
/// Default largest plausible translation between consecutive frames, metres.
pub const DEFAULT_MAX_JUMP_M: f32 = 0.20;
/// Default largest correction ICP may make to a relocalised pose (a reseed) for the
/// relocalisation to stand, metres. A pose from ≥ 20 RANSAC inliers under the Kinect noise
/// model (σ_z 1.5 mm at 1 m, 2.6 cm at 4 m; the refit averages it down) is good to about a
/// centimetre; ICP confirming it refines it by that much. Moving it by several times more means
/// ICP found a different fit than the features did (a self-similar scene slid into place), and
/// the two independent estimates disagree: the relocalisation is rejected, not fused.
pub const DEFAULT_MAX_RESEED_CORRECTION_M: f32 = 0.05;
/// Default largest rotation ICP may apply to a relocalised pose, radians (3°; as above, a
/// few times what 20 inliers spread over the image fix).
pub const DEFAULT_MAX_RESEED_CORRECTION_RAD: f32 = 3.0 * std::f32::consts::PI / 180.0;
/// Default largest plausible rotation between consecutive frames, radians (25°).
pub const DEFAULT_MAX_JUMP_RAD: f32 = 25.0 * std::f32::consts::PI / 180.0;
/// Default Huber threshold on point-to-plane residuals, metres.
pub const DEFAULT_HUBER_DELTA_M: f32 = 0.03;
/// Default weight of the photometric term against the geometric one (0: depth only). The
/// geometric rows are in metres and the photometric ones in intensity units ([0, 1]).
pub const DEFAULT_RGB_WEIGHT: f32 = 0.03;
/// Default largest accepted intensity residual.
pub const DEFAULT_RGB_MAX_RESIDUAL: f32 = 0.3;
/// Default largest depth disagreement for a photometric pair (visibility test), metres.
pub const DEFAULT_RGB_MAX_DEPTH_DIFF_M: f32 = 0.05;
/// A level of the full-resolution image converges once a Gauss-Newton update moves no point
/// within [`DEFAULT_REFERENCE_DEPTH_M`] by more than this, metres. 0.5 mm is below half the
/// Kinect's axial noise at its nearest range (σ ≈ 1.2 mm at 0.5 m, growing with z²) and an
/// order below the trajectory accuracy that depth noise and calibration leave to any dense
/// tracker (≈ 1 cm ATE on TUM): an update that moves nothing by more than that only chases
/// noise. Checked against 1e-4 and 1e-3 on both shared TUM sequences: the same ATE to 0.1 mm,
/// and 1e-4 costs 20-50 % more finest-level iterations. Level l uses 2^l times this (its
/// pixels are 2^l wider).
pub const DEFAULT_CONVERGED_UPDATE_M: f32 = 5e-4;
/// Depth at which an update's rotation is turned into a displacement for the convergence test,
/// metres (the far end of a room-scale Kinect view).
pub const DEFAULT_REFERENCE_DEPTH_M: f32 = 3.0;
/// Frames whose readback may be in flight before the host waits for the oldest.
pub const MAX_FRAMES_IN_FLIGHT: usize = 2;

/// ICP tracking settings.
#[derive(Clone, Debug, PartialEq)]
pub struct IcpConfig {
    /// Most iterations per pyramid level, finest (level 0) first; its length is the number of
    /// levels used, at most the preprocessing pyramid's.
    pub iterations_per_level: Vec<u32>,
    /// Largest distance between corresponding points, metres.
    pub dist_thresh_m: f32,
    /// Largest angle between corresponding normals, radians.
    pub angle_thresh_rad: f32,
    /// Smallest fraction of level-0 pixels that must pair up.
    pub min_inlier_fraction: f64,
    /// Largest condition number of a scaled JᵀJ whose step is taken; at level 0, of a tracked
    /// frame.
    pub max_condition: f32,
    /// Largest condition number of the translation block of a JᵀJ whose step is taken; at
    /// level 0, of a tracked frame.
    pub max_translation_condition: f32,
    /// Length that scales the rotation columns for the condition number, metres.
    pub rotation_scale_m: f32,
    /// Largest plausible inter-frame translation, metres.
    pub max_jump_m: f32,
    /// Largest plausible inter-frame rotation, radians.
    pub max_jump_rad: f32,
    /// Largest correction ICP may make to a reseeded (relocalised) pose, metres.
    pub max_reseed_correction_m: f32,
    /// Largest rotation ICP may apply to a reseeded pose, radians.
    pub max_reseed_correction_rad: f32,
    /// Huber threshold on point-to-plane residuals, metres (0: plain least squares).
    pub huber_delta_m: f32,
    /// Weight pairs by the Kinect noise model: geometric rows by the axial noise at their depth
    /// (far points count less), photometric rows by its incidence term (grazing surfaces and
    /// silhouettes count less).
    pub noise_weighting: bool,
    /// Weight of the photometric (previous-frame intensity) term; 0 turns it off.
    pub rgb_weight: f32,
    /// Largest accepted intensity residual of the photometric term.
    pub rgb_max_residual: f32,
    /// Largest depth disagreement of a photometric pair, metres.
    pub rgb_max_depth_diff_m: f32,
    /// Convergence: the level-0 update bound below which a level stops, metres.
    pub converged_update_m: f32,
    /// Depth at which rotations become displacements for the convergence test, metres.
    pub reference_depth_m: f32,
    /// Start each frame from the previous pose advanced by the last inter-frame motion
    /// (constant velocity) instead of the previous pose.
    pub constant_velocity: bool,
}

impl Default for IcpConfig {
    fn default() -> Self {
        Self {
            iterations_per_level: DEFAULT_ICP_ITERATIONS.to_vec(),
            dist_thresh_m: DEFAULT_ICP_DIST_THRESH_M,
            angle_thresh_rad: DEFAULT_ICP_ANGLE_THRESH_RAD,
            min_inlier_fraction: DEFAULT_MIN_INLIER_FRACTION,
            max_condition: DEFAULT_MAX_CONDITION,
            max_translation_condition: DEFAULT_MAX_TRANSLATION_CONDITION,
            rotation_scale_m: DEFAULT_ROTATION_SCALE_M,
            max_jump_m: DEFAULT_MAX_JUMP_M,
            max_jump_rad: DEFAULT_MAX_JUMP_RAD,
            max_reseed_correction_m: DEFAULT_MAX_RESEED_CORRECTION_M,
            max_reseed_correction_rad: DEFAULT_MAX_RESEED_CORRECTION_RAD,
            constant_velocity: false,
            huber_delta_m: DEFAULT_HUBER_DELTA_M,
            rgb_weight: DEFAULT_RGB_WEIGHT,
            rgb_max_residual: DEFAULT_RGB_MAX_RESIDUAL,
            rgb_max_depth_diff_m: DEFAULT_RGB_MAX_DEPTH_DIFF_M,
            converged_update_m: DEFAULT_CONVERGED_UPDATE_M,
            reference_depth_m: DEFAULT_REFERENCE_DEPTH_M,
            noise_weighting: true,
        }
    }
}

/// Settings of the whole pipeline.
#[derive(Clone, Debug, PartialEq)]
pub struct FusionConfig {
    /// Depth preprocessing.
    pub preprocess: PreprocessConfig,
    /// The TSDF volume.
    pub tsdf: TsdfConfig,
    /// Tracking.
    pub icp: IcpConfig,
}

impl Default for FusionConfig {
    /// KinectFusion's preprocessing (bilateral filter, pyramid, central-difference normals):
    /// without 003's gradient smoothing, which only sharpens the frame's normals, and those
    /// serve tracking for the 20° angle test alone (the rows use the model's normals), so the
    /// smoothing costs a third of the preprocessing for no accuracy (measured: the same ATE to
    /// 0.01 cm on both shared sequences).
    fn default() -> Self {
        Self { preprocess: PreprocessConfig { gradient_smoothing: None, ..PreprocessConfig::default() }, tsdf: TsdfConfig::default(), icp: IcpConfig::default() }
    }
}

impl FusionConfig {
    /// These settings for a source whose depth has `noise` (what the source says of its
    /// sensor): exact depth (a simulated log without noise) is tracked without the Kinect
    /// model's weights, every depth being measured as well as any other (weighting would only
    /// throw away the far points' leverage), and fused with a truncation band of μ at every
    /// depth unless `keep_band` (a band the user or a loaded map chose). A Kinect's depth
    /// keeps them as they are.
    pub fn for_depth_noise(mut self, noise: crate::source::DepthNoise, keep_band: bool) -> Self {
        if noise == crate::source::DepthNoise::None {
            self.icp.noise_weighting = false;
            if !keep_band {
                self.tsdf.noise_band_sigmas = 0.0;
            }
        }
        self
    }

    /// Rejects settings the pipeline cannot honour, naming the offending one.
    pub fn validate(&self) -> Result<()> {
        self.preprocess.validate()?;
        // The device's binding limit is checked again when the volume is allocated.
        self.tsdf.validate(u64::MAX)?;
        let icp = &self.icp;
        let levels = icp.iterations_per_level.len();
        let bad = |m: String| Err(Error::InvalidConfig(m));
        if levels == 0 || levels > self.preprocess.pyramid_levels {
            return bad(format!("ICP uses {levels} levels but preprocessing builds {}", self.preprocess.pyramid_levels));
        }
        if icp.iterations_per_level.iter().all(|&n| n == 0) {
            return bad("ICP needs at least one iteration".into());
        }
        if icp.iterations_per_level.iter().any(|&n| n > 100) {
            return bad(format!("ICP iterations {:?}: at most 100 per level", icp.iterations_per_level));
        }
        let positive = |v: f32| v > 0.0 && v.is_finite();
        let non_negative = |v: f32| v >= 0.0 && v.is_finite();
        if !non_negative(icp.huber_delta_m) {
            return bad(format!("the Huber threshold must be >= 0 m, got {}", icp.huber_delta_m));
        }
        if !positive(icp.dist_thresh_m) || !positive(icp.angle_thresh_rad) {
            return bad(format!("ICP thresholds must be positive, got {} m and {} rad", icp.dist_thresh_m, icp.angle_thresh_rad));
        }
        if !non_negative(icp.rgb_weight) || !positive(icp.rgb_max_residual) || !positive(icp.rgb_max_depth_diff_m) {
            return bad(format!("photometric weight {} must be >= 0 and its thresholds positive", icp.rgb_weight));
        }
        if !positive(icp.converged_update_m) || !positive(icp.reference_depth_m) {
            return bad("the convergence threshold and reference depth must be positive".into());
        }
        if !(icp.min_inlier_fraction >= 0.0 && icp.min_inlier_fraction <= 1.0) {
            return bad(format!("the inlier fraction {} must be in [0, 1]", icp.min_inlier_fraction));
        }
        if !positive(icp.max_condition) || !positive(icp.max_translation_condition) || !positive(icp.max_jump_m) || !positive(icp.max_jump_rad) || !positive(icp.rotation_scale_m) || !positive(icp.max_reseed_correction_m) || !positive(icp.max_reseed_correction_rad) {
            return bad("the lost-frame limits must be positive".into());
        }
        Ok(())
    }
}

/// Why a frame was not tracked.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LostReason {
    /// Too few correspondences at the finest level.
    TooFewInliers {
        /// Pairs found.
        inliers: u64,
        /// Pairs required.
        required: u64,
    },
    /// The finest level's scaled normal equations were (nearly) singular: the geometry does
    /// not constrain all six degrees of freedom (e.g. a single plane, a corridor).
    IllConditioned {
        /// Largest / smallest eigenvalue of the scaled JᵀJ (see [`DEFAULT_MAX_CONDITION`]).
        condition: f64,
        /// Largest / smallest eigenvalue of its translation block (see
        /// [`DEFAULT_MAX_TRANSLATION_CONDITION`]).
        translation_condition: f64,
    },
    /// The estimated motion since the last tracked frame is implausibly large.
    ImplausibleJump {
        /// Translation, metres.
        translation_m: f64,
        /// Rotation, radians.
        rotation_rad: f64,
    },
    /// Not tracked at all: so long after the last tracked frame that ICP from its pose could
    /// converge to a false fit its checks pass, and no feature pose to start from
    /// (`odometry::assist::MAX_UNSEEDED_GAP_S`).
    Unverified {
        /// Seconds since the last tracked frame (negative where the clock jumped back).
        gap_s: f64,
    },
}

/// Outcome of tracking one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TrackingState {
    /// The first frame: it defines the world frame.
    Initialised,
    /// Tracked.
    Tracked,
    /// Tracked again after one or more lost frames.
    Recovered,
    /// Not tracked: the pose is the last good one and the frame was not fused.
    Lost(LostReason),
}

impl TrackingState {
    /// Whether the frame was not fused.
    pub fn is_lost(&self) -> bool {
        matches!(self, Self::Lost(_))
    }

    /// Short name for logs and status JSON.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Initialised => "initialised",
            Self::Tracked => "tracked",
            Self::Recovered => "recovered",
            Self::Lost(_) => "lost",
        }
    }
}

/// ICP statistics of one pyramid level.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct IcpLevelStats {
    /// Pyramid level (0 = full resolution).
    pub level: usize,
    /// Iterations run.
    pub iterations: u32,
    /// Correspondences in the last iteration.
    pub inliers: u64,
    /// Photometric pairs in the last iteration.
    pub rgb_pairs: u64,
    /// RMS point-to-plane residual of the last iteration, metres.
    pub rms_residual_m: f64,
    /// Condition number of the last iteration's scaled system.
    pub condition: f64,
    /// Condition number of its translation block.
    pub translation_condition: f64,
    /// Bound on the last update's displacement, metres.
    pub last_update_m: f64,
}

/// Time of each stage of one frame, milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimesMs {
    /// Preprocessing.
    pub preprocess: f64,
    /// Tracking (every level and iteration, the solves included).
    pub track: f64,
    /// TSDF integration.
    pub integrate: f64,
    /// Surface prediction and keeping the reference.
    pub raycast: f64,
    /// A feature pass recorded into the frame ([`KinectFusion::submit_frame_with`]): its
    /// [`FEATURE_STAGES`] (0 without one).
    pub features: [f64; 4],
    /// The whole frame.
    pub total: f64,
}

/// The stages a feature pass records into a frame (`odometry::gpu::FeatureExtractor`'s, which
/// names them from this list), in [`StageTimesMs::features`]' order.
pub const FEATURE_STAGES: [&str; 4] = ["detection", "description", "matching", "estimation"];

impl StageTimesMs {
    /// From the GPU times of the frame's stages.
    pub fn from_stages(stages: &[StageTime]) -> Self {
        let get = |name: &str| stages.iter().filter(|s| s.name == name).map(|s| s.gpu_ms).sum::<f64>();
        Self { preprocess: get("preprocess"), track: get("track"), integrate: get("integrate"), raycast: get("predict"), features: FEATURE_STAGES.map(get), total: stages.iter().map(|s| s.gpu_ms).sum() }
    }
}

/// What the pipeline reports about one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameReport {
    /// The frame's index in its source.
    pub index: u64,
    /// The camera pose used for this frame (the last good one when lost).
    pub world_from_camera: Se3,
    /// Tracking outcome.
    pub state: TrackingState,
    /// ICP statistics, coarsest level first (empty for the first frame).
    pub icp: Vec<IcpLevelStats>,
    /// GPU time per stage from timestamp queries, when the device has them.
    pub gpu_ms: Option<StageTimesMs>,
    /// Host time to upload, record and submit the frame, milliseconds.
    pub encode_ms: f64,
    /// Wall clock from the start of the submission to the report's collection, milliseconds
    /// (includes the time the report waited for the next frame's submission to be collected).
    pub latency_ms: f64,
    /// What the host did with the GPU while submitting this frame: submissions, waits (0
    /// unless every readback slot was in flight) and readbacks (1: its summary).
    pub host: GpuCounts,
    /// A sparse map's counters after this frame (read back with the frame's summary): blocks
    /// used and any exhaustion; `None` for a dense map.
    pub map: Option<MapStats>,
    /// What a pass recorded into the frame copied for the host ([`PassSummary`],
    /// [`PASS_SUMMARY_BYTES`]); empty for a frame without one.
    pub pass_summary: Vec<u8>,
}

/// What a frame's readback slot carries besides its bytes.
#[derive(Debug)]
struct FrameTag {
    index: u64,
    run: u64,
    stages: Vec<&'static str>,
    submitted_at: Instant,
    encode_ms: f64,
    host: GpuCounts,
    /// A pass recorded into the frame wrote a summary.
    with_summary: bool,
}

/// Byte offset of the timestamps in a frame's readback (after the `TrackState`).
const TIMESTAMPS_OFFSET: u64 = tracker::TRACK_STATE_BYTES.next_multiple_of(8);
/// Byte offset of a sparse map's counters in a frame's readback (after the timestamps).
const MAP_COUNTERS_OFFSET: u64 = TIMESTAMPS_OFFSET + StageTimer::BYTES;
/// Bytes of a sparse map's counters.
const MAP_COUNTERS_BYTES: u64 = (crate::cpu::shared::MAP_COUNTERS * 4) as u64;
/// Byte offset of a pass's summary in a frame's readback (after the map's counters).
const PASS_SUMMARY_OFFSET: u64 = MAP_COUNTERS_OFFSET + MAP_COUNTERS_BYTES;
/// Bytes a pass recorded into the frame ([`KinectFusion::submit_frame_with`]) may have read
/// back with the frame's report ([`FrameReport::pass_summary`]).
pub const PASS_SUMMARY_BYTES: u64 = 256;
/// Bytes of a frame's readback.
const READBACK_BYTES: u64 = PASS_SUMMARY_OFFSET + PASS_SUMMARY_BYTES;

/// A pass recorded into a frame between preprocessing and tracking
/// ([`KinectFusion::submit_frame_with`]).
pub type FramePass<'p> = dyn FnMut(&mut FrameEncoder<'_>, &PassSummary<'_>) + 'p;

/// Where a pass recorded into a frame ([`KinectFusion::submit_frame_with`]) copies what the
/// host needs of it, so that it arrives with the frame's report in the frame's one readback.
#[derive(Debug)]
pub struct PassSummary<'a> {
    buffer: &'a wgpu::Buffer,
}

impl PassSummary<'_> {
    /// Records a copy of `source`'s first `bytes` into the summary.
    ///
    /// # Panics
    /// If `bytes` exceeds [`PASS_SUMMARY_BYTES`] or is not a multiple of 4 (a bug in the pass).
    pub fn copy_from(&self, encoder: &mut wgpu::CommandEncoder, source: &wgpu::Buffer, bytes: u64) {
        assert!(bytes <= PASS_SUMMARY_BYTES && bytes.is_multiple_of(4), "a pass summary of {bytes} bytes");
        encoder.copy_buffer_to_buffer(source, 0, self.buffer, PASS_SUMMARY_OFFSET, bytes);
    }
}

/// The KinectFusion pipeline on one GPU, for one camera.
#[derive(Debug)]
pub struct KinectFusion {
    config: FusionConfig,
    preprocessor: DepthPreprocessor,
    tracker: IcpTracker,
    mapper: Mapper,
    predictor: Predictor,
    timer: Option<StageTimer>,
    readbacks: ReadbackRing<FrameTag>,
    reports: VecDeque<FrameReport>,
    run: u64,
    frames_submitted: usize,
    last_pose: Se3,
    /// The pose of the last frame tracked (what a lost frame reports, also after a reseed that
    /// its frame did not confirm).
    last_good_pose: Se3,
}

impl KinectFusion {
    /// Allocates the pipeline for `calibration`'s camera. The first frame's camera defines the
    /// world frame, and the volume is placed relative to it by the config's placement.
    pub fn new(gpu: &Gpu, calibration: RgbdCalibration, config: FusionConfig) -> Result<Self> {
        let origin = config.tsdf.origin_for_first_camera(&Se3::IDENTITY);
        Self::new_at(gpu, calibration, config, origin)
    }

    /// [`Self::new`] with the map's box corner at `origin` in the world (a loaded map's; the
    /// first frame then needs an initial guess in that world, [`Self::set_initial_guess`]).
    pub fn new_at(gpu: &Gpu, calibration: RgbdCalibration, config: FusionConfig, origin: [f32; 3]) -> Result<Self> {
        config.validate()?;
        let preprocessor = DepthPreprocessor::new(gpu, calibration, config.preprocess)?;
        // The tracker's state buffer is the pose source of the mapper and predictor: they are
        // built around it, then the tracker around the predictor's maps.
        let state = tracker::state_buffer(gpu);
        let mapper = Mapper::new(gpu, config.tsdf, origin, &preprocessor, &state)?;
        let depth_range = (config.preprocess.min_depth_m, config.preprocess.max_depth_m);
        let predictor = Predictor::new(gpu, mapper.volume(), preprocessor.levels[0].intrinsics, config.icp.iterations_per_level.len(), &state, Some(DepthHint::from_preprocessor(&preprocessor)), depth_range);
        let tracker = IcpTracker::new(gpu, &config.icp, &preprocessor, &predictor, state)?;
        let timer = StageTimer::new(gpu, "core.fusion");
        let readbacks = ReadbackRing::new(gpu, "core.fusion", READBACK_BYTES, MAX_FRAMES_IN_FLIGHT);
        Ok(Self { config, preprocessor, tracker, mapper, predictor, timer, readbacks, reports: VecDeque::new(), run: 0, frames_submitted: 0, last_pose: Se3::IDENTITY, last_good_pose: Se3::IDENTITY })
    }

    /// The settings.
    pub fn config(&self) -> &FusionConfig {
        &self.config
    }

    /// The TSDF store (for mesh extraction and free-view raycasts).
    pub fn volume(&self) -> &Map {
        self.mapper.volume()
    }

    /// The preprocessing chain (its buffers feed the views).
    pub fn preprocessor(&self) -> &DepthPreprocessor {
        &self.preprocessor
    }

    /// The predicted surface at full resolution, rendered from the last tracked pose.
    pub fn prediction(&self) -> &RaycastTarget {
        self.predictor.finest()
    }

    /// The tracker (its state buffer holds the current pose on the GPU).
    pub fn tracker(&self) -> &IcpTracker {
        &self.tracker
    }

    /// The mapper (the TSDF store and its integration).
    pub fn mapper(&self) -> &Mapper {
        &self.mapper
    }

    /// The mapper, mutably (to load a saved map, or gather a swapping map's blocks).
    pub fn mapper_mut(&mut self) -> &mut Mapper {
        &mut self.mapper
    }

    /// The predictor (the prediction pyramid).
    pub fn predictor(&self) -> &Predictor {
        &self.predictor
    }

    /// The pose of the last frame whose report was collected (the last good one after a loss).
    pub fn world_from_camera(&self) -> Se3 {
        self.last_pose
    }

    /// Frames submitted since the last reset.
    pub fn frames_submitted(&self) -> usize {
        self.frames_submitted
    }

    /// Whether reports carry GPU stage times (the device has timestamp queries).
    pub fn timer_available(&self) -> bool {
        self.timer.is_some()
    }

    /// Frames whose readback is still in flight.
    pub fn frames_in_flight(&self) -> usize {
        self.readbacks.in_flight()
    }

    /// Forgets the model and the trajectory: the next frame starts a new world frame. Reports
    /// of frames still in flight are dropped.
    pub fn reset(&mut self, gpu: &Gpu) {
        self.mapper.reset(gpu);
        self.tracker.reset(gpu);
        self.run += 1;
        self.frames_submitted = 0;
        self.reports.clear();
        self.last_pose = Se3::IDENTITY;
        self.last_good_pose = Se3::IDENTITY;
    }

    /// Starts the next frame's tracking from `world_from_camera` (e.g. given poses used as an
    /// initial guess).
    pub fn set_initial_guess(&self, gpu: &Gpu, world_from_camera: &Se3) {
        self.tracker.set_guess(gpu, world_from_camera);
    }

    /// Relocalises the camera at `world_from_camera` (found by feature matching after tracking
    /// was lost): the tracker's reference moves there ([`IcpTracker::reseed`]) and the model is
    /// rendered there in a submission of its own, so the next frame is tracked against what the
    /// map holds at that pose and is Recovered when it checks out (its jump measured from that
    /// pose). A relocalisation that the next frame does not confirm is undone by reseeding at
    /// the last good pose. Map blocks swapped out around that pose come back with the next
    /// frame, not for this render.
    pub fn reseed(&mut self, gpu: &Gpu, world_from_camera: &Se3) -> Result<()> {
        gpu.check_lost()?;
        self.tracker.reseed(gpu, world_from_camera);
        let mut fe = FrameEncoder::new(gpu, "core.fusion.reseed", None);
        self.predictor.encode(gpu, &mut fe, "predict");
        let (commands, _) = fe.finish(None);
        gpu.submit([commands]);
        self.last_pose = *world_from_camera;
        Ok(())
    }

    /// Uploads `frame` and submits its whole pipeline as one command buffer. Never waits for
    /// the GPU unless [`MAX_FRAMES_IN_FLIGHT`] readbacks are pending (then for the oldest).
    /// Reports arrive through [`Self::poll_reports`] or [`Self::flush`].
    pub async fn submit_frame(&mut self, gpu: &Gpu, frame: &RgbdFrame) -> Result<()> {
        self.submit(gpu, frame, true, None).await.map(drop)
    }

    /// [`Self::submit_frame`] with another pass recorded into the same submission between the
    /// preprocessing and the tracking (feature odometry: it reads the preprocessed images and
    /// may set the tracker's guess on the GPU, `feature_guess`). Returns the submission, for
    /// a readback of the pass's own; what the host needs every frame the pass copies into the
    /// frame's readback ([`PassSummary`]). Its stages are timed with the frame's
    /// ([`StageTimesMs::features`]).
    pub async fn submit_frame_with(&mut self, gpu: &Gpu, frame: &RgbdFrame, before_tracking: &mut FramePass<'_>) -> Result<wgpu::SubmissionIndex> {
        self.submit(gpu, frame, true, Some(before_tracking)).await
    }

    /// [`Self::submit_frame`] for a frame that a pass sharing this pipeline's preprocessor
    /// ([`Self::preprocessor`]; feature extraction) already uploaded and preprocessed in an
    /// earlier submission: the frame skips both.
    pub async fn submit_preprocessed_frame(&mut self, gpu: &Gpu, frame: &RgbdFrame) -> Result<()> {
        self.submit(gpu, frame, false, None).await.map(drop)
    }

    async fn submit(&mut self, gpu: &Gpu, frame: &RgbdFrame, preprocess: bool, before_tracking: Option<&mut FramePass<'_>>) -> Result<wgpu::SubmissionIndex> {
        gpu.check_lost()?;
        let started = Instant::now();
        let before = gpu.counters.snapshot();
        while self.readbacks.free_slot().is_none() {
            if let Some(done) = self.readbacks.wait_oldest(gpu).await? {
                self.finish_report(done.tag, &done.bytes)?;
            }
        }
        if preprocess {
            self.preprocessor.upload(gpu, frame)?;
        }
        self.mapper.poll(gpu)?;
        self.mapper.prepare_frame(gpu, Some(&self.last_pose));
        let mut fe = FrameEncoder::new(gpu, "core.fusion.frame", self.timer.as_ref());
        if preprocess {
            self.preprocessor.encode_in(gpu, &mut fe.stage("preprocess"));
        }
        let (slot, slot_buffer) = self.readbacks.free_slot().expect("a readback slot was freed above");
        let with_summary = before_tracking.is_some();
        if let Some(record) = before_tracking {
            record(&mut fe, &PassSummary { buffer: slot_buffer });
        }
        {
            // Tracking, then the tracker keeps this frame as the next one's reference.
            let mut pass = fe.stage("track");
            self.tracker.encode_in(gpu, &mut pass, self.frames_submitted == 0);
            self.tracker.encode_keep_previous(gpu, &mut pass);
        }
        self.mapper.encode(gpu, &mut fe, "integrate");
        self.predictor.encode(gpu, &mut fe, "predict");
        fe.encoder().copy_buffer_to_buffer(self.tracker.state_buffer(), 0, slot_buffer, 0, tracker::TRACK_STATE_BYTES);
        if let Some(map) = self.mapper.sparse() {
            fe.encoder().copy_buffer_to_buffer(map.counters(), 0, slot_buffer, MAP_COUNTERS_OFFSET, MAP_COUNTERS_BYTES);
        }
        let (commands, stages) = fe.finish(Some((slot_buffer, TIMESTAMPS_OFFSET)));
        let submission = gpu.submit([commands]);
        let returned = submission.clone();
        self.mapper.frame_submitted(gpu, &submission);
        let mut host = gpu.counters.snapshot() - before;
        host.readbacks += 1;
        let tag = FrameTag { index: frame.index, run: self.run, stages, submitted_at: started, encode_ms: ms_since(started), host, with_summary };
        self.readbacks.start(gpu, slot, submission, tag);
        self.frames_submitted += 1;
        for done in self.readbacks.collect(gpu)? {
            self.finish_report(done.tag, &done.bytes)?;
        }
        Ok(returned)
    }

    /// Reports of frames whose readback completed, oldest first (never waits).
    pub fn poll_reports(&mut self, gpu: &Gpu) -> Result<Vec<FrameReport>> {
        self.mapper.poll(gpu)?;
        for done in self.readbacks.collect(gpu)? {
            self.finish_report(done.tag, &done.bytes)?;
        }
        Ok(self.reports.drain(..).collect())
    }

    /// Waits for every frame in flight and returns all pending reports, oldest first.
    pub async fn flush(&mut self, gpu: &Gpu) -> Result<Vec<FrameReport>> {
        while let Some(done) = self.readbacks.wait_oldest(gpu).await? {
            self.finish_report(done.tag, &done.bytes)?;
        }
        self.mapper.flush(gpu).await?;
        Ok(self.reports.drain(..).collect())
    }

    /// Tracks, fuses and predicts one frame and waits for its report (one host wait per frame:
    /// for tests and one-shot tools; streaming callers use [`Self::submit_frame`]).
    pub async fn process_frame(&mut self, gpu: &Gpu, frame: &RgbdFrame) -> Result<FrameReport> {
        self.submit_frame(gpu, frame).await?;
        let reports = self.flush(gpu).await?;
        reports.into_iter().rev().find(|r| r.index == frame.index).ok_or_else(|| Error::Poll(format!("frame {} produced no report", frame.index)))
    }

    fn finish_report(&mut self, tag: FrameTag, bytes: &[u8]) -> Result<()> {
        if tag.run != self.run {
            return Ok(());
        }
        let state: TrackState = bytemuck::pod_read_unaligned(&bytes[..tracker::TRACK_STATE_BYTES as usize]);
        let gpu_ms = self.timer.as_ref().map(|timer| {
            let n = 2 * tag.stages.len();
            let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes[TIMESTAMPS_OFFSET as usize..][..8 * n]);
            StageTimesMs::from_stages(&timer.stage_times(&tag.stages, &ticks))
        });
        let mut report = report_from_state(&state, &self.config, self.preprocessor.levels[0].intrinsics.pixel_count(), tag.index, gpu_ms, tag.encode_ms, ms_since(tag.submitted_at), tag.host);
        if tag.with_summary {
            report.pass_summary = bytes[PASS_SUMMARY_OFFSET as usize..READBACK_BYTES as usize].to_vec();
        }
        report.map = self.mapper.sparse().map(|m| {
            let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[MAP_COUNTERS_OFFSET as usize..PASS_SUMMARY_OFFSET as usize]);
            MapStats::from_words(&words, m.desc().pool_blocks)
        });
        if let Some(stats) = &mut report.map {
            self.mapper.on_report(stats);
        }
        // A lost frame publishes the tracker's reference, which a reseed may have moved: it
        // reports the last tracked pose instead.
        if report.state.is_lost() {
            report.world_from_camera = self.last_good_pose;
        } else {
            self.last_good_pose = report.world_from_camera;
        }
        self.last_pose = report.world_from_camera;
        self.reports.push_back(report);
        Ok(())
    }
}

/// The frame report a read-back `TrackState` describes.
#[expect(clippy::too_many_arguments, reason = "the state plus what the host measured around it")]
pub fn report_from_state(state: &TrackState, config: &FusionConfig, pixels: usize, index: u64, gpu_ms: Option<StageTimesMs>, encode_ms: f64, latency_ms: f64, host: GpuCounts) -> FrameReport {
    let finest = state.levels[0];
    let tracking = match state.outcome {
        outcome::INITIALISED => TrackingState::Initialised,
        outcome::TRACKED => TrackingState::Tracked,
        outcome::RECOVERED => TrackingState::Recovered,
        outcome::LOST_TOO_FEW_INLIERS => {
            let required = (config.icp.min_inlier_fraction * pixels as f64).ceil() as u64;
            TrackingState::Lost(LostReason::TooFewInliers { inliers: u64::from(finest.inliers), required })
        }
        outcome::LOST_ILL_CONDITIONED => {
            TrackingState::Lost(LostReason::IllConditioned { condition: f64::from(finest.condition), translation_condition: f64::from(finest.translation_condition) })
        }
        _ => TrackingState::Lost(LostReason::ImplausibleJump { translation_m: f64::from(state.jump_translation_m), rotation_rad: f64::from(state.jump_rotation_rad) }),
    };
    let icp = if tracking == TrackingState::Initialised {
        Vec::new()
    } else {
        (0..config.icp.iterations_per_level.len())
            .rev()
            .map(|l| {
                let s = state.levels[l];
                IcpLevelStats {
                    level: l,
                    iterations: s.iterations,
                    inliers: u64::from(s.inliers),
                    rgb_pairs: u64::from(s.rgb_pairs),
                    rms_residual_m: f64::from(s.rms_residual_m),
                    condition: f64::from(s.condition),
                    translation_condition: f64::from(s.translation_condition),
                    last_update_m: f64::from(s.last_update_m),
                }
            })
            .collect()
    };
    FrameReport { index, world_from_camera: Se3::from_cols_f32(&state.pose.world_from_camera), state: tracking, icp, gpu_ms, encode_ms, latency_ms, host, map: None, pass_summary: Vec::new() }
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::DepthNoise;

    #[test]
    fn exact_depth_is_tracked_unweighted_and_fused_with_mu_and_a_kinects_keeps_the_model() {
        let kinect = FusionConfig::default();
        assert!(kinect.icp.noise_weighting && kinect.tsdf.noise_band_sigmas == crate::tsdf::DEFAULT_NOISE_BAND_SIGMAS, "the defaults are a Kinect's");
        assert_eq!(kinect.clone().for_depth_noise(DepthNoise::KinectV1, false), kinect, "a Kinect's depth changes nothing");
        let exact = kinect.clone().for_depth_noise(DepthNoise::None, false);
        assert!(!exact.icp.noise_weighting && exact.tsdf.noise_band_sigmas == 0.0, "exact depth: unweighted, band μ");
        let kept = kinect.clone().for_depth_noise(DepthNoise::None, true);
        assert!(!kept.icp.noise_weighting && kept.tsdf.noise_band_sigmas == kinect.tsdf.noise_band_sigmas, "a chosen band stays");
        assert!(exact.validate().is_ok());
    }
}
