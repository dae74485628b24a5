// SPDX-License-Identifier: MIT
//! The tracker stage: coarse-to-fine point-to-plane ICP plus a photometric term, entirely on
//! the GPU. Per frame it records, into one compute pass,
//!
//! ```text
//! track_begin                    estimate = guess | motion · reference | reference
//! for level coarse → fine, for each iteration:
//!   track_reduce (indirect)      normal equations, ICP + photometric rows, one reduction
//!   track_solve                  f32 scaled Cholesky solve, conditioning, update, convergence
//! track_finish                   outcome, lost-frame checks, pose published to the mapper
//! ```
//!
//! and, after the predictor, `keep_previous` per level (the frame's intensity and depth become
//! the next frame's reference, if it was tracked). Nothing waits for the host: the state lives
//! in [`IcpTracker::state_buffer`] (a `TrackState`, its `pose` at offset 0 is what the mapper
//! and predictor bind) and the host reads it back once per frame, late.

use crate::cpu::shared::IDENTITY;
use crate::fusion::IcpConfig;
use crate::fusion::predictor::Predictor;
use crate::kernels::keep_previous::{self, KeepPreviousParams};
use crate::kernels::track_reduce::{self, MAX_WORKGROUPS, SUM_FLOATS, WORKGROUP_THREADS, min_pixels_per_thread, reduce_workgroups};
use crate::kernels::track_solve::{TrackDispatch, TrackParams, TrackState};
use crate::kernels::{GpuIntrinsics, track_begin, track_finish, track_solve};
use crate::preprocess::DepthPreprocessor;
use crate::{Error, Gpu, PinholeIntrinsics, Result, Se3};

/// Pyramid levels a `TrackState` has room for (WGSL `TRACK_MAX_LEVELS`).
pub const TRACK_MAX_LEVELS: usize = 4;
/// Bytes of one `TrackState`.
pub const TRACK_STATE_BYTES: u64 = std::mem::size_of::<TrackState>() as u64;

#[derive(Debug)]
struct TrackerLevel {
    intrinsics: PinholeIntrinsics,
    iterations: u32,
    _params: wgpu::Buffer,
    reduce: wgpu::BindGroup,
    solve: wgpu::BindGroup,
    keep: wgpu::BindGroup,
    _previous: wgpu::Buffer,
}

/// The GPU tracker of one camera: its state, reduction buffers and per-level bind groups.
#[derive(Debug)]
pub struct IcpTracker {
    config: IcpConfig,
    state: wgpu::Buffer,
    dispatch: wgpu::Buffer,
    levels: Vec<TrackerLevel>,
    /// Workgroups of each level's `track_reduce` (0 beyond the levels used).
    level_workgroups: [u32; TRACK_MAX_LEVELS],
    partial_sums: wgpu::Buffer,
    begin: wgpu::BindGroup,
    finish: wgpu::BindGroup,
}

