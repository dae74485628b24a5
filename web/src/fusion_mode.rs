// SPDX-License-Identifier: MIT
//! The KinectFusion mode: the pipeline, its views and what it reports. The shell (`app.rs`)
//! feeds it decoded frames and asks it for its status section; it never waits for the GPU.
//!
//! A frame is submitted as one command buffer ([`KinectFusion::submit_frame`]); its views
//! (depth, normals, the model from the tracked camera) are coloured on the GPU and copied into
//! their canvases in a second one. Reports (pose, tracking state, GPU stage times) come back
//! a frame or two later through [`FusionMode::poll`]; the trajectory, the running ATE and the
//! statistics are updated then, in O(1) per frame.
//!
//! With feature odometry on (the default; `core::odometry::assist`), each frame's features are
//! extracted first (uploading and preprocessing it for both), give ICP its initial guess or,
//! after a loss, a relocalisation against stored keyframes, and the frame's report is awaited
//! before the next one: the guess needs the last verdict, so frames are not pipelined then.
//!
//! With plane segmentation on (the default; `core::planes::gpu`), each frame whose views are
//! drawn is also segmented on the GPU after its submission, its labels coloured over the frame
//! in the plane view, and the plane table (a few kilobytes, not the labels) read back for the
//! status a frame or so later, without waiting; about once a second the labels come back too,
//! for the world model of planes (`planes_world.rs`) that the scene export draws on.
//! With planes of the fused map ([`PlanesFrom::FusedMap`]) the depth segmented is instead the
//! map's, rendered by a virtual sensor at each frame's tracked pose once its report is back
//! (`core::sim::sensor::VirtualSensor::encode_into`: straight into a preprocessor of its own,
//! no readback), textured by that frame's colour: `webfusion planes --from-model`, live.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

use glam::DVec3;
use web_time::Instant;
use webfusion_core::map::window::ViewCone;
use webfusion_core::map::{MapKind, MapStats};
use webfusion_core::eval::{Alignment, RunningAte};
use webfusion_core::fusion::{FrameReport, FusionConfig, KinectFusion, RaycastTarget, TrackingState};
use webfusion_core::io::{TUM_TRAJECTORY_HEADER, push_tum_line};
use webfusion_core::odometry::assist::{AssistStats, FeatureAssist, PAIR_STAGES, PairView};
use webfusion_core::source::DepthNoise;
use webfusion_core::odometry::tracker::OdometryConfig;
use webfusion_core::source::TimedPose;
use webfusion_core::planes::PlaneConfig;
use webfusion_core::planes::gpu::GpuPlaneSegmenter;
use webfusion_core::planes::overlay::{OverlayTarget, PlaneOverlay};
use webfusion_core::preprocess::DepthPreprocessor;
use webfusion_core::sim::sensor::{SensorOptions, VirtualSensor};
use webfusion_core::view::{DEFAULT_DEPTH_VIEW_MAX_M, DepthView, LabelView, NormalView};
use webfusion_core::{ColorImage, Gpu, PinholeIntrinsics, RgbdCalibration, RgbdFrame, Se3};

use crate::canvas::GpuCanvas;
use crate::planes_world::{Drawn, PlaneWorldModel, WorldStatus};
use crate::sim::{OpenedMap, RealFrame, SensorPanel, SensorStatus};
use crate::status::{HostPerFrame, STATS_WINDOW, StageMedians, StageWindows, VolumeStatus, Window};
use crate::ui;
use crate::view::{self, FrameImage, Orbit};

/// The free view's camera.
pub(crate) const FREE_VIEW: PinholeIntrinsics = PinholeIntrinsics { fx_px: 420.0, fy_px: 420.0, cx_px: 319.5, cy_px: 239.5, width_px: 640, height_px: 480 };
/// Depth range the free view searches, metres.
const FREE_VIEW_RANGE_M: (f32, f32) = (0.05, 20.0);
/// While frames stream, the free view follows the model at most this often, milliseconds (it
/// costs a full raycast; the per-frame views show every frame). A move of its camera redraws
/// it at once; the stream stopping (nothing in flight, no report for this long) soon after.
pub(crate) const FREE_VIEW_MODEL_REFRESH_MS: f64 = 500.0;
/// While frames stream, the free view's redraws take at most this share of the GPU's time: a
/// redraw costs about one raycast of the model (the frame's own raycast, whose median GPU time
/// the stage statistics keep), so it follows the model no more often than every
/// raycast time / share. On a fast GPU the refresh period above is the bound; on a CPU
/// adapter (a raycast of 220 ms on SwiftShader) this one, or each frame would pay twice for
/// its raycast.
const FREE_VIEW_GPU_SHARE: f64 = 0.1;

/// What the shell knows about a frame until its report comes back.
#[derive(Clone, Debug)]
struct InFlight {
    index: u64,
    timestamp_ns: i64,
    ground_truth: Option<Se3>,
    arrived: Instant,
    decode_ms: f64,
    views_ms: f64,
    /// The frame's depth and calibration, for the virtual sensor's comparison at its pose.
    depth_units: Rc<Vec<u16>>,
    calibration: RgbdCalibration,
    /// The frame's colour, kept when the fused map's planes are segmented at its pose (they
    /// wait for its report).
    colour: Option<Rc<ColorImage>>,
}

/// What plane segmentation segments.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub(crate) enum PlanesFrom {
    /// Each frame's own depth, as it is fused.
    Frames,
    /// The fused map's depth at each frame's tracked pose, once its report is back: the noise
    /// averaged over every view, holes filled from other views.
    FusedMap,
}

impl PlanesFrom {
    /// Where a segmentation's planes were seen, before its frame index in the captions.
    pub(crate) fn seen_in(self) -> &'static str {
        match self {
            Self::Frames => "in frame",
            Self::FusedMap => "in the fused map at frame",
        }
    }
}

/// The fused map's depth at a tracked pose in place of a frame's: a virtual sensor (exact)
/// whose render goes straight into a preprocessor of its own, which the segmenter reads.
struct ModelDepth {
    sensor: VirtualSensor,
    pre: DepthPreprocessor,
}

/// A tracked frame whose fused-map planes are segmented at the next chance (the newest wins).
struct ModelDue {
    index: u64,
    /// The frame's tracked pose in the pipeline's world (the fused map's frame).
    map_from_camera: Se3,
    colour: Rc<ColorImage>,
    calibration: RgbdCalibration,
}

/// The per-frame views, coloured on the GPU from the pipeline's own buffers.
struct FrameViews {
    depth: DepthView,
    normals: NormalView,
    model: NormalView,
    depth_canvas: GpuCanvas,
    normals_canvas: GpuCanvas,
    model_canvas: GpuCanvas,
}

/// The free view: the model raycast from the orbiting viewer.
struct FreeView {
    target: RaycastTarget,
    shading: NormalView,
    canvas: GpuCanvas,
    /// The world model's textured planes, drawn over the raycast (`plane_overlay`).
    overlay: PlaneOverlay,
    /// The world model's version the overlay holds, and what it draws of it.
    overlay_of: Option<(u64, Drawn)>,
}

