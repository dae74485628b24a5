// SPDX-License-Identifier: MIT
//! Depth and colour preprocessing on the GPU (KinectFusion's surface measurement, 000-digest
//! §1.3 step 2; Boots' filtering and normal estimation, 003-digest §4.2).
//!
//! Per frame: raw depth -> metres -> bilateral filter (optional) -> pyramid of depth levels
//! (edge-aware 2x2 block average) -> per level a vertex map and camera-facing unit normals
//! (the crossed central-difference gradients: `vertex_normals` alone, or after
//! `vertex_gradients` when a separable Gaussian smooths the gradients, its x pass in the
//! first kernel and its y pass in the second). Colour becomes float RGB and a BT.601
//! intensity image. Invalid samples are NaN throughout.

use crate::kernels::{
    GpuIntrinsics, KernelPipeline, Kernels, bilateral_filter::BilateralFilterParams, color_to_float::ColorToFloatParams,
    depth_pyramid_down::DepthPyramidDownParams, depth_to_metres::DepthToMetresParams, intensity_pyramid_down::IntensityPyramidDownParams,
    vertex_gradients::VertexGradientsParams, vertex_map::VertexMapParams, vertex_normals::VertexNormalsParams,
};
use crate::{ColorImage, Error, Gpu, PinholeIntrinsics, RgbdCalibration, RgbdFrame, Result};

/// Nearest depth kept, metres (Kinect v1 reads nothing reliable closer than about 0.4 m).
pub const DEFAULT_MIN_DEPTH_M: f32 = 0.3;
/// Farthest depth kept, metres (Boots' `maxDepth`; Kinect v1 noise grows with z^2 beyond).
pub const DEFAULT_MAX_DEPTH_M: f32 = 5.0;
/// Bilateral window radius, pixels: a 7x7 window.
pub const DEFAULT_BILATERAL_RADIUS_PX: u32 = 3;
/// Bilateral spatial sigma, pixels.
pub const DEFAULT_BILATERAL_SIGMA_SPACE_PX: f32 = 3.0;
/// Bilateral range sigma, metres (KinectFusion's PCL implementation uses 30 mm).
pub const DEFAULT_BILATERAL_SIGMA_RANGE_M: f32 = 0.03;
/// Pyramid levels, full resolution included (KinectFusion uses 3).
pub const DEFAULT_PYRAMID_LEVELS: usize = 3;
/// A block sample this far behind the block's nearest sample is left out of the coarse
/// average, metres (3 x the bilateral range sigma, as KinectFusion's pyrDown).
pub const DEFAULT_PYRAMID_MAX_DEPTH_DIFF_M: f32 = 0.09;
/// Gradient smoothing radius, pixels (taps each side).
pub const DEFAULT_GRADIENT_SMOOTH_RADIUS_PX: u32 = 2;
/// Gradient smoothing sigma, pixels.
pub const DEFAULT_GRADIENT_SMOOTH_SIGMA_PX: f32 = 1.5;
/// Largest gradient smoothing radius accepted, pixels (each invocation of `vertex_gradients`
/// differentiates 2r+1 pixels).
pub const MAX_GRADIENT_SMOOTH_RADIUS_PX: u32 = 16;
/// Squared norm of the gradient cross product (m^4) at or below which no normal is emitted:
/// well under any real surface patch (1 mm x 1 mm gradients give 1e-12).
pub const DEFAULT_MIN_CROSS_NORM_SQ: f32 = 1e-20;

/// Bilateral filter settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BilateralConfig {
    /// Window radius, pixels.
    pub radius_px: u32,
    /// Spatial sigma, pixels.
    pub sigma_space_px: f32,
    /// Range sigma, metres.
    pub sigma_range_m: f32,
}

impl Default for BilateralConfig {
    fn default() -> Self {
        Self { radius_px: DEFAULT_BILATERAL_RADIUS_PX, sigma_space_px: DEFAULT_BILATERAL_SIGMA_SPACE_PX, sigma_range_m: DEFAULT_BILATERAL_SIGMA_RANGE_M }
    }
}

