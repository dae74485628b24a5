// SPDX-License-Identifier: MIT
//! Seed 000's virtual depth sensor: the map raycast at any pose and intrinsics (the predictor's
//! [`RaycastTarget`]), turned into a raw depth image by `depth_sensor` (exact, or a seeded
//! Kinect v1 measurement: [`KinectModel`]), with the model's colour. Frames are rendered into a
//! small ring and read back a frame late, so the GPU renders the next pose while the host writes
//! the last one.

use crate::engine::{FrameEncoder, ReadbackRing, StageTime, StageTimer};
use crate::fusion::predictor::{RaycastPart, RaycastTarget};
use crate::kernels::{GpuIntrinsics, KernelPipeline};
use crate::kernels::depth_sensor::{self, DepthSensorParams};
use crate::kernels::projector_shadow::{self, ProjectorShadowParams};
use crate::preprocess::DepthPreprocessor;
use crate::tsdf::TsdfStore;
use crate::{Error, Gpu, PinholeIntrinsics, Result, Se3};

/// The Kinect v1 (structured light, PrimeSense PS1080) as `depth_sensor` models it. The noise
/// terms are Nguyen, Izadi and Lovell's (2012) fit; the geometry is the sensor's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KinectModel {
    /// Offset of the IR projector from the IR camera along the camera's +x, metres (7.5 cm;
    /// seen from behind the sensor the projector is on the right, so shadows fall to the left
    /// of foreground objects, as in real Kinect depth images).
    pub baseline_m: f32,
    /// Focal length of the IR camera the disparity is measured in, pixels (≈ 580 at 640x480;
    /// Khoshelham and Elberink 2012), independent of the rendered image's intrinsics.
    pub disparity_focal_px: f32,
    /// Disparity steps per pixel: the PS1080 reports disparity in 1/8 pixel, so depth comes in
    /// steps of z² / (8 b f): 2.9 mm at 1 m, 26 mm at 3 m.
    pub disparity_subpixel: f32,
    /// Largest incidence angle (ray to surface normal) with a return, degrees. Beyond it the
    /// projected dots are stretched past recognition; Nguyen et al. measured returns up to about
    /// 80°, with the noise growing without bound towards 90°.
    pub max_incidence_deg: f32,
    /// A neighbour whose disparity differs by more than this many pixels marks a depth step the
    /// pattern matcher cannot resolve (the correlation window sees two shifts of the pattern);
    /// one pixel of disparity is b·f/z² · Δz: a 2.3 cm step at 1 m, 21 cm at 3 m.
    pub edge_disparity_px: f32,
    /// Nearest depth with a return, metres (the PS1080's near limit).
    pub min_depth_m: f32,
    /// Farthest depth with a return, metres (OpenNI's limit for the PS1080 is 10 m; beyond 8 m
    /// the returns are too sparse and coarse to matter).
    pub max_depth_m: f32,
}

impl Default for KinectModel {
    fn default() -> Self {
        Self { baseline_m: 0.075, disparity_focal_px: 580.0, disparity_subpixel: 8.0, max_incidence_deg: 80.0, edge_disparity_px: 1.0, min_depth_m: 0.4, max_depth_m: 8.0 }
    }
}

impl KinectModel {
    /// `depth_sensor`'s parameters for images of `k`, in raw units of `units_per_metre`, with
    /// the noise on or off (seed and frame index 0; planar depth).
    pub fn params(&self, k: GpuIntrinsics, units_per_metre: f32, noise: bool) -> DepthSensorParams {
        DepthSensorParams {
            intrinsics: k,
            units_per_metre,
            min_depth_m: self.min_depth_m,
            max_depth_m: self.max_depth_m,
            radial: 0,
            noise: u32::from(noise),
            seed: 0,
            frame_index: 0,
            baseline_m: self.baseline_m,
            disparity_focal_px: self.disparity_focal_px,
            disparity_subpixel: self.disparity_subpixel,
            max_incidence_rad: self.max_incidence_deg.to_radians(),
            edge_disparity_px: self.edge_disparity_px,
            ..Default::default()
        }
    }