impl IcpTracker {
    /// The tracker of `preprocessor`'s frames against `predictor`'s prediction pyramid, keeping
    /// its state in `state` (from [`state_buffer`]; the mapper and predictor read the pose there).
    pub fn new(gpu: &Gpu, config: &IcpConfig, preprocessor: &DepthPreprocessor, predictor: &Predictor, state: wgpu::Buffer) -> Result<Self> {
        let n_levels = config.iterations_per_level.len();
        if n_levels == 0 || n_levels > preprocessor.levels.len() || n_levels > predictor.levels() || n_levels > TRACK_MAX_LEVELS {
            return Err(Error::InvalidConfig(format!(
                "the tracker uses {n_levels} levels; the preprocessor has {}, the predictor {}, the state room for {TRACK_MAX_LEVELS}",
                preprocessor.levels.len(),
                predictor.levels()
            )));
        }
        if state.size() < TRACK_STATE_BYTES {
            return Err(Error::InvalidConfig(format!("the tracker's state buffer holds {} bytes, a TrackState {TRACK_STATE_BYTES}", state.size())));
        }
        let dispatch = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("core.track.dispatch"),
            size: std::mem::size_of::<TrackDispatch>() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        gpu.write_buffer(&dispatch, &[TrackDispatch::default()]);
        let partial_sums = gpu.storage_buffer::<f32>("core.track.partial_sums", MAX_WORKGROUPS as usize * SUM_FLOATS);
        let per_thread = min_pixels_per_thread(gpu.adapter_info.device_type);
        let mut level_workgroups = [0u32; TRACK_MAX_LEVELS];
        for (l, w) in level_workgroups.iter_mut().enumerate().take(n_levels) {
            *w = reduce_workgroups(preprocessor.levels[l].intrinsics.pixel_count(), per_thread);
        }
        let min_inliers = (config.min_inlier_fraction * preprocessor.levels[0].intrinsics.pixel_count() as f64).ceil() as u32;
        let mut levels = Vec::with_capacity(n_levels);
        for (l, &iterations) in config.iterations_per_level.iter().enumerate() {
            let pre = &preprocessor.levels[l];
            let k = pre.intrinsics;
            let params = gpu.uniform_buffer(&format!("core.track.params[{l}]"), &track_params(config, l, k, min_inliers, level_workgroups));
            let previous = gpu.storage_buffer::<[f32; 4]>(&format!("core.track.previous[{l}]"), k.pixel_count());
            let (predicted_vertex_in_world, predicted_normal_in_world) = predictor.level(l);
            let reduce = track_reduce::Bindings {
                params: &params,
                state: &state,
                vertex_in_camera: &pre.vertex_in_camera,
                normal_in_camera: &pre.normal_in_camera,
                predicted_vertex_in_world,
                predicted_normal_in_world,
                intensity: &pre.intensity,
                previous: &previous,
                partial_sums: &partial_sums,
            }
            .bind_group(gpu);
            let solve = track_solve::Bindings { params: &params, partial_sums: &partial_sums, state: &state, dispatch: &dispatch }.bind_group(gpu);
            let keep_params = gpu.uniform_buffer(&format!("core.keep_previous.params[{l}]"), &KeepPreviousParams { width_px: k.width_px, height_px: k.height_px, ..Default::default() });
            let keep = keep_previous::Bindings { params: &keep_params, pose: &state, intensity: &pre.intensity, depth_m: &pre.depth_m, previous: &previous }.bind_group(gpu);
            levels.push(TrackerLevel { intrinsics: k, iterations, _params: params, reduce, solve, keep, _previous: previous });
        }
        let level0 = gpu.uniform_buffer("core.track.params.frame", &track_params(config, 0, levels[0].intrinsics, min_inliers, level_workgroups));
        let begin = track_begin::Bindings { params: &level0, state: &state, dispatch: &dispatch }.bind_group(gpu);
        let finish = track_finish::Bindings { params: &level0, state: &state }.bind_group(gpu);
        let tracker = Self { config: config.clone(), state, dispatch, levels, level_workgroups, partial_sums, begin, finish };
        tracker.reset(gpu);
        Ok(tracker)
    }

    /// The settings.
    pub fn config(&self) -> &IcpConfig {
        &self.config
    }

    /// The `TrackState` buffer; its first member is the frame's `CameraPose`, which the mapper
    /// and predictor bind.
    pub fn state_buffer(&self) -> &wgpu::Buffer {
        &self.state
    }

    /// The partial sums of the last `track_reduce` that ran (for diagnostics and tests).
    pub fn partial_sums_buffer(&self) -> &wgpu::Buffer {
        &self.partial_sums
    }

    /// Forgets the trajectory: the next frame initialises a new world frame at the identity.
    pub fn reset(&self, gpu: &Gpu) {
        gpu.write_buffer(&self.state, &[initial_state()]);
        gpu.write_buffer(&self.dispatch, &[TrackDispatch::default()]);
    }

    /// Starts the next frame from `world_from_camera` (another tracker's estimate, or given
    /// poses used as an initial guess) instead of the motion model. On the first frame it
    /// places the world frame.
    pub fn set_guess(&self, gpu: &Gpu, world_from_camera: &Se3) {
        let guess_offset = std::mem::offset_of!(TrackState, guess) as u64;
        let flag_offset = std::mem::offset_of!(TrackState, has_guess) as u64;
        gpu.queue.write_buffer(&self.state, guess_offset, bytemuck::cast_slice(&world_from_camera.to_cols_f32()));
        gpu.queue.write_buffer(&self.state, flag_offset, bytemuck::bytes_of(&1u32));
    }

    /// Moves the tracker's reference to `world_from_camera` (a relocalisation found by another
    /// tracker): the next frame starts there and its jump check measures from there, the
    /// motion model restarts, and the pose is published active so that the predictor renders
    /// the model at it. The photometric term keeps comparing against the last fused frame's
    /// intensity at that frame's own pose (`previous_view`, which a reseed leaves alone), so
    /// a right relocalisation pairs with it where the views overlap. The lost-frame streak is
    /// kept, so a frame that tracks from here reports Recovered; that frame's jump check holds
    /// ICP's correction of the reseeded pose to `max_reseed_correction_m` / `_rad`.
    pub fn reseed(&self, gpu: &Gpu, world_from_camera: &Se3) {
        let cols = world_from_camera.to_cols_f32();
        let write = |offset: usize, bytes: &[u8]| gpu.queue.write_buffer(&self.state, offset as u64, bytes);
        write(std::mem::offset_of!(TrackState, pose), bytemuck::bytes_of(&crate::cpu::shared::camera_pose(&cols, 1)));
        write(std::mem::offset_of!(TrackState, reference), bytemuck::cast_slice(&cols));
        write(std::mem::offset_of!(TrackState, motion), bytemuck::cast_slice(&IDENTITY));
        write(std::mem::offset_of!(TrackState, has_guess), bytemuck::bytes_of(&0u32));
        write(std::mem::offset_of!(TrackState, reseeded), bytemuck::bytes_of(&1u32));
    }