/// Gradient smoothing settings (Boots).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GradientSmoothingConfig {
    /// Taps on each side.
    pub radius_px: u32,
    /// Gaussian sigma, pixels.
    pub sigma_px: f32,
}

impl Default for GradientSmoothingConfig {
    fn default() -> Self {
        Self { radius_px: DEFAULT_GRADIENT_SMOOTH_RADIUS_PX, sigma_px: DEFAULT_GRADIENT_SMOOTH_SIGMA_PX }
    }
}

/// Creation-time preprocessing settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreprocessConfig {
    /// Nearest valid depth, metres.
    pub min_depth_m: f32,
    /// Farthest valid depth, metres.
    pub max_depth_m: f32,
    /// Bilateral filter, or `None` for no filter.
    pub bilateral: Option<BilateralConfig>,
    /// Gradient smoothing before the normal cross product, or `None`.
    pub gradient_smoothing: Option<GradientSmoothingConfig>,
    /// Pyramid levels including full resolution (1..=4).
    pub pyramid_levels: usize,
    /// See [`DEFAULT_PYRAMID_MAX_DEPTH_DIFF_M`].
    pub pyramid_max_depth_diff_m: f32,
    /// See [`DEFAULT_MIN_CROSS_NORM_SQ`].
    pub min_cross_norm_sq: f32,
}

impl Default for PreprocessConfig {
    fn default() -> Self {
        Self {
            min_depth_m: DEFAULT_MIN_DEPTH_M,
            max_depth_m: DEFAULT_MAX_DEPTH_M,
            bilateral: Some(BilateralConfig::default()),
            gradient_smoothing: Some(GradientSmoothingConfig::default()),
            pyramid_levels: DEFAULT_PYRAMID_LEVELS,
            pyramid_max_depth_diff_m: DEFAULT_PYRAMID_MAX_DEPTH_DIFF_M,
            min_cross_norm_sq: DEFAULT_MIN_CROSS_NORM_SQ,
        }
    }
}

impl PreprocessConfig {
    /// Rejects settings the kernels cannot honour.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::InvalidConfig(m));
        if !(self.min_depth_m >= 0.0 && self.max_depth_m > self.min_depth_m) {
            return bad(format!("depth range [{}, {}] m is empty", self.min_depth_m, self.max_depth_m));
        }
        if !(1..=4).contains(&self.pyramid_levels) {
            return bad(format!("pyramid_levels = {} (must be 1..=4)", self.pyramid_levels));
        }
        if let Some(b) = self.bilateral
            && !(b.sigma_space_px > 0.0 && b.sigma_range_m > 0.0 && b.radius_px <= 16)
        {
            return bad(format!("bilateral sigmas must be > 0 and radius <= 16, got {b:?}"));
        }
        if let Some(g) = self.gradient_smoothing
            && !(g.sigma_px > 0.0 && g.radius_px <= MAX_GRADIENT_SMOOTH_RADIUS_PX)
        {
            return bad(format!("gradient smoothing sigma must be > 0 and radius <= {MAX_GRADIENT_SMOOTH_RADIUS_PX}, got {g:?}"));
        }
        if !(self.pyramid_max_depth_diff_m > 0.0) {
            return bad("pyramid_max_depth_diff_m must be > 0".into());
        }
        Ok(())
    }
}

/// The kernel parameters of each stage, built in one place for the GPU chain and its CPU
/// twin (`cpu::preprocess`), so the two cannot drift apart.
impl PreprocessConfig {
    /// `depth_to_metres` at full resolution.
    pub fn depth_to_metres_params(&self, calibration: &RgbdCalibration) -> DepthToMetresParams {
        let k = calibration.intrinsics;
        DepthToMetresParams {
            width_px: k.width_px,
            height_px: k.height_px,
            metres_per_unit: calibration.metres_per_depth_unit(),
            min_depth_m: self.min_depth_m,
            max_depth_m: self.max_depth_m,
            ..Default::default()
        }
    }