impl FreeView {
    fn new(gpu: &Gpu, store: &webfusion_core::map::Map) -> Result<Self, String> {
        let target = RaycastTarget::new(gpu, store, FREE_VIEW, "web.free_view");
        let shading = NormalView::new(gpu, "web.view.free", &target.normal_in_world, [FREE_VIEW.width_px, FREE_VIEW.height_px]);
        let overlay = PlaneOverlay::new(gpu, "web.free_view.planes");
        Ok(Self { target, shading, canvas: GpuCanvas::new(gpu, "view-free", [FREE_VIEW.width_px, FREE_VIEW.height_px])?, overlay, overlay_of: None })
    }
}

/// Where the virtual sensor is asked to render.
#[derive(Clone, Copy, Debug)]
pub(crate) enum SensorPose {
    /// A pose typed into the panel (the map's frame).
    At(Se3),
    /// The free view's camera.
    FreeView,
    /// The last real frame with a pose in the map, beside its real depth.
    LastFrame,
    /// The i-th pose of the run's trajectory (beside its depth if it is the last frame's).
    Trajectory(usize),
    /// The last render's pose again (its settings changed).
    Again,
}

/// Plane segmentation of each frame (or of the fused map at its pose), its view and the world
/// model of planes.
struct PlaneViews {
    /// Reads the fusion's preprocessor, or with planes of the fused map `model`'s.
    segmenter: GpuPlaneSegmenter,
    /// With planes of the fused map: where its depth is rendered and preprocessed.
    model: Option<ModelDepth>,
    view: LabelView,
    canvas: GpuCanvas,
    world: PlaneWorldModel,
}

impl PlaneViews {
    /// What the segmenter reads: the frames, or the fused map at their poses.
    fn source(&self) -> PlanesFrom {
        if self.model.is_some() { PlanesFrom::FusedMap } else { PlanesFrom::Frames }
    }
}

/// The pipeline and everything built on its device.
struct Pipeline {
    fusion: KinectFusion,
    /// Feature odometry beside ICP (off by the setting, or for frames too small for it).
    assist: Option<FeatureAssist>,
    /// Plane segmentation (off by the setting).
    planes: Option<PlaneViews>,
    views: FrameViews,
    free: FreeView,
}

impl Pipeline {
    fn new(gpu: &Gpu, calibration: RgbdCalibration, config: &FusionConfig, features: bool, planes: Option<PlanesFrom>) -> Result<Self, String> {
        let fusion = KinectFusion::new(gpu, calibration, config.clone()).map_err(|e| format!("cannot build the pipeline: {e}"))?;
        let assist = if features {
            match FeatureAssist::new(gpu, fusion.preprocessor(), OdometryConfig::default()) {
                Ok(mut assist) => {
                    assist.set_jump_limits(f64::from(config.icp.max_jump_m), f64::from(config.icp.max_jump_rad));
                    // The odometry view draws every frame's keypoints and matches.
                    assist.keep_pair_view(true);
                    Some(assist)
                }
                // Frames too small for the keypoint grid: ICP alone.
                Err(webfusion_core::Error::InvalidConfig(_)) => None,
                Err(e) => return Err(format!("cannot build feature odometry: {e}")),
            }
        } else {
            None
        };
        let k = calibration.intrinsics;
        let size = [k.width_px, k.height_px];
        let pre = fusion.preprocessor();
        let views = FrameViews {
            depth: DepthView::new(gpu, &pre.depth_raw, size, 1.0 / calibration.depth_units_per_metre, DEFAULT_DEPTH_VIEW_MAX_M),
            normals: NormalView::new(gpu, "web.view.normals", &pre.levels[0].normal_in_camera, size),
            model: NormalView::new(gpu, "web.view.model", &fusion.prediction().normal_in_world, size),
            depth_canvas: GpuCanvas::new(gpu, "view-depth", size)?,
            normals_canvas: GpuCanvas::new(gpu, "view-normals", size)?,
            model_canvas: GpuCanvas::new(gpu, "view-model", size)?,
        };
        let free = FreeView::new(gpu, fusion.volume())?;
        let planes = match planes {
            Some(from) => {
                let model = match from {
                    PlanesFrom::Frames => None,
                    PlanesFrom::FusedMap => {
                        let options = SensorOptions { units_per_metre: calibration.depth_units_per_metre, ..SensorOptions::default() };
                        let sensor = VirtualSensor::new(gpu, fusion.volume(), k, options).map_err(|e| format!("cannot build the fused map's sensor: {e}"))?;
                        let pre = DepthPreprocessor::new(gpu, calibration, *pre.config()).map_err(|e| format!("cannot build the fused map's preprocessing: {e}"))?;
                        Some(ModelDepth { sensor, pre })
                    }
                };
                let segmented = model.as_ref().map_or(pre, |m| &m.pre);
                let segmenter = GpuPlaneSegmenter::new(gpu, segmented, &PlaneConfig::default()).map_err(|e| format!("cannot build plane segmentation: {e}"))?;
                let view = LabelView::new(gpu, "web.view.planes", &segmenter.labels, &segmented.color, size);
                let world = PlaneWorldModel::new(PlaneConfig::default());
                Some(PlaneViews { segmenter, model, view, canvas: GpuCanvas::new(gpu, "view-planes", size)?, world })
            }
            None => {
                ui::set_text("planes-caption", "off");
                None
            }
        };
        Ok(Self { fusion, assist, planes, views, free })
    }
}

/// KinectFusion on the frames the shell hands over.
pub(crate) struct FusionMode {
    config: FusionConfig,
    /// Feature odometry beside ICP.
    features: bool,
    /// Plane segmentation (off: `None`) and what it segments.
    planes: Option<PlanesFrom>,
    pipeline: Option<Pipeline>,
    in_flight: VecDeque<InFlight>,
    /// Index of the last frame submitted.
    last_submitted: Option<u64>,
    /// Index of the last frame whose report came back.
    last_reported: Option<u64>,
    /// Poses of this run, in the run's world frame (after `run_origin`).
    trajectory: Vec<TimedPose>,
    /// The trajectory as TUM text, grown a line per report (shared with the page's
    /// `window.webfusion.trajectory_tum()`).
    trajectory_tum: Rc<RefCell<String>>,
    /// Ground-truth positions paired with `trajectory` (for the running ATE and the path).
    ground_truth: Vec<DVec3>,
    ate: RunningAte,
    alignment: Option<(Alignment, f64)>,
    /// Where a pipeline rebuilt mid-run (after a lost device) starts: its world frame is the
    /// camera of its first frame, placed at the last pose before the loss.
    run_origin: Se3,
    tracking: &'static str,
    lost_frames: u64,
    recovered_frames: u64,
    /// A sparse map's counters as of the last report.
    map: Option<MapStats>,
    stages: StageWindows,
    frame_instants: VecDeque<Instant>,
    host: HostPerFrame,
    latency_ms: Option<f64>,
    orbit: Option<Orbit>,
    /// The free view's camera or shading changed: redraw at once.
    free_dirty: bool,
    /// The model changed since the free view was drawn: redraw when due.
    free_model_dirty: bool,
    free_drawn_at: Option<Instant>,
    free_colour: bool,
    /// Draw the world model's textured planes in the free view.
    free_planes: bool,
    /// The odometry view: the stage shown (an index into `PAIR_STAGES`), the last pair and the
    /// colour images of its two frames.
    odometry_stage: usize,
    pair: Option<PairView>,
    reference_image: Option<FrameImage>,
    current_image: Option<FrameImage>,
    /// The last segmented frame's planes.
    plane_status: Option<PlaneStatus>,
    /// Segmentation wall times per frame (submission to the table's arrival, which includes
    /// the frame's own GPU work queued before it), milliseconds.
    plane_ms: Window,
    /// A report was applied since the last `poll`.
    reported: bool,
    /// Frames segmented and when, until their plane table comes back.
    planes_sent: VecDeque<(u64, Instant)>,
    /// With planes of the fused map: the last tracked frame, not segmented yet.
    model_due: Option<ModelDue>,
    /// The virtual sensor (seed 000), in the fused map or the opened one.
    sensor: SensorPanel,
    /// A real frame arrived while the sensor follows frames: render at it at the next poll.
    sensor_due: bool,
    /// A saved map opened in the page and its free view: while one is open frames are not
    /// fused, only compared with the map at their ground-truth pose.
    opened: Option<(OpenedMap, FreeView)>,
}

