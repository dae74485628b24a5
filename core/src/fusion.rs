// SPDX-License-Identifier: MIT
//! KinectFusion (000-digest §1.3, §2.3): per frame, preprocess the depth, track the camera
//! against the model's predicted surface with coarse-to-fine point-to-plane ICP, fuse the depth
//! into the TSDF at the tracked pose, and raycast the model from that pose to predict the next
//! frame's surface.
//!
//! Everything heavy runs in WGSL kernels; the host only solves the 6x6 normal equations of each
//! ICP iteration (Cholesky, f64) from the per-workgroup partial sums `icp_reduce` writes. The
//! API is async so the same code drives the browser (WebGPU) and native (Vulkan) builds.

use glam::{DQuat, DVec3};
use nalgebra::{Matrix6, SymmetricEigen, Vector6};
use web_time::Instant;

use crate::kernels::icp_reduce::{self, IcpReduceParams, SUM_FLOATS};
use crate::kernels::intensity_pyramid_down::{self, IntensityPyramidDownParams};
use crate::kernels::rgb_reduce::{self, RgbReduceParams};
use crate::kernels::raycast::{self, RaycastParams};
use crate::kernels::tsdf_integrate::{self, TsdfIntegrateParams};
use crate::kernels::GpuIntrinsics;
use crate::preprocess::{DepthPreprocessor, PreprocessConfig};
use crate::tsdf::{DenseTsdfVolume, TsdfConfig, TsdfStore};
use crate::{Error, Gpu, PinholeIntrinsics, Result, RgbdCalibration, RgbdFrame, Se3};

/// Default ICP iterations per pyramid level, finest first (KinectFusion's 10/5/4).
pub const DEFAULT_ICP_ITERATIONS: [u32; 3] = [10, 5, 4];
/// Default largest distance between corresponding points, metres.
pub const DEFAULT_ICP_DIST_THRESH_M: f32 = 0.10;
/// Default largest angle between corresponding normals, radians (20°).
pub const DEFAULT_ICP_ANGLE_THRESH_RAD: f32 = 20.0 * std::f32::consts::PI / 180.0;
/// Default smallest fraction of the finest level's pixels that must pair up for a frame to
/// count as tracked.
pub const DEFAULT_MIN_INLIER_FRACTION: f64 = 0.05;
/// Default largest ratio of the normal matrix's largest to smallest eigenvalue (in units where
/// the translation rows are scaled to the rotation rows by 1 m).
pub const DEFAULT_MAX_CONDITION: f64 = 1e7;
/// Default largest plausible translation between consecutive frames, metres.
pub const DEFAULT_MAX_JUMP_M: f64 = 0.20;
/// Default largest plausible rotation between consecutive frames, radians (25°).
pub const DEFAULT_MAX_JUMP_RAD: f64 = 25.0 * std::f64::consts::PI / 180.0;
/// Default Huber threshold on point-to-plane residuals, metres.
pub const DEFAULT_HUBER_DELTA_M: f32 = 0.03;
/// Default weight of the photometric term against the geometric one (0: depth only). The
/// geometric rows are in metres and the photometric ones in intensity units ([0, 1]).
pub const DEFAULT_RGB_WEIGHT: f32 = 0.03;
/// Default largest accepted intensity residual.
pub const DEFAULT_RGB_MAX_RESIDUAL: f32 = 0.3;
/// Default largest depth disagreement for a photometric pair (visibility test), metres.
pub const DEFAULT_RGB_MAX_DEPTH_DIFF_M: f32 = 0.05;
/// ICP stops a level early once an update is smaller than this (radians and metres).
pub const DEFAULT_CONVERGED_UPDATE: f64 = 1e-6;

