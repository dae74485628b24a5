// SPDX-License-Identifier: MIT
//! CPU twin of [`crate::preprocess::DepthPreprocessor`]: the same chain of kernels, run with
//! the CPU references, for end-to-end checks and for CPU-only tests of later stages.

use crate::cpu::shared::{pack_bytes, pack_u16_pairs};
use crate::kernels::{GpuIntrinsics, color_to_float::ColorToFloatParams, intensity_pyramid_down::IntensityPyramidDownParams, vertex_map::VertexMapParams};
use crate::preprocess::PreprocessConfig;
use crate::{PinholeIntrinsics, RgbdCalibration, RgbdFrame};

/// One pyramid level computed on the CPU.
#[derive(Clone, Debug)]
pub struct CpuPyramidLevel {
    /// Intrinsics of this level.
    pub intrinsics: PinholeIntrinsics,
    /// Depth, metres.
    pub depth_m: Vec<f32>,
    /// Vertices (x, y, z, 1), camera frame.
    pub vertex_in_camera: Vec<[f32; 4]>,
    /// Unit normals (nx, ny, nz, 0), camera frame.
    pub normal_in_camera: Vec<[f32; 4]>,
    /// Intensity (level 0: BT.601 of the colour; coarser: 2x2 block means).
    pub intensity: Vec<f32>,
}

/// Everything the GPU preprocessor produces, computed on the CPU.
#[derive(Clone, Debug)]
pub struct CpuPreprocessed {
    /// Depth in metres before the bilateral filter.
    pub depth_unfiltered_m: Vec<f32>,
    /// Pyramid, level 0 = full resolution.
    pub levels: Vec<CpuPyramidLevel>,
    /// Colour (r, g, b, 1).
    pub color: Vec<[f32; 4]>,
    /// BT.601 intensity.
    pub intensity: Vec<f32>,
}

/// Runs the preprocessing chain on the CPU, stage for stage as the GPU does.
pub fn preprocess(calibration: &RgbdCalibration, config: &PreprocessConfig, frame: &RgbdFrame) -> CpuPreprocessed {
    let k0 = calibration.intrinsics;
    let (w0, h0) = (k0.width_px, k0.height_px);
    let n0 = k0.pixel_count();
    let mut depth_unfiltered_m = vec![0.0; n0];
    let p = config.depth_to_metres_params(calibration);
    crate::cpu::depth_to_metres(&p, &pack_u16_pairs(&frame.depth.units), &mut depth_unfiltered_m);
    let depth0 = match config.bilateral {
        Some(b) => {
            let mut out = vec![0.0; n0];
            let p = b.params(&k0);
            crate::cpu::bilateral_filter(&p, &depth_unfiltered_m, &mut out);
            out
        }
        None => depth_unfiltered_m.clone(),
    };
    let mut depths = vec![depth0];
    for l in 1..config.pyramid_levels {
        let (fine, coarse) = (k0.pyramid_level(l - 1), k0.pyramid_level(l));
        let p = config.depth_pyramid_down_params(&fine, &coarse);
        let mut out = vec![0.0; coarse.pixel_count()];
        crate::cpu::depth_pyramid_down(&p, &depths[l - 1], &mut out);
        depths.push(out);
    }
    let mut color = vec![[0.0; 4]; n0];
    let mut intensity = vec![0.0; n0];
    crate::cpu::color_to_float(&ColorToFloatParams { width_px: w0, height_px: h0, ..Default::default() }, &pack_bytes(&frame.color.rgb8), &mut color, &mut intensity);
    let mut intensities = vec![intensity.clone()];
    for l in 1..config.pyramid_levels {
        let (fine, coarse) = (k0.pyramid_level(l - 1), k0.pyramid_level(l));
        let p = IntensityPyramidDownParams { src_width_px: fine.width_px, src_height_px: fine.height_px, dst_width_px: coarse.width_px, dst_height_px: coarse.height_px };
        let mut out = vec![0.0; coarse.pixel_count()];
        crate::cpu::intensity_pyramid_down(&p, &intensities[l - 1], &mut out);
        intensities.push(out);
    }
    let levels = depths
        .into_iter()
        .zip(intensities)
        .enumerate()
        .map(|(l, (depth_m, intensity))| {
            let k = k0.pyramid_level(l);
            let n = k.pixel_count();
            let mut vertex_in_camera = vec![[0.0; 4]; n];
            crate::cpu::vertex_map(&VertexMapParams { intrinsics: GpuIntrinsics::from(k) }, &depth_m, &mut vertex_in_camera);
            let (mut grad_x, mut grad_y) = (vec![[0.0; 4]; n], vec![[0.0; 4]; n]);
            if let Some(p) = config.vertex_gradients_params(&k) {
                crate::cpu::vertex_gradients(&p, &vertex_in_camera, &mut grad_x, &mut grad_y);
            }
            let mut normal_in_camera = vec![[0.0; 4]; n];
            crate::cpu::vertex_normals(&config.vertex_normals_params(&k), &vertex_in_camera, &grad_x, &grad_y, &mut normal_in_camera);
            CpuPyramidLevel { intrinsics: k, depth_m, vertex_in_camera, normal_in_camera, intensity }
        })
        .collect();
    CpuPreprocessed { depth_unfiltered_m, levels, color, intensity }
}