    /// `depth_pyramid_down` from level `fine` to level `coarse`.
    pub fn depth_pyramid_down_params(&self, fine: &PinholeIntrinsics, coarse: &PinholeIntrinsics) -> DepthPyramidDownParams {
        DepthPyramidDownParams {
            src_width_px: fine.width_px,
            src_height_px: fine.height_px,
            dst_width_px: coarse.width_px,
            dst_height_px: coarse.height_px,
            max_depth_diff_m: self.pyramid_max_depth_diff_m,
            ..Default::default()
        }
    }

    /// `vertex_gradients` at a level with intrinsics `k`, when the gradients are smoothed.
    pub fn vertex_gradients_params(&self, k: &PinholeIntrinsics) -> Option<VertexGradientsParams> {
        self.gradient_smoothing.map(|g| VertexGradientsParams { width_px: k.width_px, height_px: k.height_px, radius_px: g.radius_px, sigma_px: g.sigma_px })
    }

    /// `vertex_normals` at a level with intrinsics `k` (radius 0 without smoothing).
    pub fn vertex_normals_params(&self, k: &PinholeIntrinsics) -> VertexNormalsParams {
        let (radius_px, sigma_px) = self.gradient_smoothing.map_or((0, 1.0), |g| (g.radius_px, g.sigma_px));
        VertexNormalsParams { width_px: k.width_px, height_px: k.height_px, radius_px, sigma_px, min_cross_norm_sq: self.min_cross_norm_sq, ..Default::default() }
    }
}

impl BilateralConfig {
    /// `bilateral_filter` at full resolution.
    pub fn params(&self, k: &PinholeIntrinsics) -> BilateralFilterParams {
        BilateralFilterParams {
            width_px: k.width_px,
            height_px: k.height_px,
            radius_px: self.radius_px,
            sigma_space_px: self.sigma_space_px,
            sigma_range_m: self.sigma_range_m,
            ..Default::default()
        }
    }
}

/// One level of the depth/vertex/normal pyramid.
#[derive(Debug)]
pub struct PyramidLevel {
    /// Intrinsics of this level.
    pub intrinsics: PinholeIntrinsics,
    /// Depth, metres, f32 per pixel (filtered at level 0 when the filter is on).
    pub depth_m: wgpu::Buffer,
    /// Vertices (x, y, z, 1), camera frame, metres.
    pub vertex_in_camera: wgpu::Buffer,
    /// Unit normals (nx, ny, nz, 0), camera frame.
    pub normal_in_camera: wgpu::Buffer,
    /// Intensity in [0, 1] (level 0 is [`DepthPreprocessor::intensity`]; coarser levels are
    /// 2x2 block means).
    pub intensity: wgpu::Buffer,
}

/// One recorded dispatch of the preprocessing chain.
#[derive(Debug)]
pub struct Stage {
    /// Kernel name plus level, e.g. `vertex_map[1]`.
    pub name: String,
    pipeline: fn(&Kernels) -> &KernelPipeline,
    bind_group: wgpu::BindGroup,
    invocations: [u32; 3],
    /// Whether it builds the depth pyramid or the vertex and normal maps (which image-feature
    /// consumers do not read).
    geometry: bool,
    _params: wgpu::Buffer,
}

/// GPU buffers and the recorded kernel chain for one camera resolution.
#[derive(Debug)]
pub struct DepthPreprocessor {
    calibration: RgbdCalibration,
    config: PreprocessConfig,
    /// Raw depth, two u16 per u32 word.
    pub depth_raw: wgpu::Buffer,
    /// RGB8 bytes, four per u32 word.
    pub rgb8: wgpu::Buffer,
    /// Depth in metres before the bilateral filter (aliases level 0 when the filter is off).
    pub depth_unfiltered_m: Option<wgpu::Buffer>,
    /// Colour (r, g, b, 1) in [0, 1].
    pub color: wgpu::Buffer,
    /// BT.601 intensity in [0, 1].
    pub intensity: wgpu::Buffer,
    /// Pyramid, level 0 = full resolution.
    pub levels: Vec<PyramidLevel>,
    stages: Vec<Stage>,
}

