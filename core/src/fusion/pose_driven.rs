// SPDX-License-Identifier: MIT
//! A second composition of the same stages: fusion at given poses, without tracking (seed
//! 000's robot maps from reported poses; the first step of `reconstruct --poses`).
//!
//! ```text
//! preprocess   DepthPreprocessor     as in KinectFusion
//! integrate    Mapper                at the pose the host wrote into its pose buffer
//! predict      Predictor             (optional) the model seen from that pose, for views
//! ```
//!
//! One submission per frame and no readback: the host already knows the pose.

use crate::engine::FrameEncoder;
use crate::fusion::mapper::Mapper;
use crate::fusion::predictor::{DepthHint, Predictor, camera_pose, pose_buffer};
use crate::preprocess::{DepthPreprocessor, PreprocessConfig};
use crate::map::Map;
use crate::tsdf::TsdfConfig;
use crate::{Gpu, Result, RgbdCalibration, RgbdFrame, Se3};

/// Fuses frames at poses the caller gives.
#[derive(Debug)]
pub struct PoseDrivenMapper {
    preprocessor: DepthPreprocessor,
    pose: wgpu::Buffer,
    mapper: Mapper,
    predictor: Option<Predictor>,
}

impl PoseDrivenMapper {
    /// A mapper for `calibration`'s camera whose volume sits as `tsdf.placement` puts it around
    /// `first_world_from_camera`. With `predict`, each frame also raycasts the model from its
    /// pose (the views of the browser app).
    pub fn new(gpu: &Gpu, calibration: RgbdCalibration, preprocess: PreprocessConfig, tsdf: TsdfConfig, first_world_from_camera: &Se3, predict: bool) -> Result<Self> {
        preprocess.validate()?;
        let preprocessor = DepthPreprocessor::new(gpu, calibration, preprocess)?;
        let pose = pose_buffer(gpu, "core.pose_driven.pose", None);
        let mapper = Mapper::new(gpu, tsdf, tsdf.origin_for_first_camera(first_world_from_camera), &preprocessor, &pose)?;
        let predictor = predict.then(|| Predictor::new(gpu, mapper.volume(), calibration.intrinsics, 1, &pose, Some(DepthHint::from_preprocessor(&preprocessor)), (preprocess.min_depth_m, preprocess.max_depth_m)));
        Ok(Self { preprocessor, pose, mapper, predictor })
    }

    /// The TSDF store.
    pub fn volume(&self) -> &Map {
        self.mapper.volume()
    }

    /// The prediction from the last frame's pose, when predicting.
    pub fn predictor(&self) -> Option<&Predictor> {
        self.predictor.as_ref()
    }

    /// Fuses `frame` at `world_from_camera`: one submission, no wait.
    pub fn submit_frame(&self, gpu: &Gpu, frame: &RgbdFrame, world_from_camera: &Se3) -> Result<()> {
        gpu.check_lost()?;
        self.preprocessor.upload(gpu, frame)?;
        gpu.write_buffer(&self.pose, &[camera_pose(Some(world_from_camera))]);
        let mut fe = FrameEncoder::new(gpu, "core.pose_driven.frame", None);
        self.preprocessor.encode_in(gpu, &mut fe.stage("preprocess"));
        self.mapper.encode(gpu, &mut fe, "integrate");
        if let Some(p) = &self.predictor {
            p.encode(gpu, &mut fe, "predict");
        }
        let (commands, _) = fe.finish(None);
        gpu.submit([commands]);
        Ok(())
    }
}
