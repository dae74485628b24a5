// SPDX-License-Identifier: MIT
//! The predictor stage: raycasts the map at any pose and intrinsics ([`RaycastTarget`]), and
//! the prediction pyramid the tracker aligns against ([`Predictor`]: the finest level raycast,
//! the coarser ones downsampled from it by `prediction_down`, as KinectFusion does).

use crate::kernels::prediction_down::{self, PredictionDownParams};
use crate::engine::FrameEncoder;
use crate::kernels::raycast::{self, CameraPose, DEFAULT_MAX_STEPS, DEFAULT_STEP_FACTOR, RaycastParams};
use crate::kernels::raycast_hint_tiles::{self, RaycastHintTilesParams};
use crate::kernels::raycast_range::{self, RaycastRangeParams};
use crate::kernels::surface_normals::{self, SurfaceNormalsParams};
use crate::kernels::{GpuIntrinsics, KernelPipeline};
use crate::preprocess::DepthPreprocessor;
use crate::tsdf::TsdfStore;
use crate::{Error, Gpu, PinholeIntrinsics, Result, Se3};

/// A uniform buffer holding one [`CameraPose`], written by the host (kernels bind their pose
/// as a uniform).
pub fn pose_buffer(gpu: &Gpu, label: &str, world_from_camera: Option<&Se3>) -> wgpu::Buffer {
    gpu.uniform_buffer(label, &camera_pose(world_from_camera))
}

/// The [`CameraPose`] of `world_from_camera`, or a disabled one for `None`.
pub fn camera_pose(world_from_camera: Option<&Se3>) -> CameraPose {
    match world_from_camera {
        Some(p) => crate::cpu::shared::camera_pose(&p.to_cols_f32(), 1),
        None => CameraPose::default(),
    }
}

/// Squared norm of a surface normal's cross product (m⁴) at or below which none is emitted:
/// well under any real surface patch (1 mm x 1 mm neighbour differences give 1e-12).
pub const MIN_NORMAL_CROSS_NORM_SQ: f32 = 1e-20;

/// The depth a prediction's rays search around: the raw sensor depth (u16 per pixel, packed
/// two per word as the preprocessor uploads it) fused at the pose the prediction renders from.
#[derive(Clone, Copy, Debug)]
pub struct DepthHint<'a> {
    /// The raw depth buffer.
    pub depth_raw: &'a wgpu::Buffer,
    /// Metres per raw unit.
    pub metres_per_unit: f32,
}

impl<'a> DepthHint<'a> {
    /// The raw depth the preprocessor uploaded last.
    pub fn from_preprocessor(preprocessor: &'a DepthPreprocessor) -> Self {
        Self { depth_raw: &preprocessor.depth_raw, metres_per_unit: preprocessor.calibration().metres_per_depth_unit() }
    }
}

/// Pixels along each edge of a tile of the depth-range image (`raycast_range`): small enough
/// that a tile's interval stays tight at silhouettes, large enough that a brick near the
/// camera touches tens of tiles rather than thousands.
pub const RANGE_TILE_PX: u32 = 8;

/// The parts of a render, in order (timed alone by `bench`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RaycastPart {
    /// `raycast_hint_tiles` (with a depth hint) and `raycast_range`: each tile's depth interval.
    RangeTiles,
    /// `raycast`: the rays.
    Rays,
    /// `surface_normals`.
    Normals,
}