/// ICP tracking settings.
#[derive(Clone, Debug, PartialEq)]
pub struct IcpConfig {
    /// Iterations per pyramid level, finest (level 0) first; its length is the number of
    /// levels used, at most the preprocessing pyramid's.
    pub iterations_per_level: Vec<u32>,
    /// Largest distance between corresponding points, metres.
    pub dist_thresh_m: f32,
    /// Largest angle between corresponding normals, radians.
    pub angle_thresh_rad: f32,
    /// Smallest fraction of level-0 pixels that must pair up.
    pub min_inlier_fraction: f64,
    /// Largest acceptable eigenvalue ratio of JᵀJ.
    pub max_condition: f64,
    /// Largest plausible inter-frame translation, metres.
    pub max_jump_m: f64,
    /// Largest plausible inter-frame rotation, radians.
    pub max_jump_rad: f64,
    /// Huber threshold on point-to-plane residuals, metres (0: plain least squares).
    pub huber_delta_m: f32,
    /// Weight pairs by the Kinect axial noise model (far points count less).
    pub noise_weighting: bool,
    /// Weight of the photometric (previous-frame intensity) term; 0 turns it off.
    pub rgb_weight: f32,
    /// Largest accepted intensity residual of the photometric term.
    pub rgb_max_residual: f32,
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
            max_jump_m: DEFAULT_MAX_JUMP_M,
            max_jump_rad: DEFAULT_MAX_JUMP_RAD,
            constant_velocity: false,
            huber_delta_m: DEFAULT_HUBER_DELTA_M,
            rgb_weight: DEFAULT_RGB_WEIGHT,
            rgb_max_residual: DEFAULT_RGB_MAX_RESIDUAL,
            noise_weighting: true,
        }
    }
}

/// Settings of the whole pipeline.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct FusionConfig {
    /// Depth preprocessing.
    pub preprocess: PreprocessConfig,
    /// The TSDF volume.
    pub tsdf: TsdfConfig,
    /// Tracking.
    pub icp: IcpConfig,
}

impl FusionConfig {
    /// Rejects settings the pipeline cannot honour.
    pub fn validate(&self) -> Result<()> {
        self.preprocess.validate()?;
        // The device's binding limit is checked again when the volume is allocated.
        self.tsdf.validate(u64::MAX)?;
        let levels = self.icp.iterations_per_level.len();
        if levels == 0 || levels > self.preprocess.pyramid_levels {
            return Err(Error::InvalidConfig(format!("ICP uses {levels} levels but preprocessing builds {}", self.preprocess.pyramid_levels)));
        }
        if self.icp.iterations_per_level.iter().all(|&n| n == 0) {
            return Err(Error::InvalidConfig("ICP needs at least one iteration".into()));
        }
        if !(self.icp.huber_delta_m >= 0.0) {
            return Err(Error::InvalidConfig("the Huber threshold must be >= 0".into()));
        }
        if !(self.icp.dist_thresh_m > 0.0) || !(self.icp.angle_thresh_rad > 0.0) {
            return Err(Error::InvalidConfig("ICP thresholds must be positive".into()));
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
    /// The normal equations were (nearly) singular: the geometry does not constrain all six
    /// degrees of freedom (e.g. a single plane).
    IllConditioned {
        /// Largest / smallest eigenvalue.
        condition: f64,
    },
    /// The estimated motion since the last tracked frame is implausibly large.
    ImplausibleJump {
        /// Translation, metres.
        translation_m: f64,
        /// Rotation, radians.
        rotation_rad: f64,
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
    /// Whether the frame was fused.
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
    /// RMS point-to-plane residual of the last iteration, metres.
    pub rms_residual_m: f64,
}

/// Wall-clock time of each stage of one frame, milliseconds (submit to completion).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimesMs {
    /// Upload and preprocessing.
    pub preprocess: f64,
    /// ICP (all levels and iterations, readbacks and solves included).
    pub track: f64,
    /// TSDF integration.
    pub integrate: f64,
    /// Surface prediction (all levels).
    pub raycast: f64,
    /// The whole frame.
    pub total: f64,
}

/// What [`KinectFusion::process_frame`] reports.
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
    /// Stage timings.
    pub times_ms: StageTimesMs,
}

/// Images rendered by `raycast` at one resolution.
#[derive(Debug)]
pub struct RaycastTarget {
    /// Intrinsics of the images.
    pub intrinsics: PinholeIntrinsics,
    /// Surface points (x, y, z, 1), world frame.
    pub vertex_in_world: wgpu::Buffer,
    /// Unit normals, world frame.
    pub normal_in_world: wgpu::Buffer,
    /// Depth along the camera's z, metres (NaN: no surface): the virtual depth sensor.
    pub depth_m: wgpu::Buffer,
    /// Headlight-shaded grey, RGBA8 per pixel.
    pub shaded_rgba8: wgpu::Buffer,
    /// Model colour, RGBA8 per pixel.
    pub color_rgba8: wgpu::Buffer,
    params: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

impl RaycastTarget {
    /// Allocates the images for `intrinsics` and binds them to `store`.
    pub fn new(gpu: &Gpu, store: &dyn TsdfStore, intrinsics: PinholeIntrinsics, label: &str) -> Self {
        let n = intrinsics.pixel_count();
        let name = |what: &str| format!("core.raycast.{label}.{what}");
        let vertex_in_world = gpu.storage_buffer::<[f32; 4]>(&name("vertex_in_world"), n);
        let normal_in_world = gpu.storage_buffer::<[f32; 4]>(&name("normal_in_world"), n);
        let depth_m = gpu.storage_buffer::<f32>(&name("depth_m"), n);
        let shaded_rgba8 = gpu.storage_buffer::<u32>(&name("shaded_rgba8"), n);
        let color_rgba8 = gpu.storage_buffer::<u32>(&name("color_rgba8"), n);
        let params = gpu.uniform_buffer(&name("params"), &RaycastParams::default());
        let bind_group = raycast::Bindings {
            params: &params,
            tsdf_volume: store.voxels(),
            color_volume: store.colors(),
            vertex_in_world: &vertex_in_world,
            normal_in_world: &normal_in_world,
            depth_m: &depth_m,
            shaded_rgba8: &shaded_rgba8,
            color_rgba8: &color_rgba8,
        }
        .bind_group(gpu);
        Self { intrinsics, vertex_in_world, normal_in_world, depth_m, shaded_rgba8, color_rgba8, params, bind_group }
    }

