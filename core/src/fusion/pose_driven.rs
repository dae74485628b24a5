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
//! One submission per frame. A dense map needs no readback (the host already knows the pose); a
//! sparse map reads its counters back a frame or more later ([`MapStats`]: capacity, and what
//! swapping needs to plan), as KinectFusion's report does.

use crate::engine::{FrameEncoder, ReadbackRing};
use crate::map::{MapBlock, MapStats};
use crate::fusion::mapper::Mapper;
use crate::fusion::predictor::{DepthHint, Predictor, camera_pose, pose_buffer};
use crate::preprocess::{DepthPreprocessor, PreprocessConfig};
use crate::map::Map;
use crate::tsdf::TsdfStore as _;
use crate::tsdf::TsdfConfig;
use crate::{Gpu, Result, RgbdCalibration, RgbdFrame, Se3};

/// Fuses frames at poses the caller gives.
#[derive(Debug)]
pub struct PoseDrivenMapper {
    preprocessor: DepthPreprocessor,
    pose: wgpu::Buffer,
    mapper: Mapper,
    predictor: Option<Predictor>,
    /// A sparse map's counters, one readback per frame.
    readbacks: Option<ReadbackRing<()>>,
    last_stats: Option<MapStats>,
}

/// Frames a pose-driven mapper keeps in flight before it waits for the oldest one's counters.
const MAX_FRAMES_IN_FLIGHT: usize = 3;

impl PoseDrivenMapper {
    /// A mapper for `calibration`'s camera whose volume sits as `tsdf.placement` puts it around
    /// `first_world_from_camera`. With `predict`, each frame also raycasts the model from its
    /// pose (the views of the browser app).
    pub fn new(gpu: &Gpu, calibration: RgbdCalibration, preprocess: PreprocessConfig, tsdf: TsdfConfig, first_world_from_camera: &Se3, predict: bool) -> Result<Self> {
        Self::new_at(gpu, calibration, preprocess, tsdf, tsdf.origin_for_first_camera(first_world_from_camera), predict)
    }

    /// [`Self::new`] with the map's box corner at `origin_in_world` (a loaded map's).
    pub fn new_at(gpu: &Gpu, calibration: RgbdCalibration, preprocess: PreprocessConfig, tsdf: TsdfConfig, origin_in_world: [f32; 3], predict: bool) -> Result<Self> {
        preprocess.validate()?;
        let preprocessor = DepthPreprocessor::new(gpu, calibration, preprocess)?;
        let pose = pose_buffer(gpu, "core.pose_driven.pose", None);
        let mapper = Mapper::new(gpu, tsdf, origin_in_world, &preprocessor, &pose)?;
        let predictor = predict.then(|| Predictor::new(gpu, mapper.volume(), calibration.intrinsics, 1, &pose, Some(DepthHint::from_preprocessor(&preprocessor)), (preprocess.min_depth_m, preprocess.max_depth_m)));
        let readbacks = mapper.sparse().map(|_| ReadbackRing::new(gpu, "core.pose_driven.map_counters", (crate::cpu::shared::MAP_COUNTERS * 4) as u64, MAX_FRAMES_IN_FLIGHT));
        Ok(Self { preprocessor, pose, mapper, predictor, readbacks, last_stats: None })
    }

    /// The TSDF store.
    pub fn volume(&self) -> &Map {
        self.mapper.volume()
    }

    /// The prediction from the last frame's pose, when predicting.
    pub fn predictor(&self) -> Option<&Predictor> {
        self.predictor.as_ref()
    }

    /// The mapper stage (for a sparse map's blocks on the host).
    pub fn mapper(&self) -> &Mapper {
        &self.mapper
    }

    /// The mapper stage, mutably (to load a saved map into it).
    pub fn mapper_mut(&mut self) -> &mut Mapper {
        &mut self.mapper
    }

    /// A sparse map's counters as the last collected frame left them (with swapping's host
    /// side), `None` for a dense map or before the first frame's readback.
    pub fn map_stats(&self) -> Option<MapStats> {
        self.last_stats
    }

    /// Fuses `frame` at `world_from_camera`: one submission. Waits only when a sparse map's
    /// counters of [`MAX_FRAMES_IN_FLIGHT`] frames are pending (then for the oldest).
    pub async fn submit_frame(&mut self, gpu: &Gpu, frame: &RgbdFrame, world_from_camera: &Se3) -> Result<()> {
        gpu.check_lost()?;
        if let Some(ring) = &mut self.readbacks {
            while ring.free_slot().is_none() {
                if let Some(done) = ring.wait_oldest(gpu).await? {
                    Self::take_stats(&mut self.mapper, &mut self.last_stats, &done.bytes);
                }
            }
        }
        self.preprocessor.upload(gpu, frame)?;
        gpu.write_buffer(&self.pose, &[camera_pose(Some(world_from_camera))]);
        self.mapper.poll(gpu)?;
        self.mapper.prepare_frame(gpu, Some(world_from_camera));
        let mut fe = FrameEncoder::new(gpu, "core.pose_driven.frame", None);
        self.preprocessor.encode_in(gpu, &mut fe.stage("preprocess"));
        self.mapper.encode(gpu, &mut fe, "integrate");
        if let Some(p) = &self.predictor {
            p.encode(gpu, &mut fe, "predict");
        }
        let slot = match (&self.readbacks, self.mapper.sparse()) {
            (Some(ring), Some(map)) => {
                let (slot, buffer) = ring.free_slot().expect("a slot was freed above");
                fe.encoder().copy_buffer_to_buffer(map.counters(), 0, buffer, 0, (crate::cpu::shared::MAP_COUNTERS * 4) as u64);
                Some(slot)
            }
            _ => None,
        };
        let (commands, _) = fe.finish(None);
        let submission = gpu.submit([commands]);
        self.mapper.frame_submitted(gpu, &submission);
        if let (Some(ring), Some(slot)) = (&mut self.readbacks, slot) {
            ring.start(gpu, slot, submission, ());
            for done in ring.collect(gpu)? {
                Self::take_stats(&mut self.mapper, &mut self.last_stats, &done.bytes);
            }
        }
        Ok(())
    }

    /// Waits for every frame in flight (a sparse map's counters and swap-outs).
    pub async fn flush(&mut self, gpu: &Gpu) -> Result<()> {
        if let Some(ring) = &mut self.readbacks {
            while let Some(done) = ring.wait_oldest(gpu).await? {
                Self::take_stats(&mut self.mapper, &mut self.last_stats, &done.bytes);
            }
        }
        self.mapper.flush(gpu).await
    }

    /// Every block of the map (see [`Mapper::download_blocks`]), sorted by key; waits for the
    /// frames in flight.
    pub async fn download_blocks(&mut self, gpu: &Gpu) -> Result<Vec<MapBlock>> {
        self.flush(gpu).await?;
        self.mapper.download_blocks(gpu).await
    }

    /// The map's mesh, of every block (a swapping map's on the host too); waits for the frames
    /// in flight.
    pub async fn extract_mesh(&mut self, gpu: &Gpu) -> Result<crate::mesh::Mesh> {
        self.flush(gpu).await?;
        self.mapper.extract_mesh(gpu).await
    }

    fn take_stats(mapper: &mut Mapper, last: &mut Option<MapStats>, bytes: &[u8]) {
        let Some(map) = mapper.sparse() else { return };
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(bytes);
        let mut stats = MapStats::from_words(&words, map.desc().pool_blocks);
        mapper.on_report(&mut stats);
        *last = Some(stats);
    }
}