/// Images `raycast` renders at one resolution (and `surface_normals` completes), bound to a
/// store and a pose buffer.
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
    /// Model colour, RGBA8 per pixel.
    pub color_rgba8: wgpu::Buffer,
    params: wgpu::Buffer,
    pose: wgpu::Buffer,
    owns_pose: bool,
    hint: Option<(f32, f32)>,
    bind_group: wgpu::BindGroup,
    /// `raycast` compiled for the store's map kind, with the depth hint's window only when
    /// there is a hint ([`DeferredPipeline::variant`](crate::kernels::DeferredPipeline::variant)).
    raycast: KernelPipeline,
    /// Per tile, the depth interval surface bricks cover (`raycast_range`, cleared each render).
    depth_range_tiles: wgpu::Buffer,
    range_params: wgpu::Buffer,
    range_bind_group: wgpu::BindGroup,
    /// With a depth hint: `raycast_hint_tiles` (its params and bind group), which spares
    /// `raycast_range` the tiles whose rays all have a hint.
    hint_tiles: Option<(wgpu::Buffer, wgpu::BindGroup)>,
    /// Surface-brick words of the store (one `raycast_range` invocation each).
    bricks: u32,
    _normals_params: wgpu::Buffer,
    normals_bind_group: wgpu::BindGroup,
}

impl RaycastTarget {
    /// Images for `intrinsics`, rendered from a pose this target owns ([`Self::set_pose`]).
    pub fn new(gpu: &Gpu, store: &dyn TsdfStore, intrinsics: PinholeIntrinsics, label: &str) -> Self {
        let pose = pose_buffer(gpu, &format!("core.raycast.{label}.pose"), None);
        Self::build(gpu, store, intrinsics, pose, true, None, label)
    }

    /// Images for `intrinsics`, rendered from the pose another stage writes into `pose` (a
    /// `CameraPose` at offset 0: the tracker's state). With `depth_hint`, the raw depth just
    /// fused at that pose, each ray searches only within the truncation distance (plus the
    /// sensor's noise) of the measured surface.
    pub fn with_pose_buffer(gpu: &Gpu, store: &dyn TsdfStore, intrinsics: PinholeIntrinsics, pose: &wgpu::Buffer, depth_hint: Option<DepthHint<'_>>, label: &str) -> Self {
        Self::build(gpu, store, intrinsics, pose.clone(), false, depth_hint, label)
    }

    fn build(gpu: &Gpu, store: &dyn TsdfStore, intrinsics: PinholeIntrinsics, pose: wgpu::Buffer, owns_pose: bool, hint: Option<DepthHint<'_>>, label: &str) -> Self {
        let n = intrinsics.pixel_count();
        let name = |what: &str| format!("core.raycast.{label}.{what}");
        let vertex_in_world = gpu.storage_buffer::<[f32; 4]>(&name("vertex_in_world"), n);
        let normal_in_world = gpu.storage_buffer::<[f32; 4]>(&name("normal_in_world"), n);
        let depth_m = gpu.storage_buffer::<f32>(&name("depth_m"), n);
        let color_rgba8 = gpu.storage_buffer::<u32>(&name("color_rgba8"), n);
        let params = gpu.uniform_buffer(&name("params"), &RaycastParams::default());
        let tiles = Self::tiles(intrinsics);
        let depth_range_tiles = gpu.storage_buffer::<[u32; 2]>(&name("depth_range_tiles"), (tiles[0] * tiles[1]) as usize);
        let range_params = gpu.uniform_buffer(&name("range_params"), &RaycastRangeParams::default());
        let range_bind_group = raycast_range::Bindings { params: &range_params, pose: &pose, surface_bricks: store.surface_bricks(), depth_range_tiles: &depth_range_tiles, block_coords: store.block_coords() }.bind_group(gpu);
        // Specialised: lavapipe runs a branch's arithmetic even where no invocation takes it,
        // so the other map kind's paths and an unused hint window cost every step of every ray.
        let raycast = gpu.kernels.raycast.variant(&[("MAP_KIND", f64::from(store.desc().kind)), ("DEPTH_HINTS", if hint.is_some() { 1.0 } else { 0.0 })]);
        let placeholder;
        let depth_hint_raw = match &hint {
            Some(h) => h.depth_raw,
            None => {
                placeholder = gpu.storage_buffer::<u32>(&name("no_depth_hint"), 1);
                &placeholder
            }
        };
        let hint_tiles = hint.as_ref().map(|h| {
            let p = RaycastHintTilesParams { intrinsics: GpuIntrinsics::from(intrinsics), tile_px: RANGE_TILE_PX, tiles_x: tiles[0], tiles_y: tiles[1], hint_metres_per_unit: h.metres_per_unit };
            let params = gpu.uniform_buffer(&name("hint_tiles_params"), &p);
            let bind_group = raycast_hint_tiles::Bindings { params: &params, depth_hint_raw, depth_range_tiles: &depth_range_tiles }.bind_group(gpu);
            (params, bind_group)
        });
        let bind_group = raycast::Bindings {
            params: &params,
            pose: &pose,
            tsdf_volume: store.voxels(),
            color_volume: store.colors(),
            vertex_in_world: &vertex_in_world,
            depth_m: &depth_m,
            color_rgba8: &color_rgba8,
            depth_hint_raw,
            depth_range_tiles: &depth_range_tiles,
            block_table: store.block_table(),
        }
        .bind_group(gpu);
        let np = SurfaceNormalsParams { width_px: intrinsics.width_px, height_px: intrinsics.height_px, min_cross_norm_sq: MIN_NORMAL_CROSS_NORM_SQ, ..Default::default() };
        let normals_params = gpu.uniform_buffer(&name("normals_params"), &np);
        let normals_bind_group = surface_normals::Bindings { params: &normals_params, pose: &pose, vertex_in_world: &vertex_in_world, normal_in_world: &normal_in_world }.bind_group(gpu);
        Self {
            intrinsics,
            vertex_in_world,
            normal_in_world,
            depth_m,
            color_rgba8,
            params,
            pose,
            owns_pose,
            hint: hint.map(|h| (store.desc().truncation_m, h.metres_per_unit)),
            bind_group,
            raycast,
            depth_range_tiles,
            range_params,
            range_bind_group,
            hint_tiles,
            bricks: store.desc().brick_count() as u32,
            _normals_params: normals_params,
            normals_bind_group,
        }
    }