impl DepthPreprocessor {
    /// Allocates buffers and records the chain for `calibration`'s resolution.
    pub fn new(gpu: &Gpu, calibration: RgbdCalibration, config: PreprocessConfig) -> Result<Self> {
        config.validate()?;
        let k0 = calibration.intrinsics;
        if k0.width_px < 2 << config.pyramid_levels || k0.height_px < 2 << config.pyramid_levels {
            return Err(Error::InvalidConfig(format!("{}x{} px is too small for {} pyramid levels", k0.width_px, k0.height_px, config.pyramid_levels)));
        }
        let n0 = k0.pixel_count();
        let depth_raw = gpu.storage_buffer::<u16>("core.preprocess.depth_raw", n0);
        let rgb8 = gpu.storage_buffer::<u8>("core.preprocess.rgb8", 3 * n0);
        let color = gpu.storage_buffer::<[f32; 4]>("core.preprocess.color", n0);
        let intensity = gpu.storage_buffer::<f32>("core.preprocess.intensity[0]", n0);
        let levels: Vec<PyramidLevel> = (0..config.pyramid_levels)
            .map(|l| {
                let k = k0.pyramid_level(l);
                let n = k.pixel_count();
                let name = |what: &str| format!("core.preprocess.{what}[{l}]");
                PyramidLevel {
                    intrinsics: k,
                    depth_m: gpu.storage_buffer::<f32>(&name("depth_m"), n),
                    vertex_in_camera: gpu.storage_buffer::<[f32; 4]>(&name("vertex_in_camera"), n),
                    normal_in_camera: gpu.storage_buffer::<[f32; 4]>(&name("normal_in_camera"), n),
                    intensity: if l == 0 { intensity.clone() } else { gpu.storage_buffer::<f32>(&name("intensity"), n) },
                }
            })
            .collect();
        let depth_unfiltered_m = config.bilateral.map(|_| gpu.storage_buffer::<f32>("core.preprocess.depth_unfiltered_m", n0));
        // Gradients smoothed along x, when smoothing is on: one pair at full resolution serves
        // every level (the levels' dispatches run one after another).
        let gradients = config.gradient_smoothing.map(|_| {
            [gpu.storage_buffer::<[f32; 4]>("core.preprocess.grad_x", n0), gpu.storage_buffer::<[f32; 4]>("core.preprocess.grad_y", n0)]
        });

        use crate::kernels::{bilateral_filter, color_to_float, depth_pyramid_down, depth_to_metres, intensity_pyramid_down, vertex_gradients, vertex_map, vertex_normals};
        let mut stages = Vec::new();
        // Whether a stage builds the geometry (depth pyramid, vertex and normal maps) or the
        // images (metric depth, colour, intensity pyramid).
        const GEOMETRY: bool = true;
        const IMAGES: bool = false;
        let mut push = |geometry: bool, name: String, pipeline: fn(&Kernels) -> &KernelPipeline, params: wgpu::Buffer, bind_group: wgpu::BindGroup, invocations: [u32; 3]| {
            stages.push(Stage { name, pipeline, bind_group, invocations, geometry, _params: params });
        };
        let (w0, h0) = (k0.width_px, k0.height_px);
        let to_metres_out = depth_unfiltered_m.as_ref().unwrap_or(&levels[0].depth_m);
        let params = gpu.uniform_buffer("core.depth_to_metres.params", &config.depth_to_metres_params(&calibration));
        let bg = depth_to_metres::Bindings { params: &params, depth_raw: &depth_raw, depth_m: to_metres_out }.bind_group(gpu);
        push(IMAGES, "depth_to_metres".into(), |k| &k.depth_to_metres, params, bg, [w0, h0, 1]);
        if let (Some(b), Some(unfiltered)) = (config.bilateral, &depth_unfiltered_m) {
            let params = gpu.uniform_buffer("core.bilateral_filter.params", &b.params(&k0));
            let bg = bilateral_filter::Bindings { params: &params, depth_in_m: unfiltered, depth_out_m: &levels[0].depth_m }.bind_group(gpu);
            push(GEOMETRY, "bilateral_filter".into(), |k| &k.bilateral_filter, params, bg, bilateral_filter::invocations(w0, h0));
        }
        for l in 1..levels.len() {
            let (fine, coarse) = (&levels[l - 1], &levels[l]);
            let p = config.depth_pyramid_down_params(&fine.intrinsics, &coarse.intrinsics);
            let inv = [p.dst_width_px, p.dst_height_px, 1];
            let params = gpu.uniform_buffer("core.depth_pyramid_down.params", &p);
            let bg = depth_pyramid_down::Bindings { params: &params, depth_fine_m: &fine.depth_m, depth_coarse_m: &coarse.depth_m }.bind_group(gpu);
            push(GEOMETRY, format!("depth_pyramid_down[{l}]"), |k| &k.depth_pyramid_down, params, bg, inv);
        }
        for (l, level) in levels.iter().enumerate() {
            let k = level.intrinsics;
            let inv = [k.width_px, k.height_px, 1];
            let params = gpu.uniform_buffer("core.vertex_map.params", &VertexMapParams { intrinsics: GpuIntrinsics::from(k) });
            let bg = vertex_map::Bindings { params: &params, depth_m: &level.depth_m, vertex_in_camera: &level.vertex_in_camera }.bind_group(gpu);
            push(GEOMETRY, format!("vertex_map[{l}]"), |k| &k.vertex_map, params, bg, inv);
            if let (Some(p), Some([grad_x, grad_y])) = (config.vertex_gradients_params(&k), &gradients) {
                let params = gpu.uniform_buffer("core.vertex_gradients.params", &p);
                let bg = vertex_gradients::Bindings { params: &params, vertex_in_camera: &level.vertex_in_camera, grad_x, grad_y }.bind_group(gpu);
                push(GEOMETRY, format!("vertex_gradients[{l}]"), |k| &k.vertex_gradients, params, bg, vertex_gradients::invocations(k.width_px, k.height_px));
            }
            let params = gpu.uniform_buffer("core.vertex_normals.params", &config.vertex_normals_params(&k));
            // Without smoothing the gradient bindings are unread: the vertices stand in.
            let [grad_x, grad_y] = gradients.as_ref().map_or([&level.vertex_in_camera; 2], |[x, y]| [x, y]);
            let bg = vertex_normals::Bindings { params: &params, vertex_in_camera: &level.vertex_in_camera, grad_x, grad_y, normal_in_camera: &level.normal_in_camera }.bind_group(gpu);
            push(GEOMETRY, format!("vertex_normals[{l}]"), |k| &k.vertex_normals, params, bg, inv);
        }
        let params = gpu.uniform_buffer("core.color_to_float.params", &ColorToFloatParams { width_px: w0, height_px: h0, ..Default::default() });
        let bg = color_to_float::Bindings { params: &params, rgb8: &rgb8, color: &color, intensity: &intensity }.bind_group(gpu);
        push(IMAGES, "color_to_float".into(), |k| &k.color_to_float, params, bg, [w0, h0, 1]);
        for l in 1..levels.len() {
            let (fine, coarse) = (&levels[l - 1], &levels[l]);
            let p = IntensityPyramidDownParams { src_width_px: fine.intrinsics.width_px, src_height_px: fine.intrinsics.height_px, dst_width_px: coarse.intrinsics.width_px, dst_height_px: coarse.intrinsics.height_px };
            let params = gpu.uniform_buffer("core.intensity_pyramid_down.params", &p);
            let bg = intensity_pyramid_down::Bindings { params: &params, src: &fine.intensity, dst: &coarse.intensity }.bind_group(gpu);
            push(IMAGES, format!("intensity_pyramid_down[{l}]"), |k| &k.intensity_pyramid_down, params, bg, [p.dst_width_px, p.dst_height_px, 1]);
        }

        Ok(Self { calibration, config, depth_raw, rgb8, depth_unfiltered_m, color, intensity, levels, stages })
    }