/// How a frame reached the page: its ground truth (if the source has it), when it arrived and
/// how long decoding took.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Received {
    pub(crate) ground_truth: Option<Se3>,
    pub(crate) arrived: Instant,
    pub(crate) decode_ms: f64,
}

/// This mode's part of the page's status.
#[derive(Clone, Debug, serde::Serialize)]
pub(crate) struct FusionStatus {
    pub(crate) frames_done: usize,
    pub(crate) last_index: Option<u64>,
    pub(crate) frames_in_flight: usize,
    pub(crate) fps: f64,
    pub(crate) stages_ms: StageMedians,
    pub(crate) gpu_timestamps: bool,
    pub(crate) host_per_frame: HostPerFrame,
    pub(crate) tracking: &'static str,
    pub(crate) lost_frames: u64,
    pub(crate) recovered_frames: u64,
    pub(crate) ate_rmse_m: Option<f64>,
    pub(crate) ate_pairs: usize,
    pub(crate) volume: VolumeStatus,
    pub(crate) latency_ms: Option<f64>,
    /// Feature odometry's counts (absent when it is off).
    pub(crate) features: Option<FeatureStatus>,
    /// The last frame's planes (absent when segmentation is off or no frame was segmented).
    pub(crate) planes: Option<PlaneStatus>,
    /// The world model of planes (absent when segmentation is off).
    pub(crate) world: Option<WorldStatus>,
}

/// Plane segmentation's part of the status: the last segmented frame's planes.
#[derive(Clone, Debug, serde::Serialize)]
pub(crate) struct PlaneStatus {
    pub(crate) frame: u64,
    /// The frame's own depth, or the fused map's at its pose.
    pub(crate) source: PlanesFrom,
    pub(crate) count: usize,
    pub(crate) curved_rejected: u32,
    pub(crate) overflow: u32,
    /// Largest first: unit normal (camera frame, facing it), offset d of n·p + d = 0, pixels.
    pub(crate) planes: Vec<PlaneEntry>,
    /// Median wall time per frame, from the segmentation's submission to its table's arrival
    /// (the frame's fusion work, queued before it, included).
    pub(crate) median_ms: f64,
}

/// One plane of [`PlaneStatus`].
#[derive(Clone, Debug, serde::Serialize)]
pub(crate) struct PlaneEntry {
    pub(crate) normal: [f32; 3],
    pub(crate) offset_m: f32,
    pub(crate) pixels: u32,
    pub(crate) area_m2: f32,
}

/// Feature odometry's part of the status.
#[derive(Clone, Debug, serde::Serialize)]
pub(crate) struct FeatureStatus {
    pub(crate) guesses: usize,
    pub(crate) relocalisations: usize,
    pub(crate) relocalisations_confirmed: usize,
    pub(crate) recoveries: usize,
    /// Frames after a gap that no feature pose placed (lost without tracking).
    pub(crate) withheld: usize,
    pub(crate) keyframes: usize,
    /// Median milliseconds of a frame through features and dense tracking (one submission while
    /// tracking).
    pub(crate) median_ms: f64,
    /// The last frame pair (the odometry view).
    pub(crate) pair: Option<PairStatus>,
}

/// The odometry view's pair.
#[derive(Clone, Debug, serde::Serialize)]
pub(crate) struct PairStatus {
    pub(crate) frame: u64,
    pub(crate) reference_frame: u64,
    pub(crate) keypoints: usize,
    pub(crate) reference_keypoints: usize,
    pub(crate) matches: usize,
    pub(crate) inliers: usize,
    /// The stage the view shows.
    pub(crate) stage: &'static str,
    /// Milliseconds per stage (`PAIR_STAGES`; null without GPU timestamps).
    pub(crate) stages_ms: [Option<f64>; 5],
}

impl FusionMode {
    pub(crate) fn new(config: FusionConfig, features: bool, planes: Option<PlanesFrom>) -> Self {
        Self {
            config,
            features,
            planes,
            pipeline: None,
            in_flight: VecDeque::new(),
            last_submitted: None,
            last_reported: None,
            trajectory: Vec::new(),
            trajectory_tum: Rc::new(RefCell::new(TUM_TRAJECTORY_HEADER.to_owned())),
            ground_truth: Vec::new(),
            ate: RunningAte::default(),
            alignment: None,
            run_origin: Se3::IDENTITY,
            tracking: "idle",
            lost_frames: 0,
            map: None,
            recovered_frames: 0,
            stages: Default::default(),
            frame_instants: VecDeque::new(),
            host: HostPerFrame::default(),
            latency_ms: None,
            orbit: None,
            free_dirty: false,
            free_model_dirty: false,
            free_drawn_at: None,
            free_colour: false,
            free_planes: true,
            odometry_stage: PAIR_STAGES.len() - 1,
            pair: None,
            reference_image: None,
            current_image: None,
            plane_status: None,
            plane_ms: Window::default(),
            reported: false,
            planes_sent: VecDeque::new(),
            model_due: None,
            sensor: SensorPanel::default(),
            sensor_due: false,
            opened: None,
        }
    }

    /// Replaces the settings: the pipeline is rebuilt at the next frame.
    pub(crate) fn set_config(&mut self, config: FusionConfig, features: bool, planes: Option<PlanesFrom>) {
        self.config = config;
        self.features = features;
        self.planes = planes;
        self.drop_fused_map();
        self.planes_sent.clear();
        self.model_due = None;
    }

    /// Drops the pipeline (and the fused map the sensor may be bound to).
    fn drop_fused_map(&mut self) {
        self.pipeline = None;
        if self.opened.is_none() {
            self.sensor.unbind();
        }
    }