    /// The uniform buffer holding the pose it renders from (a `CameraPose`), for kernels that
    /// read its images at the same pose.
    pub fn pose_buffer(&self) -> &wgpu::Buffer {
        &self.pose
    }

    /// Tiles of [`RANGE_TILE_PX`] along x and y.
    fn tiles(k: PinholeIntrinsics) -> [u32; 2] {
        [k.width_px.div_ceil(RANGE_TILE_PX), k.height_px.div_ceil(RANGE_TILE_PX)]
    }

    /// Sets the volume description and depth range the kernels march with.
    pub fn set_params(&self, gpu: &Gpu, store: &dyn TsdfStore, depth_range_m: (f32, f32)) {
        let tiles = Self::tiles(self.intrinsics);
        let p = RaycastParams {
            volume: store.desc(),
            intrinsics: GpuIntrinsics::from(self.intrinsics),
            min_depth_m: depth_range_m.0,
            max_depth_m: depth_range_m.1,
            step_factor: DEFAULT_STEP_FACTOR,
            max_steps: DEFAULT_MAX_STEPS,
            use_depth_hint: u32::from(self.hint.is_some()),
            hint_margin_m: self.hint.map_or(0.0, |h| h.0),
            hint_metres_per_unit: self.hint.map_or(0.0, |h| h.1),
            range_tile_px: RANGE_TILE_PX,
            range_tiles_x: tiles[0],
            ..Default::default()
        };
        gpu.write_buffer(&self.params, std::slice::from_ref(&p));
        let r = RaycastRangeParams {
            volume: store.desc(),
            intrinsics: GpuIntrinsics::from(self.intrinsics),
            tile_px: RANGE_TILE_PX,
            tiles_x: tiles[0],
            tiles_y: tiles[1],
            min_depth_m: depth_range_m.0,
            max_depth_m: depth_range_m.1,
            ..Default::default()
        };
        gpu.write_buffer(&self.range_params, std::slice::from_ref(&r));
    }