    /// The calibration this preprocessor was built for.
    pub fn calibration(&self) -> &RgbdCalibration {
        &self.calibration
    }

    /// The settings this preprocessor was built with.
    pub fn config(&self) -> &PreprocessConfig {
        &self.config
    }

    /// The recorded dispatches, in execution order.
    pub fn stages(&self) -> &[Stage] {
        &self.stages
    }

    /// Uploads a frame's depth and colour, checking their sizes.
    pub fn upload(&self, gpu: &Gpu, frame: &RgbdFrame) -> Result<()> {
        self.check_size("depth image", frame.depth.width_px, frame.depth.height_px)?;
        self.check_size("colour image", frame.color.width_px, frame.color.height_px)?;
        gpu.write_buffer(&self.depth_raw, &frame.depth.units);
        gpu.write_buffer(&self.rgb8, &frame.color.rgb8);
        Ok(())
    }

    /// Uploads a colour image alone, checking its size: the depth comes from elsewhere on the
    /// GPU (a virtual sensor's render of the fused map copied into [`Self::depth_raw`]).
    pub fn upload_color(&self, gpu: &Gpu, color: &ColorImage) -> Result<()> {
        self.check_size("colour image", color.width_px, color.height_px)?;
        gpu.write_buffer(&self.rgb8, &color.rgb8);
        Ok(())
    }