    /// Records a raycast of `store` from `world_from_camera`.
    pub fn encode(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, store: &dyn TsdfStore, world_from_camera: &Se3, depth_range_m: (f32, f32)) {
        let p = RaycastParams {
            volume: store.desc(),
            intrinsics: GpuIntrinsics::from(self.intrinsics),
            world_from_camera: world_from_camera.to_mat4().to_cols_array_2d(),
            min_depth_m: depth_range_m.0,
            max_depth_m: depth_range_m.1,
            step_factor: raycast::DEFAULT_STEP_FACTOR,
            max_steps: raycast::DEFAULT_MAX_STEPS,
        };
        gpu.write_buffer(&self.params, std::slice::from_ref(&p));
        raycast::encode(gpu, encoder, &self.bind_group, &p);
    }
}

/// The per-level buffers of the ICP and photometric reductions.
#[derive(Debug)]
struct IcpLevel {
    intrinsics: PinholeIntrinsics,
    params: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    rgb_params: wgpu::Buffer,
    rgb_bind_group: wgpu::BindGroup,
    /// This frame's intensity at this level (level 0 aliases the preprocessor's).
    intensity: Option<wgpu::Buffer>,
    /// The previous fused frame's intensity and depth at this level.
    prev_intensity: wgpu::Buffer,
    prev_depth_m: wgpu::Buffer,
    /// Builds `intensity` from the finer level (levels > 0).
    down: Option<(IntensityPyramidDownParams, wgpu::Buffer, wgpu::BindGroup)>,
}

/// The KinectFusion pipeline on one GPU, for one camera.
#[derive(Debug)]
pub struct KinectFusion {
    config: FusionConfig,
    preprocessor: DepthPreprocessor,
    volume: DenseTsdfVolume,
    /// Predicted surface per pyramid level, rendered from [`Self::prediction_pose`].
    predicted: Vec<RaycastTarget>,
    icp_levels: Vec<IcpLevel>,
    partial_sums: wgpu::Buffer,
    rgb_partial_sums: wgpu::Buffer,
    integrate_params: wgpu::Buffer,
    integrate_bind_group: wgpu::BindGroup,
    world_from_camera: Se3,
    prediction_pose: Se3,
    /// Pose of the frame held in the `prev_*` buffers, if any.
    prev_frame_pose: Option<Se3>,
    last_motion: Se3,
    frames_processed: usize,
    lost_streak: usize,
    has_volume_data: bool,
}

impl KinectFusion {
    /// Allocates the pipeline for `calibration`'s camera. The first frame's camera defines the
    /// world frame, and the volume is placed so that it looks at the volume's centre.
    pub fn new(gpu: &Gpu, calibration: RgbdCalibration, config: FusionConfig) -> Result<Self> {
        config.validate()?;
        let preprocessor = DepthPreprocessor::new(gpu, calibration, config.preprocess)?;
        let origin = config.tsdf.origin_for_first_camera(&Se3::IDENTITY);
        let volume = DenseTsdfVolume::new(gpu, config.tsdf, origin)?;
        let levels = config.icp.iterations_per_level.len();
        let predicted: Vec<RaycastTarget> =
            (0..levels).map(|l| RaycastTarget::new(gpu, &volume, preprocessor.levels[l].intrinsics, &format!("predicted[{l}]"))).collect();
        let partial_sums = gpu.storage_buffer::<f32>("core.icp_reduce.partial_sums", icp_reduce::WORKGROUPS as usize * SUM_FLOATS);
        let rgb_partial_sums = gpu.storage_buffer::<f32>("core.rgb_reduce.partial_sums", icp_reduce::WORKGROUPS as usize * SUM_FLOATS);
        let mut intensities: Vec<Option<wgpu::Buffer>> = vec![None];
        for l in 1..levels {
            intensities.push(Some(gpu.storage_buffer::<f32>(&format!("core.fusion.intensity[{l}]"), preprocessor.levels[l].intrinsics.pixel_count())));
        }
        let icp_levels = (0..levels)
            .map(|l| {
                let k = preprocessor.levels[l].intrinsics;
                let intensity_here = intensities[l].as_ref().unwrap_or(&preprocessor.intensity);
                let down = (l > 0).then(|| {
                    let fine = preprocessor.levels[l - 1].intrinsics;
                    let p = IntensityPyramidDownParams { src_width_px: fine.width_px, src_height_px: fine.height_px, dst_width_px: k.width_px, dst_height_px: k.height_px };
                    let params = gpu.uniform_buffer(&format!("core.intensity_pyramid_down.params[{l}]"), &p);
                    let src = intensities[l - 1].as_ref().unwrap_or(&preprocessor.intensity);
                    let bind_group = intensity_pyramid_down::Bindings { params: &params, src, dst: intensity_here }.bind_group(gpu);
                    (p, params, bind_group)
                });
                let prev_intensity = gpu.storage_buffer::<f32>(&format!("core.fusion.prev_intensity[{l}]"), k.pixel_count());
                let prev_depth_m = gpu.storage_buffer::<f32>(&format!("core.fusion.prev_depth_m[{l}]"), k.pixel_count());
                let rgb_params = gpu.uniform_buffer(&format!("core.rgb_reduce.params[{l}]"), &RgbReduceParams::default());
                let rgb_bind_group = rgb_reduce::Bindings {
                    params: &rgb_params,
                    vertex_in_camera: &preprocessor.levels[l].vertex_in_camera,
                    intensity: intensity_here,
                    prev_intensity: &prev_intensity,
                    prev_depth_m: &prev_depth_m,
                    partial_sums: &rgb_partial_sums,
                }
                .bind_group(gpu);
                let params = gpu.uniform_buffer(&format!("core.icp_reduce.params[{l}]"), &IcpReduceParams::default());
                let bind_group = icp_reduce::Bindings {
                    params: &params,
                    vertex_in_camera: &preprocessor.levels[l].vertex_in_camera,
                    normal_in_camera: &preprocessor.levels[l].normal_in_camera,
                    predicted_vertex_in_world: &predicted[l].vertex_in_world,
                    predicted_normal_in_world: &predicted[l].normal_in_world,
                    partial_sums: &partial_sums,
                }
                .bind_group(gpu);
                IcpLevel { intrinsics: k, params, bind_group, rgb_params, rgb_bind_group, intensity: intensities[l].take(), prev_intensity, prev_depth_m, down }
            })
            .collect();
        let integrate_params = gpu.uniform_buffer("core.tsdf_integrate.params", &TsdfIntegrateParams::default());
        let depth_for_fusion = preprocessor.depth_unfiltered_m.as_ref().unwrap_or(&preprocessor.levels[0].depth_m);
        let integrate_bind_group = tsdf_integrate::Bindings {
            params: &integrate_params,
            depth_m: depth_for_fusion,
            color: &preprocessor.color,
            tsdf_volume: volume.voxels(),
            color_volume: volume.colors(),
        }
        .bind_group(gpu);
        Ok(Self {
            config,
            preprocessor,
            volume,
            predicted,
            icp_levels,
            partial_sums,
            rgb_partial_sums,
            integrate_params,
            integrate_bind_group,
            world_from_camera: Se3::IDENTITY,
            prediction_pose: Se3::IDENTITY,
            prev_frame_pose: None,
            last_motion: Se3::IDENTITY,
            frames_processed: 0,
            lost_streak: 0,
            has_volume_data: false,
        })
    }