    /// Drops everything built on the GPU (the device was lost, or the source changed); the
    /// next frame rebuilds it. With `keep_trajectory` the run goes on: the new pipeline's
    /// poses continue from the last one.
    pub(crate) fn drop_pipeline(&mut self, keep_trajectory: bool) {
        self.drop_fused_map();
        self.in_flight.clear();
        self.planes_sent.clear();
        self.model_due = None;
        if keep_trajectory {
            self.run_origin = self.trajectory.last().map_or(Se3::IDENTITY, |p| p.world_from_camera);
        } else {
            self.reset_run_state();
        }
    }

    /// Forgets the model, the trajectory and the statistics: the next frame starts a new run.
    pub(crate) fn reset(&mut self, gpu: &Gpu) {
        if let Some(p) = &mut self.pipeline {
            p.fusion.reset(gpu);
            if let Some(assist) = &mut p.assist {
                assist.reset();
            }
            if let Some(planes) = &mut p.planes {
                planes.world.reset();
            }
        }
        self.in_flight.clear();
        self.planes_sent.clear();
        self.model_due = None;
        self.reset_run_state();
        if let Some((o, _)) = &self.opened {
            self.orbit = Some(first_look(o));
        }
    }

    fn reset_run_state(&mut self) {
        self.last_submitted = None;
        self.last_reported = None;
        self.trajectory.clear();
        TUM_TRAJECTORY_HEADER.clone_into(&mut self.trajectory_tum.borrow_mut());
        self.ground_truth.clear();
        self.ate = RunningAte::default();
        self.alignment = None;
        self.run_origin = Se3::IDENTITY;
        self.tracking = "idle";
        self.lost_frames = 0;
        self.recovered_frames = 0;
        self.stages.clear();
        self.frame_instants.clear();
        self.latency_ms = None;
        self.orbit = None;
        self.free_dirty = true;
        self.free_model_dirty = false;
        self.pair = None;
        self.reference_image = None;
        self.current_image = None;
    }

    /// Index of the last frame submitted (the shell requests the next one from it).
    pub(crate) fn last_submitted(&self) -> Option<u64> {
        self.last_submitted
    }

    /// Whether anything submitted is still to come back (frame reports, plane tables).
    pub(crate) fn awaiting_gpu(&self) -> bool {
        !self.in_flight.is_empty() || !self.planes_sent.is_empty() || self.model_due.is_some() || self.sensor.awaiting_gpu() || self.sensor_due
    }

    /// The trajectory so far, TUM text (kept current as reports arrive).
    pub(crate) fn trajectory_tum(&self) -> Rc<RefCell<String>> {
        Rc::clone(&self.trajectory_tum)
    }

    /// After the frames in flight were lost with the device: the next frame requested is the
    /// one after `last` (the last one fused).
    pub(crate) fn rewind_to(&mut self, last: Option<u64>) {
        self.last_submitted = last;
    }

    /// Index of the last frame whose report came back.
    pub(crate) fn last_reported(&self) -> Option<u64> {
        self.last_reported
    }

    /// The scene of the world model as glTF binary: its textured planes and the fused mesh
    /// (every block, a swapping map's host ones too) less what they cover.
    pub(crate) async fn scene_glb(&mut self, gpu: &Gpu) -> Result<Vec<u8>, String> {
        let voxel_m = self.config.tsdf.voxel_size_m;
        let Some(p) = self.pipeline.as_mut() else { return Err("nothing fused yet".to_owned()) };
        let Some(planes) = &p.planes else { return Err("plane segmentation is off (settings)".to_owned()) };
        if planes.world.status().planes == 0 {
            return Err("no world planes yet (the world model takes a frame about once a second)".to_owned());
        }
        let mesh = p.fusion.mapper_mut().extract_mesh(gpu).await.map_err(|e| e.to_string())?;
        planes.world.scene_glb(&mesh, voxel_m).map_err(|e| e.to_string())
    }

    /// The pipeline (for the mesh export), if built; mutably, as a swapping map's mesh gathers
    /// its blocks from the host.
    pub(crate) fn fusion_mut(&mut self) -> Option<&mut KinectFusion> {
        self.pipeline.as_mut().map(|p| &mut p.fusion)
    }