    /// `projector_shadow`'s parameters for images of `k`: the depth-step tolerance converted
    /// from the IR camera's pixels to the image's.
    pub fn shadow_params(&self, k: GpuIntrinsics) -> ProjectorShadowParams {
        ProjectorShadowParams { intrinsics: k, baseline_m: self.baseline_m, edge_disparity_px: self.edge_disparity_px * k.fx_px / self.disparity_focal_px, ..Default::default() }
    }
}

/// How a [`VirtualSensor`] renders.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorOptions {
    /// Raw units per metre of the depth images (TUM: 5000).
    pub units_per_metre: f32,
    /// Distance along each ray instead of depth along z.
    pub radial: bool,
    /// The Kinect model and the noise's seed; `None`: exact depth.
    pub noise: Option<(KinectModel, u32)>,
    /// The returned range, metres (the model's by default).
    pub depth_range_m: (f32, f32),
    /// Also read back the map's colour.
    pub color: bool,
    /// Also read back the exact hit of each pixel's ray (the raycast's depth along z, before
    /// any noise): what marking rays through never-observed space needs.
    pub hits: bool,
    /// Time each stage of a frame on the GPU ([`SimulatedFrame::stages`]), where the device
    /// has timestamp queries: what `simulate --bench` reports.
    pub timed: bool,
}

impl Default for SensorOptions {
    fn default() -> Self {
        let m = KinectModel::default();
        Self { units_per_metre: crate::camera::TUM_DEPTH_UNITS_PER_METRE, radial: false, noise: None, depth_range_m: (m.min_depth_m, m.max_depth_m), color: false, hits: false, timed: false }
    }
}

impl SensorOptions {
    fn validate(&self) -> Result<()> {
        let (near, far) = self.depth_range_m;
        if !(self.units_per_metre.is_finite() && self.units_per_metre > 0.0) {
            return Err(Error::InvalidConfig(format!("depth units per metre must be positive, not {}", self.units_per_metre)));
        }
        if !(near.is_finite() && far.is_finite() && near >= 0.0 && far > near) {
            return Err(Error::InvalidConfig(format!("the sensor's depth range [{near}, {far}] m is empty")));
        }
        if far * self.units_per_metre > 65535.0 + 0.5 * self.units_per_metre {
            return Err(Error::InvalidConfig(format!("{far} m is past the u16 scale at {} units per metre ({:.1} m)", self.units_per_metre, 65535.0 / self.units_per_metre)));
        }
        Ok(())
    }
}

/// One simulated frame.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedFrame {
    /// The caller's tag for it (e.g. its index).
    pub tag: u64,
    /// Raw depth, one u16 per pixel, row-major (0: no return).
    pub depth_units: Vec<u16>,
    /// The map's colour at each pixel (RGB8; black where nothing was hit), when asked for.
    pub color_rgb8: Option<Vec<[u8; 3]>>,
    /// The exact hit of each pixel's ray, depth along z in metres (NaN: none within the range),
    /// when asked for ([`SensorOptions::hits`]).
    pub hit_m: Option<Vec<f32>>,
    /// GPU time of each stage (range tiles, rays, with noise normals and projector shadow,
    /// sensor) when the sensor is timed ([`SensorOptions::timed`]) and the device has
    /// timestamps; empty otherwise.
    pub stages: Vec<StageTime>,
}

/// Frames rendered and not yet read back, at most.
const IN_FLIGHT: usize = 2;