    /// Sets the pose of a target that owns its pose buffer.
    pub fn set_pose(&self, gpu: &Gpu, world_from_camera: &Se3) -> Result<()> {
        if !self.owns_pose {
            return Err(Error::InvalidConfig("this raycast target renders from another stage's pose; it cannot be set".into()));
        }
        gpu.write_buffer(&self.pose, &[camera_pose(Some(world_from_camera))]);
        Ok(())
    }

    /// Clears the depth-range tiles: recorded before [`Self::dispatch_in`]'s pass.
    fn clear(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.depth_range_tiles, 0, None);
    }

    /// Records the range tiles (those a hinted prediction reads), the raycast and, with
    /// `normals`, the normals into an open compute pass (the tiles cleared before it).
    fn dispatch_in(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>, normals: bool) {
        for part in [RaycastPart::RangeTiles, RaycastPart::Rays, RaycastPart::Normals] {
            if normals || part != RaycastPart::Normals {
                self.dispatch_part(gpu, pass, part);
            }
        }
    }

    /// Records one part of the render into an open compute pass.
    fn dispatch_part(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>, part: RaycastPart) {
        let size = [self.intrinsics.width_px, self.intrinsics.height_px, 1];
        match part {
            RaycastPart::RangeTiles => {
                if let Some((_, hint_tiles)) = &self.hint_tiles {
                    let tiles = Self::tiles(self.intrinsics);
                    gpu.kernels.raycast_hint_tiles.dispatch_in(pass, hint_tiles, [tiles[0], tiles[1], 1]);
                }
                gpu.kernels.raycast_range.dispatch_in(pass, &self.range_bind_group, [self.bricks, 1, 1]);
            }
            RaycastPart::Rays => self.raycast.dispatch_in(pass, &self.bind_group, size),
            RaycastPart::Normals => gpu.kernels.surface_normals.dispatch_in(pass, &self.normals_bind_group, size),
        }
    }

    /// Records the render as stage `stage` of a frame.
    pub fn encode(&self, gpu: &Gpu, frame: &mut FrameEncoder<'_>, stage: &'static str) {
        self.clear(frame.encoder());
        self.dispatch_in(gpu, &mut frame.stage(stage), true);
    }

    /// Records one part of the render alone as stage `stage` (what `bench` times; the parts
    /// read what the earlier ones wrote, so run alone they time the same work as in a frame).
    pub fn encode_part(&self, gpu: &Gpu, frame: &mut FrameEncoder<'_>, stage: &'static str, part: RaycastPart) {
        if part == RaycastPart::RangeTiles {
            self.clear(frame.encoder());
        }
        self.dispatch_part(gpu, &mut frame.stage(stage), part);
    }

    /// Renders `store` from `world_from_camera` (a target that owns its pose): sets the
    /// parameters and pose, and records the render into `encoder`; the surface normals only
    /// with `normals` (a reader that needs none, such as an exact virtual sensor, leaves
    /// `normal_in_world` as the last render that had them).
    pub fn render(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, store: &dyn TsdfStore, world_from_camera: &Se3, depth_range_m: (f32, f32), normals: bool) -> Result<()> {
        self.set_params(gpu, store, depth_range_m);
        self.set_pose(gpu, world_from_camera)?;
        self.clear(encoder);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("core.raycast"), timestamp_writes: None });
        self.dispatch_in(gpu, &mut pass, normals);
        Ok(())
    }
}