    /// Submits one decoded frame and, with `draw_views`, draws its views, without waiting for
    /// the GPU (unless two frames are in flight already: then for the oldest's report).
    /// A source whose depth is exact (`depth_noise`, from the bridge's hello: a simulated log
    /// without noise) is tracked and fused as native `reconstruct` does it
    /// ([`FusionConfig::for_depth_noise`]).
    pub(crate) async fn submit(&mut self, gpu: &Gpu, calibration: RgbdCalibration, depth_noise: DepthNoise, frame: &RgbdFrame, received: Received, draw_views: bool) -> Result<(), String> {
        let Received { ground_truth, arrived, decode_ms } = received;
        if let Some((opened, _)) = &self.opened {
            // A saved map is open: the frame is compared with it, not fused.
            self.last_submitted = Some(frame.index);
            if opened.header.frame == webfusion_core::map::file::MapFrame::GivenPoses
                && let Some(gt) = ground_truth
            {
                self.sensor_due |= self.sensor.observe(real_frame(frame.index, Rc::new(frame.depth.units.clone()), calibration, gt));
            }
            return Ok(());
        }
        if self.pipeline.is_none() {
            let config = self.config.clone().for_depth_noise(depth_noise, false);
            self.pipeline = Some(Pipeline::new(gpu, calibration, &config, self.features, self.planes)?);
        }
        let Some(p) = self.pipeline.as_mut() else { return Ok(()) };
        let failed = |e: webfusion_core::Error| format!("frame {}: {e}", frame.index);
        // With features, the frame (features, their guess, tracking: one submission) is
        // awaited: the next frame's features need its outcome.
        let mut assisted = None;
        if let Some(assist) = &mut p.assist {
            let frame_done = assist.process_frame(gpu, &mut p.fusion, frame).await.map_err(failed)?;
            self.pair = assist.last_pair().cloned();
            self.current_image = Some((frame.index, frame.color.width_px, frame.color.height_px, view::rgba_from_rgb(&frame.color.rgb8)));
            if draw_views {
                draw_odometry_view(self.pair.as_ref(), self.reference_image.as_ref(), self.current_image.as_ref(), self.odometry_stage);
            }
            assisted = Some(frame_done.report);
        } else {
            p.fusion.submit_frame(gpu, frame).await.map_err(failed)?;
        }
        let t_views = Instant::now();
        if draw_views {
            draw_frame_views(gpu, p, frame)?;
        }
        let views_ms = t_views.elapsed().as_secs_f64() * 1e3;
        // Kept for the virtual sensor's comparison.
        let depth_units = Rc::new(frame.depth.units.clone());
        // The plane kernels compile once the first frame is fused (they would hold it up).
        let segment = draw_views && gpu.kernels.all_compiled();
        // The fused map's planes at this frame's pose wait for its report.
        let source = p.planes.as_ref().map(PlaneViews::source);
        let colour = (segment && source == Some(PlanesFrom::FusedMap)).then(|| Rc::new(frame.color.clone()));
        if segment
            && source == Some(PlanesFrom::Frames)
            && let Some(planes) = &mut p.planes
        {
            // About once a second the labels come back too, for the world model.
            let with_labels = planes.world.wants_frame();
            let encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("web.planes") });
            if segment_planes(gpu, planes, encoder, frame.index, with_labels).map_err(|e| format!("frame {}: planes: {e}", frame.index))? {
                self.planes_sent.push_back((frame.index, Instant::now()));
                if with_labels {
                    planes.world.asked(frame.index, &frame.color, calibration);
                }
            }
        }
        self.in_flight.push_back(InFlight {
            index: frame.index,
            timestamp_ns: frame.depth_timestamp_ns,
            ground_truth,
            arrived,
            decode_ms,
            views_ms,
            depth_units,
            calibration,
            colour,
        });
        self.last_submitted = Some(frame.index);
        if let Some(report) = assisted {
            if !report.state.is_lost() {
                // The next pair's left frame.
                self.reference_image = self.current_image.clone();
            }
            self.apply(report);
        }
        self.collect_planes(gpu)?;
        self.segment_model_due(gpu)
    }

    /// With planes of the fused map: segments the map's depth at the last tracked frame's pose
    /// (if one is due), textured by that frame's colour; its table comes back like a frame's.
    fn segment_model_due(&mut self, gpu: &Gpu) -> Result<(), String> {
        let Some(Pipeline { fusion, planes: Some(planes), .. }) = self.pipeline.as_mut() else {
            self.model_due = None;
            return Ok(());
        };
        let Some(model) = planes.model.as_mut() else {
            self.model_due = None;
            return Ok(());
        };
        // Both table slots in flight: it stays due until one comes back (the last frame of a
        // log must not go unread).
        if !planes.segmenter.table_slot_free() {
            return Ok(());
        }
        let Some(due) = self.model_due.take() else { return Ok(()) };
        let with_labels = planes.world.wants_frame();
        let failed = |e: webfusion_core::Error| format!("frame {}: the fused map's planes: {e}", due.index);
        model.pre.upload_color(gpu, &due.colour).map_err(failed)?;
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("web.planes.model") });
        // The noise stream's frame index is unused: the sensor is exact.
        model.sensor.encode_into(gpu, &mut encoder, fusion.volume(), &due.map_from_camera, due.index as u32, &model.pre).map_err(failed)?;
        model.pre.encode(gpu, &mut encoder);
        if segment_planes(gpu, planes, encoder, due.index, with_labels).map_err(|e| format!("frame {}: planes: {e}", due.index))? {
            self.planes_sent.push_back((due.index, Instant::now()));
            if with_labels {
                planes.world.asked(due.index, &due.colour, due.calibration);
                // Its report came before it was asked for.
                planes.world.pose_reported(due.index, Some(due.map_from_camera));
            }
        }
        Ok(())
    }

    /// Shows the odometry view's next stage; past the last one it starts again from the first
    /// and returns true: the caller fetches the next frame.
    pub(crate) fn next_odometry_stage(&mut self) -> bool {
        let wrapped = self.odometry_stage + 1 >= PAIR_STAGES.len();
        self.odometry_stage = if wrapped { 0 } else { self.odometry_stage + 1 };
        draw_odometry_view(self.pair.as_ref(), self.reference_image.as_ref(), self.current_image.as_ref(), self.odometry_stage);
        wrapped
    }

    /// Takes the reports (and plane tables) that came back (never waits); true if a report
    /// did since the last call (including those `submit` took itself, with feature odometry on).
    pub(crate) fn poll(&mut self, gpu: &Gpu) -> Result<bool, String> {
        if let Some(p) = self.pipeline.as_mut() {
            let reports = p.fusion.poll_reports(gpu).map_err(|e| e.to_string())?;
            for report in reports {
                self.apply(report);
            }
            self.collect_planes(gpu)?;
            self.segment_model_due(gpu)?;
        }
        if std::mem::take(&mut self.sensor_due) {
            self.render_sensor(gpu, SensorPose::LastFrame)?;
        }
        self.sensor.poll(gpu)?;
        Ok(std::mem::take(&mut self.reported))
    }

    /// The frame of the map on show (the opened one, or the pipeline's) from the run's world:
    /// an opened map's frame is the world; the pipeline's world is the run's after `run_origin`.
    fn map_from_world(&self) -> Se3 {
        if self.opened.is_some() { Se3::IDENTITY } else { self.run_origin.inverse() }
    }

    /// Renders the virtual sensor in the opened map, or else in the fused one.
    pub(crate) fn render_sensor(&mut self, gpu: &Gpu, at: SensorPose) -> Result<(), String> {
        let map_from_world = self.map_from_world();
        let real = self.sensor.real().cloned();
        let (pose, real) = match at {
            SensorPose::At(pose) => (pose, None),
            SensorPose::FreeView => match self.orbit {
                Some(orbit) => (map_from_world * orbit.world_from_viewer(), None),
                None => return Err("virtual sensor: the free view has no camera yet".to_owned()),
            },
            SensorPose::LastFrame => match real {
                Some(r) => (r.map_from_camera, Some(r)),
                None => return Err("virtual sensor: no real frame with a pose in this map yet".to_owned()),
            },
            SensorPose::Trajectory(i) => match self.trajectory.get(i) {
                Some(p) => {
                    let pose = map_from_world * p.world_from_camera;
                    (pose, real.filter(|r| (r.map_from_camera.translation_m - pose.translation_m).length() < 1e-9 && r.map_from_camera.rotation.angle_between(pose.rotation) < 1e-9))
                }
                None => return Err(format!("virtual sensor: the trajectory has {} poses; there is no pose {i}", self.trajectory.len())),
            },
            SensorPose::Again => match self.sensor.last_pose() {
                Some(pose) => (pose, real.filter(|r| r.map_from_camera == pose)),
                None => return Ok(()),
            },
        };
        // Without a real frame at the pose, the sensor is the camera the map was made with: an
        // opened map's (as `webfusion simulate` renders it), the stream's for the live map. An
        // opened map larger than the page's pool first gets a window holding this view.
        if let Some((o, _)) = &mut self.opened {
            let cone = crate::sim::sensor_cone(real.as_ref(), o.header.fused_camera());
            o.map.prepare(gpu, &pose, &cone).map_err(|e| format!("virtual sensor: {e}"))?;
        }
        let (store, camera) = match (&self.opened, &self.pipeline) {
            (Some((o, _)), _) => (o.map.map(), o.header.fused_camera()),
            (None, Some(p)) => (p.fusion.volume(), Some(p.fusion.preprocessor().calibration().intrinsics)),
            (None, None) => return Err("virtual sensor: no map yet (fuse a frame, or open a saved map)".to_owned()),
        };
        let ask_bridge = self.opened.as_ref().is_some_and(|(o, _)| o.from_bridge);
        self.sensor.render(gpu, store, pose, real, camera, ask_bridge)?;
        self.free_dirty = true;
        Ok(())
    }

    pub(crate) fn set_sensor_follow(&mut self, on: bool) {
        self.sensor.set_follow(on);
    }

    pub(crate) fn set_sensor_noise(&mut self, seed: Option<u32>) {
        self.sensor.set_noise(seed);
    }

    pub(crate) fn download_sensor(&self) -> Result<(), String> {
        self.sensor.download()
    }

    /// The render request to send the bridge now (the unknown mask of the sensor's newest
    /// render in a map opened from the bridge), if one is due.
    pub(crate) fn bridge_request(&mut self) -> Option<webfusion_core::protocol::RenderRequest> {
        self.sensor.bridge_request()
    }

    /// The link to the bridge closed with a request in flight.
    pub(crate) fn bridge_lost(&mut self) {
        self.sensor.bridge_lost();
    }

    /// The bridge answered a render request.
    pub(crate) fn on_bridge_reply(&mut self, request_id: u32, outcome: webfusion_core::protocol::RenderOutcome) -> Result<(), String> {
        self.sensor.on_bridge_reply(request_id, outcome)
    }

    /// Opens a saved map: the pipeline and the run are dropped (frames are compared with the
    /// map, not fused, until it is closed) and the free view looks at the map.
    pub(crate) fn open_map(&mut self, gpu: &Gpu, map: OpenedMap) -> Result<(), String> {
        // The old free view's canvas is let go before the new one configures it.
        self.opened = None;
        self.drop_pipeline(false);
        let free = FreeView::new(gpu, map.map.map())?;
        self.orbit = Some(first_look(&map));
        self.opened = Some((map, free));
        self.free_dirty = true;
        Ok(())
    }

    /// Closes the opened map: the next frame starts a new run.
    pub(crate) fn close_map(&mut self) {
        if self.opened.take().is_some() {
            self.sensor.unbind();
            self.reset_run_state();
        }
    }

    /// Takes the plane tables that came back (never waits) into the status and the caption.
    fn collect_planes(&mut self, gpu: &Gpu) -> Result<(), String> {
        let Some(planes) = self.pipeline.as_mut().and_then(|p| p.planes.as_mut()) else { return Ok(()) };
        let version = planes.world.version();
        let source = planes.source();
        for (frame, seg, stats) in planes.segmenter.collect_tables(gpu).map_err(|e| format!("planes: {e}"))? {
            while self.planes_sent.front().is_some_and(|(f, _)| *f != frame) {
                self.planes_sent.pop_front();
            }
            if let Some((_, sent)) = self.planes_sent.pop_front() {
                self.plane_ms.push(sent.elapsed().as_secs_f64() * 1e3);
            }
            let world = planes.world.status();
            ui::set_text("planes-caption", &format!("{} {} {frame} · world: {} planes from {} frames", seg.planes.len(), source.seen_in(), world.planes, world.frames));
            self.plane_status = Some(PlaneStatus {
                frame,
                source,
                count: seg.planes.len(),
                curved_rejected: seg.curved_rejected,
                overflow: stats.overflow,
                planes: seg.planes.iter().map(|p| PlaneEntry { normal: p.normal, offset_m: p.offset_m, pixels: p.pixels, area_m2: p.area_m2 }).collect(),
                median_ms: 0.0,
            });
            if !seg.labels.is_empty() {
                planes.world.labels_arrived(frame, seg);
            }
        }
        // The free view's textured planes follow the world as it grows.
        self.free_model_dirty |= planes.world.version() != version;
        Ok(())
    }

    fn apply(&mut self, report: FrameReport) {
        self.reported = true;
        while self.in_flight.front().is_some_and(|f| f.index != report.index) {
            self.in_flight.pop_front();
        }
        let Some(meta) = self.in_flight.pop_front() else { return };
        let world_from_camera = self.run_origin * report.world_from_camera;
        self.last_reported = Some(report.index);
        if let Some(planes) = self.pipeline.as_mut().and_then(|p| p.planes.as_mut()) {
            // The world of planes is in the pipeline's frame, the fused mesh's.
            planes.world.pose_reported(report.index, (!report.state.is_lost()).then_some(report.world_from_camera));
        }
        let pose = TimedPose { timestamp_ns: meta.timestamp_ns, world_from_camera };
        push_tum_line(&mut self.trajectory_tum.borrow_mut(), &pose);
        self.trajectory.push(pose);
        if let Some(gt) = meta.ground_truth {
            self.ground_truth.push(gt.translation_m);
            self.ate.push(world_from_camera.translation_m, gt.translation_m);
            self.alignment = self.ate.alignment_and_rmse_m().ok();
        }
        self.tracking = report.state.name();
        if report.map.is_some() {
            self.map = report.map;
        }
        if !report.state.is_lost() {
            self.sensor_due |= self.sensor.observe(real_frame(meta.index, Rc::clone(&meta.depth_units), meta.calibration, report.world_from_camera));
            if let Some(colour) = meta.colour {
                self.model_due = Some(ModelDue { index: report.index, map_from_camera: report.world_from_camera, colour, calibration: meta.calibration });
            }
        }
        match report.state {
            TrackingState::Lost(_) => self.lost_frames += 1,
            TrackingState::Recovered => self.recovered_frames += 1,
            _ => {}
        }
        if self.orbit.is_none() {
            // Look at a point 1.5 m in front of the first camera, about its up axis (−y).
            self.orbit = Some(Orbit::looking_at(world_from_camera.transform_point(DVec3::new(0.0, 0.0, 1.5)), 3.0, world_from_camera.rotation * DVec3::NEG_Y));
        }
        let t = report.gpu_ms.unwrap_or_default();
        self.stages.push(&StageMedians {
            decode: meta.decode_ms,
            preprocess: t.preprocess,
            features: t.features.iter().sum(),
            track: t.track,
            integrate: t.integrate,
            raycast: t.raycast,
            views: meta.views_ms,
        });
        self.host = HostPerFrame { submits: report.host.submits as f64, host_waits: report.host.host_waits as f64, readbacks: report.host.readbacks as f64 };
        self.latency_ms = Some(meta.arrived.elapsed().as_secs_f64() * 1e3);
        if self.frame_instants.len() == STATS_WINDOW {
            self.frame_instants.pop_front();
        }
        self.frame_instants.push_back(Instant::now());
        self.free_model_dirty = true;
    }

    /// Milliseconds until the free view is due to follow the model, if it has to.
    pub(crate) fn free_view_due_in_ms(&self) -> Option<f64> {
        if self.free_dirty {
            return Some(0.0);
        }
        if !self.free_model_dirty {
            return None;
        }
        let since_ms = |t: Option<Instant>| t.map_or(f64::INFINITY, |t| t.elapsed().as_secs_f64() * 1e3);
        let raycast_ms = self.stages.raycast.median().unwrap_or(0.0);
        let period_ms = FREE_VIEW_MODEL_REFRESH_MS.max(raycast_ms / FREE_VIEW_GPU_SHARE);
        let mut due_ms = (period_ms - since_ms(self.free_drawn_at)).max(0.0);
        if self.in_flight.is_empty() {
            // Nothing in flight (with feature odometry every frame's report is awaited, so
            // this holds between any two frames): the stream paused or ended once no report
            // came for a refresh period, and the model as it is then is shown.
            due_ms = due_ms.min((FREE_VIEW_MODEL_REFRESH_MS - since_ms(self.frame_instants.back().copied())).max(0.0));
        }
        Some(due_ms)
    }

    /// The free view's camera moved or its shading changed.
    pub(crate) fn orbit_mut(&mut self) -> Option<&mut Orbit> {
        self.free_dirty = true;
        self.orbit.as_mut()
    }

    pub(crate) fn set_free_colour(&mut self, on: bool) {
        self.free_colour = on;
        self.free_dirty = true;
    }

    pub(crate) fn set_free_planes(&mut self, on: bool) {
        self.free_planes = on;
        self.free_dirty = true;
    }

    /// Redraws the free view if its camera moved, or if the model changed and a redraw is due
    /// ([`FREE_VIEW_MODEL_REFRESH_MS`] while frames stream).
    pub(crate) fn draw_free_view(&mut self, gpu: &Gpu) -> Result<(), String> {
        if self.free_view_due_in_ms() != Some(0.0) {
            return Ok(());
        }
        let Some(orbit) = self.orbit else { return Ok(()) };
        let world_from_viewer = orbit.world_from_viewer();
        let map_from_viewer = self.map_from_world() * world_from_viewer;
        // The world of planes is in the pipeline's frame (the map's): its textured planes are
        // drawn over the pipeline's model, not over an opened map.
        let planes_shown = self.free_planes && self.opened.is_none();
        if let Some(p) = self.pipeline.as_mut().filter(|_| planes_shown)
            && let Some(planes) = &p.planes
        {
            let version = planes.world.version();
            if p.free.overlay_of.is_none_or(|(v, _)| v != version) {
                let model = planes.world.overlay_model();
                p.free.overlay.upload(gpu, &model).map_err(|e| format!("the free view's planes: {e}"))?;
                p.free.overlay_of = Some((version, Drawn { planes: p.free.overlay.plane_count(), texels: model.texels.len(), left_out: model.left_out }));
            }
        }
        let occlusion_m = (2.0 * self.config.tsdf.voxel_size_m).max(PlaneConfig::default().label_min_distance_m);
        if let Some((o, _)) = &mut self.opened {
            // A map larger than its pool shows the nearest of the free view's blocks when they
            // do not all fit (the status says how far the image is complete).
            o.free_view_window = Some(o.map.prepare_nearest(gpu, &map_from_viewer, &ViewCone::for_camera(&FREE_VIEW, FREE_VIEW_RANGE_M)).map_err(|e| format!("the free view: {e}"))?);
        }
        let (free, store) = match (&self.opened, &self.pipeline) {
            (Some((o, free)), _) => (free, o.map.map()),
            (None, Some(p)) if !self.trajectory.is_empty() => (&p.free, p.fusion.volume()),
            _ => return Ok(()),
        };
        self.free_dirty = false;
        self.free_model_dirty = false;
        self.free_drawn_at = Some(Instant::now());
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("web.free_view") });
        free.target.render(gpu, &mut encoder, store, &map_from_viewer, FREE_VIEW_RANGE_M, true).map_err(|e| e.to_string())?;
        if !self.free_colour {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("web.free_view.shading"), timestamp_writes: None });
            free.shading.dispatch_in(gpu, &mut pass);
        }
        // The textured planes over the model's colour or shading, where the model's surface
        // lies on them (within two voxels, or the plane's labelling distance).
        let (image, row_stride_px) = if self.free_colour { (&free.target.color_rgba8, FREE_VIEW.width_px) } else { (&free.shading.image.rgba8, free.shading.image.row_stride_px) };
        let drawn = match free.overlay_of {
            Some((_, drawn)) if planes_shown => {
                let target = OverlayTarget { intrinsics: FREE_VIEW, depth_m: &free.target.depth_m, rgba8: image, row_stride_px };
                free.overlay.draw(gpu, &mut encoder, &target, &map_from_viewer, FREE_VIEW_RANGE_M, occlusion_m);
                drawn
            }
            _ => Drawn::default(),
        };
        let texture = if self.free_colour { free.canvas.draw_packed(&mut encoder, image, FREE_VIEW.width_px)? } else { free.canvas.draw(&mut encoder, &free.shading.image)? };
        gpu.submit([encoder.finish()]);
        GpuCanvas::present(gpu, [texture]);
        if let Some(planes) = self.pipeline.as_mut().and_then(|p| p.planes.as_mut()) {
            planes.world.set_drawn(drawn);
        }
        self.draw_overlay(&world_from_viewer)
    }

    /// The trajectories and the current camera over the free view (a 2D canvas on top).
    fn draw_overlay(&self, world_from_viewer: &Se3) -> Result<(), String> {
        let canvas: web_sys::HtmlCanvasElement = ui::element("view-free-overlay")?;
        let ctx = view::context_2d(&canvas, FREE_VIEW.width_px, FREE_VIEW.height_px).map_err(|e| crate::link::js_text(&e))?;
        ctx.clear_rect(0.0, 0.0, f64::from(FREE_VIEW.width_px), f64::from(FREE_VIEW.height_px));
        if let Some((alignment, _)) = &self.alignment {
            // Ground truth, moved into this reconstruction's frame by the ATE alignment.
            let est_from_gt = alignment.gt_from_est.inverse();
            view::draw_path(&ctx, &FREE_VIEW, world_from_viewer, self.ground_truth.iter().map(|p| est_from_gt.transform_point(*p)), "#4caf50");
        }
        view::draw_path(&ctx, &FREE_VIEW, world_from_viewer, self.trajectory.iter().map(|p| p.world_from_camera.translation_m), "#ffb300");
        if let Some(last) = self.trajectory.last() {
            view::draw_camera(&ctx, &FREE_VIEW, world_from_viewer, &last.world_from_camera, "#ff5252");
        }
        if let Some(map_from_sensor) = self.sensor.last_pose() {
            // The virtual Kinect, in the run's frame.
            view::draw_camera(&ctx, &FREE_VIEW, world_from_viewer, &(self.map_from_world().inverse() * map_from_sensor), "#40c4ff");
        }
        Ok(())
    }

    /// The virtual sensor's status section.
    pub(crate) fn sensor_status(&self) -> SensorStatus {
        self.sensor.status(self.opened.as_ref().map(|(o, _)| o))
    }

    /// This mode's status section.
    pub(crate) fn status(&self) -> FusionStatus {
        let fps = match (self.frame_instants.front(), self.frame_instants.back()) {
            (Some(first), Some(last)) if self.frame_instants.len() >= 2 => (self.frame_instants.len() - 1) as f64 / (*last - *first).as_secs_f64().max(1e-9),
            _ => 0.0,
        };
        let t = &self.config.tsdf;
        FusionStatus {
            frames_done: self.trajectory.len(),
            last_index: self.last_reported,
            frames_in_flight: self.in_flight.len(),
            fps,
            stages_ms: self.stages.medians(),
            gpu_timestamps: self.pipeline.as_ref().is_some_and(|p| p.fusion.timer_available()),
            host_per_frame: self.host,
            tracking: self.tracking,
            lost_frames: self.lost_frames,
            recovered_frames: self.recovered_frames,
            ate_rmse_m: self.alignment.as_ref().map(|(_, rmse)| *rmse),
            ate_pairs: self.ate.len(),
            volume: VolumeStatus {
                kind: t.kind.name(),
                dims_voxels: t.box_dims_voxels(),
                pool_blocks: if t.kind == MapKind::Sparse { t.pool_blocks } else { 0 },
                blocks_used: self.map.map_or(0, |m| m.blocks_used),
                blocks_on_host: self.map.map_or(0, |m| m.blocks_on_host),
                host_bytes: self.map.map_or(0, |m| m.host_bytes),
                swap_margin_percent: self.map.map_or(0, |m| m.swap_margin_percent),
                full: self.map.is_some_and(|m| m.exhausted()),
                voxel_size_m: t.voxel_size_m,
                truncation_m: t.truncation_m,
                memory_bytes: t.memory_bytes(),
            },
            latency_ms: self.latency_ms,
            features: self.pipeline.as_ref().and_then(|p| p.assist.as_ref()).map(|a| {
                let AssistStats { guesses, relocalisations, relocalisations_confirmed, recoveries, withheld, .. } = a.stats();
                let mut ms = a.frame_ms().iter().rev().take(STATS_WINDOW).copied().collect::<Vec<f64>>();
                ms.sort_by(f64::total_cmp);
                let pair = self.pair.as_ref().map(|v| PairStatus {
                    frame: v.frame,
                    reference_frame: v.reference_frame,
                    keypoints: v.current.len(),
                    reference_keypoints: v.reference.len(),
                    matches: v.matches.len(),
                    inliers: v.matches.iter().filter(|m| m.2).count(),
                    stage: PAIR_STAGES[self.odometry_stage],
                    stages_ms: v.stages_ms.map(|t| t.is_finite().then_some(t)),
                });
                FeatureStatus { guesses, relocalisations, relocalisations_confirmed, recoveries, withheld, keyframes: a.keyframes(), median_ms: ms.get(ms.len() / 2).copied().unwrap_or(0.0), pair }
            }),
            planes: self.plane_status.clone().filter(|_| self.pipeline.as_ref().is_some_and(|p| p.planes.is_some())).map(|mut s| {
                s.median_ms = self.plane_ms.median().unwrap_or(0.0);
                s
            }),
            world: self.pipeline.as_ref().and_then(|p| p.planes.as_ref()).map(|p| p.world.status()),
        }
    }
}