    /// The settings.
    pub fn config(&self) -> &FusionConfig {
        &self.config
    }

    /// The TSDF store (for mesh extraction and free-view raycasts).
    pub fn volume(&self) -> &dyn TsdfStore {
        &self.volume
    }

    /// The preprocessing chain (its buffers feed the views).
    pub fn preprocessor(&self) -> &DepthPreprocessor {
        &self.preprocessor
    }

    /// The predicted surface at pyramid level `level`, rendered from the last tracked pose.
    pub fn prediction(&self, level: usize) -> &RaycastTarget {
        &self.predicted[level]
    }

    /// The current camera pose (the last good one after a lost frame).
    pub fn world_from_camera(&self) -> Se3 {
        self.world_from_camera
    }

    /// Frames processed so far.
    pub fn frames_processed(&self) -> usize {
        self.frames_processed
    }

    /// Forgets the model and the trajectory: the next frame starts a new world frame.
    pub fn reset(&mut self, gpu: &Gpu) {
        self.volume.reset(gpu);
        self.world_from_camera = Se3::IDENTITY;
        self.prediction_pose = Se3::IDENTITY;
        self.prev_frame_pose = None;
        self.last_motion = Se3::IDENTITY;
        self.frames_processed = 0;
        self.lost_streak = 0;
        self.has_volume_data = false;
    }

