// SPDX-License-Identifier: MIT
//! The mapper stage: a TSDF store and the integration of a depth (and colour) image into it at
//! the pose a pose buffer holds — the tracker's, or one the host writes (pose-driven mapping).

use crate::kernels::GpuIntrinsics;
use crate::kernels::tsdf_integrate::{self, TsdfIntegrateParams};
use crate::preprocess::DepthPreprocessor;
use crate::tsdf::{DenseTsdfVolume, TsdfConfig, TsdfStore};
use crate::{Gpu, Result};

/// A dense TSDF volume and its integration kernel, bound to one preprocessor and pose buffer.
#[derive(Debug)]
pub struct Mapper {
    volume: DenseTsdfVolume,
    _params: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

impl Mapper {
    /// A volume of `config` with its voxel (0, 0, 0) corner at `origin_in_world`, fusing the
    /// preprocessor's depth (unfiltered when the filter is on, as KinectFusion does) and colour
    /// at the pose in `pose` (a `CameraPose` at offset 0).
    pub fn new(gpu: &Gpu, config: TsdfConfig, origin_in_world: [f32; 3], preprocessor: &DepthPreprocessor, pose: &wgpu::Buffer) -> Result<Self> {
        let volume = DenseTsdfVolume::new(gpu, config, origin_in_world)?;
        let p = TsdfIntegrateParams {
            volume: volume.desc(),
            intrinsics: GpuIntrinsics::from(preprocessor.levels[0].intrinsics),
            color_enabled: u32::from(volume.has_color()),
            max_depth_m: preprocessor.config().max_depth_m,
            ..Default::default()
        };
        let params = gpu.uniform_buffer("core.tsdf_integrate.params", &p);
        let depth_m = Self::fused_depth(preprocessor);
        let bind_group =
            tsdf_integrate::Bindings { params: &params, pose, depth_m, color: &preprocessor.color, tsdf_volume: volume.voxels(), color_volume: volume.colors(), surface_bricks: volume.surface_bricks() }.bind_group(gpu);
        Ok(Self { volume, _params: params, bind_group })
    }

    /// The depth this mapper fuses (the unfiltered depth when the bilateral filter is on).
    pub fn fused_depth(preprocessor: &DepthPreprocessor) -> &wgpu::Buffer {
        preprocessor.depth_unfiltered_m.as_ref().unwrap_or(&preprocessor.levels[0].depth_m)
    }

    /// The store.
    pub fn volume(&self) -> &DenseTsdfVolume {
        &self.volume
    }

    /// Records the integration (skipped on the GPU when the pose is disabled).
    pub fn encode_in(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        let d = self.volume.desc();
        gpu.kernels.tsdf_integrate.dispatch_in(pass, &self.bind_group, [d.dim_x, d.dim_y, 1]);
    }
}