/// A depth sensor at any pose in a map.
#[derive(Debug)]
pub struct VirtualSensor {
    target: RaycastTarget,
    params: DepthSensorParams,
    params_buffer: wgpu::Buffer,
    depth_raw: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// With noise: `projector_shadow`'s parameters, mask and bind group.
    shadow: Option<(wgpu::Buffer, wgpu::Buffer, wgpu::BindGroup)>,
    options: SensorOptions,
    readback: ReadbackRing<u64>,
    /// With [`SensorOptions::timed`] on a device with timestamps: the frame's stage timer, and
    /// the names of the stages it times (in the order their timestamps are read back).
    timer: Option<(StageTimer, Vec<&'static str>)>,
    /// `depth_sensor` without its noise model, for a sensor of exact depth (one pipeline a device,
    /// shared by every exact sensor: `DeferredPipeline::variant`).
    exact: Option<KernelPipeline>,
}

impl VirtualSensor {
    /// A sensor with `intrinsics` in `store`.
    pub fn new(gpu: &Gpu, store: &dyn TsdfStore, intrinsics: PinholeIntrinsics, options: SensorOptions) -> Result<Self> {
        options.validate()?;
        if intrinsics.pixel_count() == 0 || !(intrinsics.fx_px > 0.0 && intrinsics.fy_px > 0.0) {
            return Err(Error::InvalidConfig(format!("the sensor's intrinsics are degenerate: {intrinsics:?}")));
        }
        let target = RaycastTarget::new(gpu, store, intrinsics, "sensor");
        target.set_params(gpu, store, options.depth_range_m);
        let (model, seed) = options.noise.unwrap_or((KinectModel::default(), 0));
        let mut params = model.params(GpuIntrinsics::from(intrinsics), options.units_per_metre, options.noise.is_some());
        params.seed = seed;
        params.radial = u32::from(options.radial);
        (params.min_depth_m, params.max_depth_m) = options.depth_range_m;
        let params_buffer = gpu.uniform_buffer("core.depth_sensor.params", &params);
        let n = intrinsics.pixel_count();
        let depth_raw = gpu.storage_buffer::<u32>("core.depth_sensor.depth_raw", n.div_ceil(2));
        // The mask is read only with noise; without, one word stands in for it.
        let mask = gpu.storage_buffer::<u32>("core.projector_shadow.shadow", if options.noise.is_some() { n } else { 1 });
        let shadow = options.noise.map(|(model, _)| {
            let p = gpu.uniform_buffer("core.projector_shadow.params", &model.shadow_params(GpuIntrinsics::from(intrinsics)));
            let bind_group = projector_shadow::Bindings { params: &p, depth_m: &target.depth_m, shadow: &mask }.bind_group(gpu);
            (p, mask.clone(), bind_group)
        });
        let bind_group = depth_sensor::Bindings {
            params: &params_buffer,
            pose: target.pose_buffer(),
            depth_m: &target.depth_m,
            vertex_in_world: &target.vertex_in_world,
            normal_in_world: &target.normal_in_world,
            shadow: &mask,
            depth_raw: &depth_raw,
        }
        .bind_group(gpu);
        let timer = options.timed.then(|| StageTimer::new(gpu, "core.sensor")).flatten().map(|t| (t, Vec::new()));
        let bytes = Self::readback_bytes(n, options.color, options.hits) + if timer.is_some() { StageTimer::BYTES } else { 0 };
        let readback = ReadbackRing::new(gpu, "core.sensor", bytes, IN_FLIGHT);
        let exact = options.noise.is_none().then(|| gpu.kernels.depth_sensor.variant(&[("NOISE_MODEL", 0.0)]));
        Ok(Self { target, params, params_buffer, depth_raw, bind_group, shadow, options, readback, timer, exact })
    }

    /// The readback layout: depth words, then colour (RGBA8 per pixel), then hits (f32), then
    /// (timed) the stages' timestamps.
    fn readback_bytes(pixels: usize, color: bool, hits: bool) -> u64 {
        4 * pixels.div_ceil(2) as u64 + if color { 4 * pixels as u64 } else { 0 } + if hits { 4 * pixels as u64 } else { 0 }
    }

    /// The intrinsics it renders with.
    pub fn intrinsics(&self) -> PinholeIntrinsics {
        self.target.intrinsics
    }

    /// The raycast it reads (depth, vertices and colour of the last render; normals only with
    /// noise, whose incidence angle reads them).
    pub fn target(&self) -> &RaycastTarget {
        &self.target
    }

    /// The raw depth of the last render (two u16 per word, as `depth_colormap` reads it).
    pub fn depth_raw(&self) -> &wgpu::Buffer {
        &self.depth_raw
    }

    /// Whether another frame can be submitted without collecting one first.
    pub fn can_submit(&self) -> bool {
        self.readback.free_slot().is_some()
    }