    fn depth_range_m(&self) -> (f32, f32) {
        (self.config.preprocess.min_depth_m, self.config.preprocess.max_depth_m)
    }

    /// Tracks, fuses and predicts one frame.
    pub async fn process_frame(&mut self, gpu: &Gpu, frame: &RgbdFrame) -> Result<FrameReport> {
        let t_frame = Instant::now();
        let mut times = StageTimesMs::default();

        let t = Instant::now();
        self.preprocessor.upload(gpu, frame)?;
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.fusion.preprocess") });
        self.preprocessor.encode(gpu, &mut encoder);
        for lvl in &self.icp_levels {
            if let Some((p, _, bind_group)) = &lvl.down {
                gpu.kernels.intensity_pyramid_down.dispatch(&mut encoder, bind_group, [p.dst_width_px, p.dst_height_px, 1]);
            }
        }
        gpu.submit_and_wait(encoder).await?;
        times.preprocess = ms_since(t);

        let (state, icp_stats) = if !self.has_volume_data {
            (TrackingState::Initialised, Vec::new())
        } else {
            let t = Instant::now();
            let initial = if self.config.icp.constant_velocity { self.last_motion * self.world_from_camera } else { self.world_from_camera };
            let (estimate, stats, failure) = self.track(gpu, initial).await?;
            times.track = ms_since(t);
            let state = match failure {
                Some(reason) => TrackingState::Lost(reason),
                None => {
                    let motion = estimate * self.world_from_camera.inverse();
                    self.last_motion = motion;
                    self.world_from_camera = estimate;
                    if self.lost_streak > 0 { TrackingState::Recovered } else { TrackingState::Tracked }
                }
            };
            (state, stats)
        };

        if state.is_lost() {
            self.lost_streak += 1;
            self.last_motion = Se3::IDENTITY;
        } else {
            self.lost_streak = 0;
            let t = Instant::now();
            self.integrate(gpu).await?;
            times.integrate = ms_since(t);
            let t = Instant::now();
            self.predict(gpu).await?;
            times.raycast = ms_since(t);
            self.keep_as_previous(gpu);
            self.has_volume_data = true;
        }
        let index = frame.index;
        self.frames_processed += 1;
        times.total = ms_since(t_frame);
        Ok(FrameReport { index, world_from_camera: self.world_from_camera, state, icp: icp_stats, times_ms: times })
    }

    /// Fuses the current (preprocessed) frame at the current pose.
    async fn integrate(&self, gpu: &Gpu) -> Result<()> {
        let p = TsdfIntegrateParams {
            volume: self.volume.desc(),
            intrinsics: GpuIntrinsics::from(self.preprocessor.levels[0].intrinsics),
            camera_from_world: self.world_from_camera.inverse().to_mat4().to_cols_array_2d(),
            color_enabled: u32::from(self.volume.has_color()),
            ..Default::default()
        };
        gpu.write_buffer(&self.integrate_params, std::slice::from_ref(&p));
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.fusion.integrate") });
        gpu.kernels.tsdf_integrate.dispatch(&mut encoder, &self.integrate_bind_group, [p.volume.dim_x, p.volume.dim_y, 1]);
        gpu.submit_and_wait(encoder).await
    }