/// Segments the frame the pipeline just submitted (its preprocessed maps), or the fused map's
/// depth `encoder` rendered and preprocessed, into planes, colours its labels into the plane
/// view and copies the plane table for reading, in one submission;
/// the table comes back a frame or so later ([`FusionMode::collect_planes`]): nothing waits.
/// False when both table slots were still in flight (this frame's table is not read).
fn segment_planes(gpu: &Gpu, planes: &mut PlaneViews, mut encoder: wgpu::CommandEncoder, index: u64, with_labels: bool) -> Result<bool, String> {
    planes.segmenter.encode(gpu, &mut encoder);
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("web.planes.view"), timestamp_writes: None });
        planes.view.dispatch_in(gpu, &mut pass);
    }
    let texture = planes.canvas.draw(&mut encoder, &planes.view.image)?;
    let slot = planes.segmenter.encode_table_copy(gpu, &mut encoder, with_labels);
    let submission = gpu.submit([encoder.finish()]);
    GpuCanvas::present(gpu, [texture]);
    if let Some(slot) = slot {
        planes.segmenter.start_table_read(gpu, slot, submission, index, with_labels);
    }
    Ok(slot.is_some())
}

/// Colours the frame's depth, normals and predicted model on the GPU and copies them into
/// their canvases (one submission, no readback); the colour image, decoded on the CPU anyway,
/// goes to its 2D canvas directly.
fn draw_frame_views(gpu: &Gpu, p: &Pipeline, frame: &RgbdFrame) -> Result<(), String> {
    let v = &p.views;
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("web.frame_views") });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("web.frame_views"), timestamp_writes: None });
        v.depth.dispatch_in(gpu, &mut pass);
        v.normals.dispatch_in(gpu, &mut pass);
        v.model.dispatch_in(gpu, &mut pass);
    }
    let textures = [v.depth_canvas.draw(&mut encoder, &v.depth.image)?, v.normals_canvas.draw(&mut encoder, &v.normals.image)?, v.model_canvas.draw(&mut encoder, &v.model.image)?];
    gpu.submit([encoder.finish()]);
    GpuCanvas::present(gpu, textures);
    let (w, h) = (frame.color.width_px, frame.color.height_px);
    view::draw_rgba(&ui::element("view-colour")?, w, h, &view::rgba_from_rgb(&frame.color.rgb8)).map_err(|e| crate::link::js_text(&e))?;
    Ok(())
}