    fn check_size(&self, what: &'static str, width_px: u32, height_px: u32) -> Result<()> {
        let k = self.calibration.intrinsics;
        if (width_px, height_px) == (k.width_px, k.height_px) {
            Ok(())
        } else {
            Err(Error::FrameSize { what, got_width: width_px, got_height: height_px, want_width: k.width_px, want_height: k.height_px })
        }
    }

    /// Records the whole chain, each kernel in a compute pass of its own.
    pub fn encode(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder) {
        for ix in 0..self.stages.len() {
            self.encode_stage(gpu, encoder, ix);
        }
    }

    /// Records the whole chain into one open compute pass (the frame engine's preprocess
    /// stage).
    pub fn encode_in(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        for s in &self.stages {
            (s.pipeline)(&gpu.kernels).dispatch_in(pass, &s.bind_group, s.invocations);
        }
    }

    /// Records into one open compute pass only the stages image features read: the metric and
    /// filtered full-resolution depth, the colour and the intensity pyramid; the depth pyramid
    /// and the vertex and normal maps are left out (feature odometry on a preprocessor of its
    /// own).
    pub fn encode_images_in(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        for s in self.stages.iter().filter(|s| !s.geometry) {
            (s.pipeline)(&gpu.kernels).dispatch_in(pass, &s.bind_group, s.invocations);
        }
    }

    /// Records stage `ix` alone (benchmarks time stages one by one).
    pub fn encode_stage(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, ix: usize) {
        let s = &self.stages[ix];
        (s.pipeline)(&gpu.kernels).dispatch(encoder, &s.bind_group, s.invocations);
    }

    /// Uploads, runs and waits: the whole preprocessing of one frame.
    pub async fn run(&self, gpu: &Gpu, frame: &RgbdFrame) -> Result<()> {
        self.upload(gpu, frame)?;
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.preprocess") });
        self.encode(gpu, &mut encoder);
        gpu.submit_and_wait(encoder).await
    }
}