    /// Keeps this frame's intensity and depth pyramids for the next frame's photometric term.
    fn keep_as_previous(&mut self, gpu: &Gpu) {
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.fusion.keep_previous") });
        for (l, lvl) in self.icp_levels.iter().enumerate() {
            let intensity = lvl.intensity.as_ref().unwrap_or(&self.preprocessor.intensity);
            encoder.copy_buffer_to_buffer(intensity, 0, &lvl.prev_intensity, 0, lvl.prev_intensity.size());
            encoder.copy_buffer_to_buffer(&self.preprocessor.levels[l].depth_m, 0, &lvl.prev_depth_m, 0, lvl.prev_depth_m.size());
        }
        gpu.queue.submit([encoder.finish()]);
        self.prev_frame_pose = Some(self.world_from_camera);
    }

    /// Raycasts every level's prediction from the current pose.
    async fn predict(&mut self, gpu: &Gpu) -> Result<()> {
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.fusion.predict") });
        for target in &self.predicted {
            target.encode(gpu, &mut encoder, &self.volume, &self.world_from_camera, self.depth_range_m());
        }
        gpu.submit_and_wait(encoder).await?;
        self.prediction_pose = self.world_from_camera;
        Ok(())
    }

    /// Coarse-to-fine ICP from `initial`. Returns the estimate, per-level statistics and the
    /// failure, if any.
    async fn track(&self, gpu: &Gpu, initial: Se3) -> Result<(Se3, Vec<IcpLevelStats>, Option<LostReason>)> {
        let camera_prev_from_world = self.prediction_pose.inverse().to_mat4().to_cols_array_2d();
        let icp = &self.config.icp;
        let photometric = self.prev_frame_pose.filter(|_| icp.rgb_weight > 0.0);
        let n_partials = icp_reduce::WORKGROUPS as usize * SUM_FLOATS;
        let mut estimate = initial;
        let mut stats = Vec::new();
        let mut last_system = None;
        for level in (0..icp.iterations_per_level.len()).rev() {
            let lvl = &self.icp_levels[level];
            let mut level_stats = IcpLevelStats { level, ..Default::default() };
            for _ in 0..icp.iterations_per_level[level] {
                let p = IcpReduceParams {
                    intrinsics: GpuIntrinsics::from(lvl.intrinsics),
                    world_from_camera: estimate.to_mat4().to_cols_array_2d(),
                    camera_prev_from_world,
                    dist_thresh_m: icp.dist_thresh_m,
                    cos_angle_thresh: icp.angle_thresh_rad.cos(),
                    thread_count: icp_reduce::WORKGROUPS * icp_reduce::WORKGROUP_THREADS,
                    huber_delta_m: icp.huber_delta_m,
                    noise_weighting: u32::from(icp.noise_weighting),
                    ..Default::default()
                };
                gpu.write_buffer(&lvl.params, std::slice::from_ref(&p));
                let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.fusion.icp") });
                icp_reduce::encode(gpu, &mut encoder, &lvl.bind_group, &p);
                if let Some(prev_pose) = photometric {
                    let rp = RgbReduceParams {
                        intrinsics: p.intrinsics,
                        world_from_camera: p.world_from_camera,
                        camera_prev_from_world: prev_pose.inverse().to_mat4().to_cols_array_2d(),
                        world_from_camera_prev: prev_pose.to_mat4().to_cols_array_2d(),
                        max_depth_diff_m: DEFAULT_RGB_MAX_DEPTH_DIFF_M,
                        max_residual: icp.rgb_max_residual,
                        thread_count: p.thread_count,
                        _pad0: 0,
                    };
                    gpu.write_buffer(&lvl.rgb_params, std::slice::from_ref(&rp));
                    gpu.kernels.rgb_reduce.dispatch(&mut encoder, &lvl.rgb_bind_group, [rp.thread_count, 1, 1]);
                }
                gpu.queue.submit([encoder.finish()]);
                let system = if photometric.is_some() {
                    let partials: Vec<f32> = gpu.read_buffers(&[(&self.partial_sums, n_partials), (&self.rgb_partial_sums, n_partials)]).await?;
                    let geometric = NormalEquations::from_partial_sums(&partials[..n_partials]);
                    let photometric = NormalEquations::from_partial_sums(&partials[n_partials..]);
                    geometric.combined_with(&photometric, f64::from(icp.rgb_weight))
                } else {
                    let partials: Vec<f32> = gpu.read_buffer(&self.partial_sums, n_partials).await?;
                    NormalEquations::from_partial_sums(&partials)
                };
                level_stats.iterations += 1;
                level_stats.inliers = system.inliers;
                level_stats.rms_residual_m = system.rms_residual_m();
                let Some(update) = system.solve() else {
                    last_system = Some(system);
                    break;
                };
                estimate = twist_exp(&update) * estimate;
                let converged = update.iter().all(|x| x.abs() < DEFAULT_CONVERGED_UPDATE);
                last_system = Some(system);
                if converged {
                    break;
                }
            }
            stats.push(level_stats);
        }
        let failure = self.check_tracking(&estimate, last_system.as_ref());
        Ok((estimate, stats, failure))
    }