    /// Records the tracking of the preprocessed frame: begin, every level's iterations, finish.
    /// `first` says the tracker has fused nothing since its reset (the host knows: no frame was
    /// submitted since): that frame only initialises the world frame (`track_begin` marks every
    /// level done and sizes no reduction), so its iterations, which would do nothing, are not
    /// recorded (nor, in the browser, compiled before the first frame).
    pub fn encode_in(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>, first: bool) {
        gpu.kernels.track_begin.dispatch_in(pass, &self.begin, [1, 1, 1]);
        for (l, level) in self.levels.iter().enumerate().rev().filter(|_| !first) {
            for _ in 0..level.iterations {
                track_reduce::dispatch_indirect(gpu, pass, &level.reduce, &self.dispatch, l);
                gpu.kernels.track_solve.dispatch_in(pass, &level.solve, [32, 1, 1]);
            }
        }
        gpu.kernels.track_finish.dispatch_in(pass, &self.finish, [1, 1, 1]);
    }

    /// Records one Gauss-Newton iteration of `level` (reduce and solve) with a direct dispatch,
    /// whatever the convergence state: what one iteration costs, for benchmarks. (The solve
    /// returns early on a level that has converged, so this is the reduction's cost plus a
    /// solve's fixed overhead.)
    pub fn encode_iteration(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>, level: usize) {
        let l = &self.levels[level];
        pass.set_pipeline(&gpu.kernels.track_reduce.pipeline);
        pass.set_bind_group(0, &l.reduce, &[]);
        pass.dispatch_workgroups(self.level_workgroups[level], 1, 1);
        gpu.kernels.track_solve.dispatch_in(pass, &l.solve, [32, 1, 1]);
    }

    /// Pyramid levels tracked.
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Workgroups of each level's `track_reduce` dispatches (0 beyond the levels used).
    pub fn level_workgroups(&self) -> [u32; TRACK_MAX_LEVELS] {
        self.level_workgroups
    }

    /// Records `keep_previous` for every level (after the predictor; skipped on the GPU when
    /// the frame was lost).
    pub fn encode_keep_previous(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        for level in &self.levels {
            gpu.kernels.keep_previous.dispatch_in(pass, &level.keep, [level.intrinsics.width_px, level.intrinsics.height_px, 1]);
        }
    }
}

/// A buffer for one `TrackState` (storage, copy source and destination; uniform too, for the
/// kernels that read its `pose`).
pub fn state_buffer(gpu: &Gpu) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("core.track.state"),
        size: TRACK_STATE_BYTES,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// The state after a reset: every pose the identity, nothing fused.
pub fn initial_state() -> TrackState {
    TrackState {
        pose: crate::cpu::shared::camera_pose(&IDENTITY, 0),
        estimate: IDENTITY,
        reference: IDENTITY,
        previous_view: IDENTITY,
        motion: IDENTITY,
        guess: IDENTITY,
        ..Default::default()
    }
}

/// The kernels' parameters at `level` (intrinsics `k`), every level's `track_reduce`
/// dispatch having `level_workgroups`.
pub fn track_params(config: &IcpConfig, level: usize, k: PinholeIntrinsics, min_inliers: u32, level_workgroups: [u32; TRACK_MAX_LEVELS]) -> TrackParams {
    TrackParams {
        intrinsics: GpuIntrinsics::from(k),
        level: level as u32,
        thread_count: level_workgroups[level] * WORKGROUP_THREADS,
        reduce_workgroups: level_workgroups[level],
        level_workgroups,
        n_levels: config.iterations_per_level.len() as u32,
        dist_thresh_m: config.dist_thresh_m,
        cos_angle_thresh: config.angle_thresh_rad.cos(),
        huber_delta_m: config.huber_delta_m,
        noise_weighting: u32::from(config.noise_weighting),
        rgb_weight: config.rgb_weight,
        rgb_max_residual: config.rgb_max_residual,
        rgb_max_depth_diff_m: config.rgb_max_depth_diff_m,
        // A pixel of level l is 2^l times wider: so is the precision an update there can reach.
        converged_update_m: config.converged_update_m * (1u32 << level) as f32,
        reference_depth_m: config.reference_depth_m,
        min_inliers,
        max_condition: config.max_condition,
        max_translation_condition: config.max_translation_condition,
        max_jump_m: config.max_jump_m,
        max_jump_rad: config.max_jump_rad,
        max_reseed_correction_m: config.max_reseed_correction_m,
        max_reseed_correction_rad: config.max_reseed_correction_rad,
        constant_velocity: u32::from(config.constant_velocity),
        rotation_scale_m: config.rotation_scale_m,
        ..Default::default()
    }
}