/// Draws the odometry view and its caption (what the stage shows, the counts, the stage
/// times); a pair whose images are missing is described, not drawn.
fn draw_odometry_view(pair: Option<&PairView>, reference: Option<&FrameImage>, current: Option<&FrameImage>, stage: usize) {
    let Some(pair) = pair else { return };
    let what = [
        "update: the two frames (uploaded and preprocessed)",
        "detection: FAST-9 keypoints per grid cell that pass 002's depth border filter",
        "description: each keypoint's orientation (its 256-bit descriptor is taken along it)",
        "matching: the matches kept (Lowe ratio 0.8, mutual)",
        "estimation: RANSAC inliers (green) and outliers (red)",
    ][stage.min(PAIR_STAGES.len() - 1)];
    let inliers = pair.matches.iter().filter(|m| m.2).count();
    ui::set_text(
        "odometry-stage",
        &format!("frame {} vs {}: {what} · {} / {} keypoints · {} matches · {inliers} inliers", pair.frame, pair.reference_frame, pair.reference.len(), pair.current.len(), pair.matches.len()),
    );
    let times: Vec<String> = PAIR_STAGES.iter().zip(pair.stages_ms).map(|(name, ms)| if ms.is_finite() { format!("{name} {ms:.1}") } else { format!("{name} -") }).collect();
    ui::set_text("odometry-times", &format!("ms: {} (GPU timestamps; estimation on the host)", times.join(" · ")));
    if let (Some(r), Some(c)) = (reference, current)
        && r.0 == pair.reference_frame
        && c.0 == pair.frame
        && let Ok(canvas) = ui::element::<web_sys::HtmlCanvasElement>("view-odometry")
    {
        view::draw_odometry_pair(&canvas, r, c, pair, stage).ok();
    }
}

/// Frame `index`'s depth at `map_from_camera`, for the virtual sensor's comparison.
fn real_frame(index: u64, depth_units: Rc<Vec<u16>>, calibration: RgbdCalibration, map_from_camera: Se3) -> RealFrame {
    RealFrame { index, depth_units, units_per_metre: calibration.depth_units_per_metre, intrinsics: calibration.intrinsics, map_from_camera }
}

/// The free view's first look at an opened map: at the mean of its blocks, from twice their
/// RMS spread (within the sensor's useful range), about the up its file names (a file without
/// one: −y, a first camera's up).
fn first_look(map: &OpenedMap) -> Orbit {
    let up = map.header.up_in_map.map_or(DVec3::NEG_Y, |u| DVec3::from(u.map(f64::from)));
    Orbit::looking_at(map.centre_m, (2.0 * map.spread_m).clamp(0.5, 6.0), up)
}