    fn check_tracking(&self, estimate: &Se3, system: Option<&NormalEquations>) -> Option<LostReason> {
        let icp = &self.config.icp;
        let required = (icp.min_inlier_fraction * self.icp_levels[0].intrinsics.pixel_count() as f64).ceil() as u64;
        let inliers = system.map_or(0, |s| s.inliers);
        if inliers < required {
            return Some(LostReason::TooFewInliers { inliers, required });
        }
        let condition = system.map_or(f64::INFINITY, NormalEquations::condition);
        if !(condition <= icp.max_condition) {
            return Some(LostReason::IllConditioned { condition });
        }
        let motion = estimate.inverse() * self.world_from_camera;
        let (translation_m, rotation_rad) = (motion.translation_m.length(), motion.rotation_angle_rad());
        if translation_m > icp.max_jump_m || rotation_rad > icp.max_jump_rad {
            return Some(LostReason::ImplausibleJump { translation_m, rotation_rad });
        }
        None
    }
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// The 6x6 point-to-plane system summed (in f64) from `icp_reduce`'s partial sums.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalEquations {
    /// JᵀJ.
    pub jtj: Matrix6<f64>,
    /// Jᵀr.
    pub jtr: Vector6<f64>,
    /// Σ r², metres².
    pub residual_sq_sum: f64,
    /// Correspondences.
    pub inliers: u64,
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
        Self { jtj, jtr, residual_sq_sum: sum[27], inliers: sum[28].round() as u64 }
    }

    /// `self + weight · other`, keeping this system's inlier count and residual (the
    /// geometric ones, which the tracking checks use).
    pub fn combined_with(&self, other: &Self, weight: f64) -> Self {
        Self { jtj: self.jtj + other.jtj * weight, jtr: self.jtr + other.jtr * weight, ..*self }
    }

    /// RMS residual, metres.
    pub fn rms_residual_m(&self) -> f64 {
        if self.inliers == 0 { 0.0 } else { (self.residual_sq_sum / self.inliers as f64).sqrt() }
    }

    /// Largest over smallest eigenvalue of JᵀJ (infinite when singular).
    pub fn condition(&self) -> f64 {
        let eig = SymmetricEigen::new(self.jtj).eigenvalues;
        let (lo, hi) = (eig.min(), eig.max());
        if lo > 0.0 { hi / lo } else { f64::INFINITY }
    }

    /// The twist (ω, t) minimising Σ (r + J ξ)², by Cholesky; `None` if JᵀJ is not positive
    /// definite.
    pub fn solve(&self) -> Option<Vector6<f64>> {
        let chol = self.jtj.cholesky()?;
        let x = chol.solve(&(-self.jtr));
        x.iter().all(|v| v.is_finite()).then_some(x)
    }
}

/// exp of a twist (ω, t) as used by the tracker: rotation by the axis-angle ω (Rodrigues)
/// followed by the translation t, applied on the left (world frame).
pub fn twist_exp(xi: &Vector6<f64>) -> Se3 {
    let omega = DVec3::new(xi[0], xi[1], xi[2]);
    let angle = omega.length();
    let rotation = if angle > 0.0 { DQuat::from_axis_angle(omega / angle, angle) } else { DQuat::IDENTITY };
    Se3::new(rotation, DVec3::new(xi[3], xi[4], xi[5]))
}