/// The predicted surface of one coarser pyramid level.
#[derive(Debug)]
pub struct PredictedLevel {
    /// Intrinsics of this level.
    pub intrinsics: PinholeIntrinsics,
    /// Predicted vertices, world frame.
    pub vertex_in_world: wgpu::Buffer,
    /// Predicted normals, world frame.
    pub normal_in_world: wgpu::Buffer,
    _params: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

/// The prediction pyramid: level 0 raycast from a pose buffer, the others downsampled.
#[derive(Debug)]
pub struct Predictor {
    finest: RaycastTarget,
    coarser: Vec<PredictedLevel>,
}

impl Predictor {
    /// `levels` levels of `intrinsics` (level 0 = full resolution), rendered from the pose in
    /// `pose`; `depth_hint` is the depth fused at that pose (see
    /// [`RaycastTarget::with_pose_buffer`]).
    pub fn new(gpu: &Gpu, store: &dyn TsdfStore, intrinsics: PinholeIntrinsics, levels: usize, pose: &wgpu::Buffer, depth_hint: Option<DepthHint<'_>>, depth_range_m: (f32, f32)) -> Self {
        let finest = RaycastTarget::with_pose_buffer(gpu, store, intrinsics, pose, depth_hint, "predicted[0]");
        finest.set_params(gpu, store, depth_range_m);
        let mut coarser: Vec<PredictedLevel> = Vec::new();
        for l in 1..levels.max(1) {
            let (fine_k, k) = (intrinsics.pyramid_level(l - 1), intrinsics.pyramid_level(l));
            let n = k.pixel_count();
            let vertex_in_world = gpu.storage_buffer::<[f32; 4]>(&format!("core.predicted[{l}].vertex_in_world"), n);
            let normal_in_world = gpu.storage_buffer::<[f32; 4]>(&format!("core.predicted[{l}].normal_in_world"), n);
            let p = PredictionDownParams { src_width_px: fine_k.width_px, src_height_px: fine_k.height_px, dst_width_px: k.width_px, dst_height_px: k.height_px };
            let params = gpu.uniform_buffer(&format!("core.prediction_down.params[{l}]"), &p);
            let (vertex_fine, normal_fine) = match coarser.last() {
                Some(c) => (&c.vertex_in_world, &c.normal_in_world),
                None => (&finest.vertex_in_world, &finest.normal_in_world),
            };
            let bind_group = prediction_down::Bindings { params: &params, vertex_fine, normal_fine, vertex_coarse: &vertex_in_world, normal_coarse: &normal_in_world }.bind_group(gpu);
            coarser.push(PredictedLevel { intrinsics: k, vertex_in_world, normal_in_world, _params: params, bind_group });
        }
        Self { finest, coarser }
    }

    /// The raycast images of the finest level (vertex, normal, depth, shaded, colour).
    pub fn finest(&self) -> &RaycastTarget {
        &self.finest
    }

    /// Levels, finest first.
    pub fn levels(&self) -> usize {
        1 + self.coarser.len()
    }

    /// The predicted vertex and normal maps of `level`.
    pub fn level(&self, level: usize) -> (&wgpu::Buffer, &wgpu::Buffer) {
        match level {
            0 => (&self.finest.vertex_in_world, &self.finest.normal_in_world),
            l => (&self.coarser[l - 1].vertex_in_world, &self.coarser[l - 1].normal_in_world),
        }
    }

    /// Changes the depth range of the raycast.
    pub fn set_depth_range(&self, gpu: &Gpu, store: &dyn TsdfStore, depth_range_m: (f32, f32)) {
        self.finest.set_params(gpu, store, depth_range_m);
    }

    /// Records the coarser levels' downsampling of the finest prediction alone (what `bench`
    /// times).
    pub fn encode_downsampling(&self, gpu: &Gpu, frame: &mut FrameEncoder<'_>, stage: &'static str) {
        self.dispatch_downsampling(gpu, &mut frame.stage(stage));
    }

    /// Records each coarser level's downsampling into an open compute pass.
    fn dispatch_downsampling(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        for c in &self.coarser {
            gpu.kernels.prediction_down.dispatch_in(pass, &c.bind_group, [c.intrinsics.width_px, c.intrinsics.height_px, 1]);
        }
    }

    /// Records the raycast (skipped on the GPU when the pose is disabled) and the downsampling
    /// as stage `stage` of a frame.
    pub fn encode(&self, gpu: &Gpu, frame: &mut FrameEncoder<'_>, stage: &'static str) {
        self.finest.clear(frame.encoder());
        let mut pass = frame.stage(stage);
        self.finest.dispatch_in(gpu, &mut pass, true);
        self.dispatch_downsampling(gpu, &mut pass);
    }
}