    /// Records the render at `world_from_camera` (the `frame_index`-th frame of the noise
    /// stream) into `encoder`, without a readback (a view that stays on the GPU).
    pub fn encode(&mut self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, store: &dyn TsdfStore, world_from_camera: &Se3, frame_index: u32) -> Result<()> {
        // Only the noise model reads the normals (the incidence angle).
        self.target.render(gpu, encoder, store, world_from_camera, self.options.depth_range_m, self.options.noise.is_some())?;
        self.set_frame(gpu, frame_index);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("core.depth_sensor"), timestamp_writes: None });
        self.dispatch_sensor(gpu, &mut pass);
        Ok(())
    }

    /// The same render as [`Self::encode`], each part in a stage of its own: range tiles,
    /// rays, (with noise) normals and projector shadow, sensor.
    fn encode_stages(&mut self, gpu: &Gpu, frame: &mut FrameEncoder<'_>, store: &dyn TsdfStore, world_from_camera: &Se3, frame_index: u32) -> Result<()> {
        self.target.set_params(gpu, store, self.options.depth_range_m);
        self.target.set_pose(gpu, world_from_camera)?;
        self.target.encode_part(gpu, frame, "range tiles", RaycastPart::RangeTiles);
        self.target.encode_part(gpu, frame, "rays", RaycastPart::Rays);
        if self.options.noise.is_some() {
            self.target.encode_part(gpu, frame, "normals", RaycastPart::Normals);
        }
        self.set_frame(gpu, frame_index);
        if self.shadow.is_some() {
            self.dispatch_shadow(gpu, &mut frame.stage("projector shadow"));
        }
        self.dispatch_depth(gpu, &mut frame.stage("sensor"));
        Ok(())
    }

    fn set_frame(&mut self, gpu: &Gpu, frame_index: u32) {
        self.params.frame_index = frame_index;
        gpu.write_buffer(&self.params_buffer, std::slice::from_ref(&self.params));
    }

    /// Records `projector_shadow` (with noise) and `depth_sensor` into an open pass.
    fn dispatch_sensor(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        self.dispatch_shadow(gpu, pass);
        self.dispatch_depth(gpu, pass);
    }

    /// Records `projector_shadow` into an open pass (with noise; nothing without).
    fn dispatch_shadow(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        if let Some((_, _, shadow)) = &self.shadow {
            gpu.kernels.projector_shadow.dispatch_in(pass, shadow, [self.target.intrinsics.height_px, 1, 1]);
        }
    }

    /// Records `depth_sensor` into an open pass.
    fn dispatch_depth(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        let words = self.target.intrinsics.pixel_count().div_ceil(2) as u32;
        let kernel: &KernelPipeline = self.exact.as_ref().unwrap_or(&gpu.kernels.depth_sensor);
        kernel.dispatch_in(pass, &self.bind_group, [words, 1, 1]);
    }

    /// Records the render at `world_from_camera` and copies its raw depth into `pre`'s (the
    /// same two-u16-a-word layout): the fused map's depth in place of a frame's, preprocessed
    /// and segmented with no readback (`webfusion planes --from-model`, the page's planes of
    /// the fused map). `pre`'s colour is the caller's to upload. Errors when the preprocessor's
    /// image size, intrinsics or depth scale are not the sensor's.
    pub fn encode_into(&mut self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, store: &dyn TsdfStore, world_from_camera: &Se3, frame_index: u32, pre: &DepthPreprocessor) -> Result<()> {
        let (k, calibration) = (self.target.intrinsics, pre.calibration());
        let want = calibration.intrinsics;
        if (want.width_px, want.height_px) != (k.width_px, k.height_px) {
            return Err(Error::FrameSize { what: "rendered model depth", got_width: k.width_px, got_height: k.height_px, want_width: want.width_px, want_height: want.height_px });
        }
        if want != k {
            return Err(Error::InvalidConfig(format!("the sensor renders with {k:?}, the preprocessor back-projects with {want:?}")));
        }
        if calibration.depth_units_per_metre != self.options.units_per_metre {
            return Err(Error::InvalidConfig(format!(
                "the sensor renders {} depth units per metre, the preprocessor reads {}",
                self.options.units_per_metre, calibration.depth_units_per_metre
            )));
        }
        self.encode(gpu, encoder, store, world_from_camera, frame_index)?;
        encoder.copy_buffer_to_buffer(&self.depth_raw, 0, &pre.depth_raw, 0, self.depth_raw.size());
        Ok(())
    }

    /// Renders a frame at `world_from_camera` and starts reading it back; collect it with
    /// [`Self::collect`] or [`Self::wait`]. Errors when every slot is in flight.
    pub fn submit(&mut self, gpu: &Gpu, store: &dyn TsdfStore, world_from_camera: &Se3, frame_index: u32, tag: u64) -> Result<()> {
        if !self.can_submit() {
            return Err(Error::InvalidConfig("every simulated frame slot is in flight: collect one first".into()));
        }
        let timer = self.timer.take();
        let mut frame = FrameEncoder::new(gpu, "core.sensor.frame", timer.as_ref().map(|(t, _)| t));
        let recorded = self.encode_stages(gpu, &mut frame, store, world_from_camera, frame_index);
        let (slot, buffer) = self.readback.free_slot().expect("checked");
        let encoder = frame.encoder();
        let depth_bytes = self.depth_raw.size();
        encoder.copy_buffer_to_buffer(&self.depth_raw, 0, buffer, 0, depth_bytes);
        let color_bytes = if self.options.color { self.target.color_rgba8.size() } else { 0 };
        if self.options.color {
            encoder.copy_buffer_to_buffer(&self.target.color_rgba8, 0, buffer, depth_bytes, color_bytes);
        }
        let hits_bytes = if self.options.hits { self.target.depth_m.size() } else { 0 };
        if self.options.hits {
            encoder.copy_buffer_to_buffer(&self.target.depth_m, 0, buffer, depth_bytes + color_bytes, hits_bytes);
        }
        let (commands, stages) = frame.finish(Some((buffer, depth_bytes + color_bytes + hits_bytes)));
        self.timer = timer.map(|(t, _)| (t, stages));
        recorded?;
        let submission = gpu.submit([commands]);
        self.readback.start(gpu, slot, submission, tag);
        Ok(())
    }

    /// Frames that finished, oldest first, without waiting.
    pub fn collect(&mut self, gpu: &Gpu) -> Result<Vec<SimulatedFrame>> {
        let done = self.readback.collect(gpu)?;
        Ok(done.into_iter().map(|r| self.decode(r.tag, &r.bytes)).collect())
    }

    /// Waits for the oldest frame in flight (`None` when none is).
    pub async fn wait(&mut self, gpu: &Gpu) -> Result<Option<SimulatedFrame>> {
        let done = self.readback.wait_oldest(gpu).await?;
        Ok(done.map(|r| self.decode(r.tag, &r.bytes)))
    }

    /// Renders one frame and waits for it.
    pub async fn render(&mut self, gpu: &Gpu, store: &dyn TsdfStore, world_from_camera: &Se3, frame_index: u32) -> Result<SimulatedFrame> {
        while self.readback.in_flight() > 0 {
            self.wait(gpu).await?;
        }
        self.submit(gpu, store, world_from_camera, frame_index, u64::from(frame_index))?;
        self.wait(gpu).await?.ok_or_else(|| Error::InvalidConfig("the simulated frame was not read back".into()))
    }

    fn decode(&self, tag: u64, bytes: &[u8]) -> SimulatedFrame {
        let n = self.target.intrinsics.pixel_count();
        let depth_bytes = self.depth_raw.size() as usize;
        let words: &[u32] = bytemuck::cast_slice(&bytes[..depth_bytes]);
        let depth_units = (0..n).map(|i| (words[i / 2] >> (16 * (i & 1))) as u16).collect();
        let color_rgb8 = self.options.color.then(|| {
            let rgba: &[u32] = bytemuck::cast_slice(&bytes[depth_bytes..depth_bytes + 4 * n]);
            rgba.iter().map(|&c| {
                let b = c.to_le_bytes();
                [b[0], b[1], b[2]]
            }).collect()
        });
        let hits_at = depth_bytes + if self.options.color { 4 * n } else { 0 };
        let hit_m = self.options.hits.then(|| bytes[hits_at..hits_at + 4 * n].chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect());
        let stages = self.timer.as_ref().map_or_else(Vec::new, |(timer, names)| {
            let at = hits_at + if self.options.hits { 4 * n } else { 0 };
            let ticks: Vec<u64> = bytes[at..at + 16 * names.len()].chunks_exact(8).map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes"))).collect();
            timer.stage_times(names, &ticks)
        });
        SimulatedFrame { tag, depth_units, color_rgb8, hit_m, stages }
    }
}
