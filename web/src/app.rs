// SPDX-License-Identifier: MIT
//! The app: connects to a bridge, runs KinectFusion on every frame it receives, and keeps the
//! views, the status panel and the `window.webfusion` test hook current.
//!
//! One async loop owns all state. It takes events from the inbox, decodes protocol messages,
//! keeps at most one frame waiting (in real-time mode a newer frame replaces it and the older
//! one counts as dropped), processes it on the GPU, then redraws.

use std::collections::VecDeque;
use std::rc::Rc;

use glam::DVec3;
use wasm_bindgen::prelude::*;
use web_time::Instant;
use webfusion_core::fusion::{FusionConfig, KinectFusion, RaycastTarget, TrackingState};
use webfusion_core::io::trajectory::format_tum_trajectory;
use webfusion_core::protocol::{Control, Delivery, FrameMessage, Hello, Message, PlaybackState, Status};
use webfusion_core::source::TimedPose;
use webfusion_core::tsdf::{DEFAULT_TRUNCATION_VOXELS, TsdfConfig, VolumePlacement};
use webfusion_core::{Gpu, GpuOptions, PinholeIntrinsics, RgbdCalibration};

use crate::link::{Event, Inbox, Link, Ui, js_text, push_later};
use crate::ui;
use crate::view::{self, Orbit};

/// First and longest wait before reconnecting, milliseconds.
const BACKOFF_FIRST_MS: i32 = 500;
const BACKOFF_MAX_MS: i32 = 8000;
/// The free view's camera.
const FREE_VIEW: PinholeIntrinsics = PinholeIntrinsics { fx_px: 420.0, fy_px: 420.0, cx_px: 319.5, cy_px: 239.5, width_px: 640, height_px: 480 };
/// Frames the fps figure averages over.
const FPS_WINDOW: usize = 20;

/// Entry point: runs when the wasm module loads.
#[wasm_bindgen(start)]
pub fn start() {
    wasm_bindgen_futures::spawn_local(async {
        if let Err(message) = run().await {
            ui::set_text("status", &format!("error: {message}"));
            ui::set_text("link-state", "stopped");
            let hook = serde_json::json!({ "state": "error", "message": message });
            publish(&hook, "");
        }
    });
}

/// Settings from the form (and the URL that pre-fills it).
#[derive(Clone, Debug, PartialEq)]
struct Settings {
    config: FusionConfig,
}

impl Settings {
    /// Reads the settings form.
    fn from_form() -> Result<Self, String> {
        let number = |id: &str, what: &str| -> Result<f32, String> { ui::value(id).trim().parse::<f32>().map_err(|_| format!("{what}: {:?} is not a number", ui::value(id))) };
        let dims: u32 = ui::value("set-volume").parse().map_err(|_| "volume size must be a whole number of voxels".to_owned())?;
        let voxel_m = number("set-voxel-mm", "voxel size")? / 1000.0;
        let truncation_voxels = number("set-trunc-vox", "truncation")?;
        let tsdf = TsdfConfig {
            truncation_m: truncation_voxels * voxel_m,
            placement: if ui::value("set-centred").is_empty() { VolumePlacement::InFront } else { VolumePlacement::Centred },
            ..TsdfConfig::cube(dims, voxel_m)
        };
        let mut config = FusionConfig { tsdf, ..FusionConfig::default() };
        config.icp.iterations_per_level = ui::value("set-icp-iters").split(',').map(|s| s.trim().parse::<u32>().map_err(|_| format!("ICP iterations: {s:?} is not a whole number"))).collect::<Result<_, _>>()?;
        config.icp.dist_thresh_m = number("set-icp-dist-cm", "ICP distance")? / 100.0;
        config.icp.angle_thresh_rad = number("set-icp-angle-deg", "ICP angle")?.to_radians();
        config.icp.rgb_weight = number("set-rgb-weight", "photometric weight")?;
        config.validate().map_err(|e| e.to_string())?;
        Ok(Self { config })
    }
}

/// Fills the settings form with the native defaults, then the URL's overrides.
fn fill_settings_form(query: &std::collections::HashMap<String, String>) {
    let defaults = FusionConfig::default();
    let t = &defaults.tsdf;
    let icp = &defaults.icp;
    let iterations: Vec<String> = icp.iterations_per_level.iter().map(u32::to_string).collect();
    for (id, key, value) in [
        ("set-volume", "volume", t.dims_voxels[0].to_string()),
        ("set-voxel-mm", "voxel_mm", format!("{:.2}", t.voxel_size_m * 1000.0)),
        ("set-trunc-vox", "trunc_vox", DEFAULT_TRUNCATION_VOXELS.to_string()),
        ("set-centred", "centred", String::new()),
        ("set-icp-iters", "icp", iterations.join(",")),
        ("set-icp-dist-cm", "icp_dist_cm", format!("{}", icp.dist_thresh_m * 100.0)),
        ("set-icp-angle-deg", "icp_angle_deg", format!("{}", icp.angle_thresh_rad.to_degrees().round())),
        ("set-rgb-weight", "rgb_weight", icp.rgb_weight.to_string()),
    ] {
        ui::set_value(id, query.get(key).map_or(value.as_str(), String::as_str));
    }
}

/// What the bridge said about its source.
#[derive(Clone, Debug, PartialEq)]
struct SourceInfo {
    name: String,
    frame_count: Option<u64>,
    calibration: RgbdCalibration,
    has_ground_truth: bool,
}

/// The state of the link to the bridge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum LinkState {
    Disconnected,
    Connecting,
    Connected,
    /// Dropped; retrying after a pause.
    Retrying,
}

struct App {
    inbox: Rc<Inbox>,
    gpu: Gpu,
    adapter: String,
    settings: Settings,
    // The link.
    link: Option<Link>,
    generation: u64,
    link_state: LinkState,
    /// The user wants a connection (reconnect after drops).
    want_connected: bool,
    backoff_ms: i32,
    reconnects: u32,
    last_error: Option<String>,
    // The source and playback.
    source: Option<SourceInfo>,
    server: Option<Status>,
    playing: bool,
    every_frame: bool,
    rate: f32,
    looping: bool,
    /// A frame waiting to be processed, and when it arrived.
    pending: Option<(FrameMessage, Instant)>,
    /// Arrival to fused, of the last frame, milliseconds (queueing included).
    latency_ms: Option<f64>,
    dropped_here: u64,
    // The reconstruction.
    fusion: Option<KinectFusion>,
    free_view: Option<RaycastTarget>,
    last_index: Option<u64>,
    trajectory: Vec<TimedPose>,
    ground_truth: Vec<TimedPose>,
    tracking: &'static str,
    lost_frames: u64,
    recovered_frames: u64,
    /// Per-frame stage times, milliseconds (see [`STAGES`]).
    stage_samples_ms: Vec<[f64; 6]>,
    frame_instants: VecDeque<Instant>,
    /// Milliseconds from connecting to the first processed frame.
    connected_at: Option<Instant>,
    first_frame_ms: Option<f64>,
    ate: Option<webfusion_core::eval::AteReport>,
    /// The trajectory as TUM text, rebuilt only when a pose was added or the run reset.
    trajectory_tum: ((u64, usize), String),
    /// Counts reconstructions (runs) started, to key `trajectory_tum`.
    run_id: u64,
    // The free view.
    orbit: Option<Orbit>,
    view_dirty: bool,
    view_colour: bool,
}

/// Names of the stages in `stage_samples_ms`, in order.
const STAGES: [&str; 6] = ["decode", "preprocess", "track", "integrate", "raycast", "views"];

async fn run() -> Result<(), String> {
    let has_webgpu = web_sys::window().is_some_and(|w| js_sys::Reflect::has(&w.navigator(), &"gpu".into()).unwrap_or(false));
    if !has_webgpu {
        return Err("this browser has no WebGPU (navigator.gpu is missing). Use Chrome or Edge 113+ (on Linux: chrome://flags/#enable-unsafe-webgpu, or start Chromium with --enable-unsafe-webgpu), Firefox 141+ on Windows, or Safari 26+. The native `webfusion reconstruct` runs the same pipeline without a browser.".into());
    }
    ui::set_text("status", "requesting a WebGPU adapter…");
    let gpu = Gpu::new(&GpuOptions::default())
        .await
        .map_err(|e| format!("this browser has WebGPU but gave no usable adapter ({e}). On Linux, Chrome/Chromium needs --enable-unsafe-webgpu (and --ignore-gpu-blocklist on blocklisted GPUs); check chrome://gpu."))?;
    // Browsers keep the adapter's name to themselves; say what is known.
    let adapter = if gpu.adapter_info.name.is_empty() { format!("browser WebGPU, {:?} adapter", gpu.adapter_info.device_type) } else { gpu.adapter_summary() };
    ui::set_text("adapter", &adapter);
    let query = ui::query();
    fill_settings_form(&query);
    let settings = Settings::from_form()?;
    let bridge = query.get("bridge").cloned().or_else(|| ui::local_get("webfusion.bridge")).unwrap_or_else(ui::own_bridge_url);
    let token = query.get("token").cloned().or_else(|| ui::local_get("webfusion.token")).unwrap_or_default();
    ui::set_value("bridge-url", &bridge);
    ui::set_value("bridge-token", &token);
    let every_frame = query.get("every").is_none_or(|v| v != "0");
    ui::set_value("every-frame", if every_frame { "1" } else { "" });
    let rate: f32 = query.get("rate").and_then(|r| r.parse().ok()).unwrap_or(1.0);
    ui::set_value("rate", &rate.to_string());

    let inbox = Rc::new(Inbox::default());
    ui::bind_controls(&inbox);
    let canvas: web_sys::HtmlCanvasElement = ui::element("view-free")?;
    ui::bind_gestures(&inbox, &canvas);
    let mut app = App {
        inbox: Rc::clone(&inbox),
        gpu,
        adapter,
        settings,
        link: None,
        generation: 0,
        link_state: LinkState::Disconnected,
        want_connected: false,
        backoff_ms: BACKOFF_FIRST_MS,
        reconnects: 0,
        last_error: None,
        source: None,
        server: None,
        playing: query.get("autoplay").is_some_and(|v| v != "0"),
        every_frame,
        rate,
        looping: false,
        pending: None,
        latency_ms: None,
        dropped_here: 0,
        fusion: None,
        free_view: None,
        last_index: None,
        trajectory: Vec::new(),
        ground_truth: Vec::new(),
        tracking: "idle",
        lost_frames: 0,
        recovered_frames: 0,
        stage_samples_ms: Vec::new(),
        frame_instants: VecDeque::new(),
        connected_at: None,
        first_frame_ms: None,
        ate: None,
        trajectory_tum: ((0, 0), String::new()),
        run_id: 0,
        orbit: None,
        view_dirty: false,
        view_colour: false,
    };
    // Connect at once to the page's own bridge (or the remembered one), unless told not to.
    if query.get("connect").is_none_or(|v| v != "0") {
        inbox.push(Event::Ui(Ui::Connect));
    }
    app.publish();
    loop {
        let event = inbox.next().await;
        app.handle(event).await;
        while let Some(event) = inbox.try_next() {
            app.handle(event).await;
        }
        if let Some((frame, arrived)) = app.pending.take() {
            match app.process(frame).await {
                Ok(()) => app.latency_ms = Some(arrived.elapsed().as_secs_f64() * 1e3),
                Err(message) => app.fail(&message),
            }
        }
        if app.view_dirty
            && let Err(message) = app.render_free_view().await
        {
            app.fail(&message);
        }
        let errors = app.gpu.take_errors();
        if !errors.is_empty() {
            app.fail(&format!("WebGPU reported errors: {}", errors.join("; ")));
        }
        app.publish();
    }
}

impl App {
    fn fail(&mut self, message: &str) {
        self.last_error = Some(message.to_owned());
        self.playing = false;
        web_sys::console::error_1(&message.into());
    }

    fn send(&self, control: Control) {
        if let Some(link) = &self.link {
            link.send(&Message::Control(control).encode());
        }
    }

    fn is_live(&self) -> bool {
        self.source.as_ref().is_some_and(|s| s.frame_count.is_none())
    }

    async fn handle(&mut self, event: Event) {
        match event {
            Event::Opened { generation } if generation == self.generation => {
                self.link_state = LinkState::Connected;
                self.connected_at = Some(Instant::now());
            }
            Event::Received { generation, bytes } if generation == self.generation => match Message::decode(&bytes) {
                Ok(Message::Hello(hello)) => self.on_hello(hello),
                Ok(Message::Status(status)) => {
                    if status.state == PlaybackState::Ended {
                        self.playing = false;
                    }
                    self.server = Some(status);
                }
                Ok(Message::Frame(frame)) => {
                    if self.pending.replace((frame, Instant::now())).is_some() {
                        self.dropped_here += 1;
                    }
                }
                Ok(Message::Error { code, message }) => self.last_error = Some(format!("bridge: {message} ({code:?})")),
                Ok(Message::Control(_)) => self.last_error = Some("the bridge sent a control message".to_owned()),
                Err(e) => self.last_error = Some(format!("undecodable message from the bridge: {e}")),
            },
            Event::Closed { generation, code, reason } if generation == self.generation => {
                self.link = None;
                if self.want_connected {
                    self.link_state = LinkState::Retrying;
                    if !reason.is_empty() {
                        self.last_error = Some(format!("bridge closed the connection ({code}): {reason}"));
                    }
                    push_later(&self.inbox, self.backoff_ms, Event::Reconnect { generation: self.generation });
                    self.backoff_ms = (self.backoff_ms * 2).min(BACKOFF_MAX_MS);
                } else {
                    self.link_state = LinkState::Disconnected;
                }
            }
            Event::Reconnect { generation } if generation == self.generation && self.want_connected && self.link.is_none() => {
                self.reconnects += 1;
                self.connect();
            }
            Event::Opened { .. } | Event::Received { .. } | Event::Closed { .. } | Event::Reconnect { .. } => {}
            Event::Ui(ui_event) => self.on_ui(ui_event).await,
        }
    }

    fn connect(&mut self) {
        let base = ui::value("bridge-url");
        let token = ui::value("bridge-token");
        ui::local_set("webfusion.bridge", &base);
        ui::local_set("webfusion.token", &token);
        let url = if token.is_empty() {
            base
        } else {
            let separator = if base.contains('?') { '&' } else { '?' };
            format!("{base}{separator}token={}", String::from(js_sys::encode_uri_component(&token)))
        };
        self.generation += 1;
        self.link = None;
        self.want_connected = true;
        self.link_state = LinkState::Connecting;
        match Link::open(&url, self.generation, &self.inbox) {
            Ok(link) => self.link = Some(link),
            Err(message) => {
                self.last_error = Some(message);
                self.want_connected = false;
                self.link_state = LinkState::Disconnected;
            }
        }
    }

    fn on_hello(&mut self, hello: Hello) {
        self.backoff_ms = BACKOFF_FIRST_MS;
        self.last_error = None;
        let info = SourceInfo { name: hello.source_name, frame_count: hello.frame_count, calibration: hello.calibration, has_ground_truth: hello.has_ground_truth };
        let same_source = self.source.as_ref() == Some(&info);
        if !same_source {
            self.source = Some(info);
            self.fusion = None;
            self.free_view = None;
            self.reset_run();
        } else if let (Some(last), Some(count)) = (self.last_index, self.source.as_ref().and_then(|s| s.frame_count)) {
            // A reconnect to the same log: carry on after the last frame fused.
            if last + 1 < count {
                self.send(Control::Seek(last + 1));
            }
        }
        let count = self.source.as_ref().and_then(|s| s.frame_count).unwrap_or(0);
        ui::set_disabled("seek", self.is_live());
        ui::set_disabled("loop", self.is_live());
        if let Ok(seek) = ui::element::<web_sys::HtmlInputElement>("seek") {
            seek.set_max(&count.saturating_sub(1).to_string());
        }
        if self.playing {
            self.start_playing();
        }
    }

    /// Asks for frames: one at a time in every-frame mode (lossless, paced by this page), or
    /// streamed at the source's rate in real-time mode.
    fn start_playing(&mut self) {
        self.playing = true;
        if self.every_frame && !self.is_live() {
            self.send(Control::Delivery(Delivery::Lossless));
            self.request_next();
        } else {
            self.send(Control::Delivery(Delivery::Live));
            if !self.is_live() {
                self.send(Control::Rate(self.rate));
                self.send(Control::Loop(self.looping));
            }
            self.send(Control::Play);
        }
    }

    /// In every-frame mode, steps to the next frame unless the log is done.
    fn request_next(&mut self) {
        let count = self.source.as_ref().and_then(|s| s.frame_count).unwrap_or(0);
        let next = self.last_index.map_or(0, |i| i + 1);
        if next < count || self.looping {
            self.send(Control::Step);
        } else {
            self.playing = false;
        }
    }

    async fn on_ui(&mut self, event: Ui) {
        match event {
            Ui::Connect => self.connect(),
            Ui::Disconnect => {
                self.want_connected = false;
                self.generation += 1;
                self.link = None;
                self.link_state = LinkState::Disconnected;
            }
            Ui::Playback(Control::Play) => {
                if self.server.as_ref().is_some_and(|s| s.state == PlaybackState::Ended) || self.last_index.is_some_and(|i| Some(i + 1) == self.source.as_ref().and_then(|s| s.frame_count)) {
                    // Play after the end starts a new pass.
                    self.reset_run();
                    self.send(Control::Seek(0));
                }
                self.start_playing();
            }
            Ui::Playback(Control::Pause) => {
                self.playing = false;
                self.send(Control::Pause);
            }
            Ui::Playback(Control::Step) => {
                self.playing = false;
                self.send(Control::Delivery(Delivery::Lossless));
                self.send(Control::Step);
            }
            Ui::Playback(Control::Seek(index)) => {
                // A jump in time is a new reconstruction from that frame.
                self.reset_run();
                self.send(Control::Seek(index));
                self.last_index = index.checked_sub(1);
                if self.playing {
                    self.start_playing();
                }
            }
            Ui::Playback(Control::Rate(rate)) => {
                self.rate = rate.clamp(0.0, 1000.0);
                if !self.every_frame {
                    self.send(Control::Rate(self.rate));
                }
            }
            Ui::Playback(Control::Loop(on)) => {
                self.looping = on;
                self.send(Control::Loop(on));
            }
            // Delivery follows the every-frame setting.
            Ui::Playback(Control::Delivery(_)) => {}
            Ui::EveryFrame(on) => {
                self.every_frame = on;
                if self.playing {
                    self.send(Control::Pause);
                    self.start_playing();
                }
            }
            Ui::ApplySettings => match Settings::from_form() {
                Ok(settings) => {
                    self.settings = settings;
                    self.fusion = None;
                    self.free_view = None;
                    self.reset_run();
                }
                Err(message) => self.last_error = Some(format!("settings: {message}")),
            },
            // reset_run also clears the volume.
            Ui::Reset => self.reset_run(),
            Ui::ExportPly | Ui::ExportGlb => {
                let glb = event == Ui::ExportGlb;
                if let Err(message) = self.export_mesh(glb).await {
                    self.last_error = Some(format!("mesh export: {message}"));
                }
            }
            Ui::ExportTrajectory => {
                let text = format_tum_trajectory(&self.trajectory);
                if let Err(e) = ui::download("trajectory.txt", text.as_bytes(), "text/plain") {
                    self.last_error = Some(format!("trajectory export: {}", js_text(&e)));
                }
            }
            Ui::Orbit(dx, dy) => {
                if let Some(orbit) = &mut self.orbit {
                    orbit.orbit(dx, dy);
                    self.view_dirty = true;
                }
            }
            Ui::Pan(dx, dy) => {
                if let Some(orbit) = &mut self.orbit {
                    orbit.pan(dx, dy, FREE_VIEW.fx_px);
                    self.view_dirty = true;
                }
            }
            Ui::Zoom(factor) => {
                if let Some(orbit) = &mut self.orbit {
                    orbit.zoom(factor);
                    self.view_dirty = true;
                }
            }
            Ui::ViewColour(on) => {
                self.view_colour = on;
                self.view_dirty = true;
            }
        }
    }

    /// Forgets the trajectory and statistics; the next frame starts a new reconstruction.
    fn reset_run(&mut self) {
        if let Some(fusion) = &mut self.fusion {
            fusion.reset(&self.gpu);
        }
        self.run_id += 1;
        self.last_index = None;
        self.trajectory.clear();
        self.ground_truth.clear();
        self.tracking = "idle";
        self.lost_frames = 0;
        self.recovered_frames = 0;
        self.stage_samples_ms.clear();
        self.frame_instants.clear();
        self.ate = None;
        self.pending = None;
        self.orbit = None;
        self.view_dirty = true;
    }

    /// Fuses one frame and redraws the per-frame views.
    async fn process(&mut self, message: FrameMessage) -> Result<(), String> {
        let Some(source) = self.source.clone() else { return Err("a frame arrived before the bridge's hello".to_owned()) };
        let t0 = Instant::now();
        let frame = message.decode_images(&source.calibration).map_err(|e| format!("frame {}: {e}", message.index))?;
        let decode_ms = t0.elapsed().as_secs_f64() * 1e3;
        if self.last_index.is_some_and(|last| message.index <= last) {
            // The log looped (or was sought backwards): a new pass.
            self.reset_run();
        }
        if self.fusion.is_none() {
            self.fusion = Some(KinectFusion::new(&self.gpu, source.calibration, self.settings.config.clone()).map_err(|e| format!("cannot build the pipeline: {e}"))?);
            self.free_view = None;
        }
        let Some(fusion) = self.fusion.as_mut() else { return Ok(()) };
        let report = fusion.process_frame(&self.gpu, &frame).await.map_err(|e| format!("frame {}: {e}", message.index))?;
        self.last_index = Some(message.index);
        self.trajectory.push(TimedPose { timestamp_ns: frame.depth_timestamp_ns, world_from_camera: report.world_from_camera });
        if let Some(pose) = message.ground_truth {
            self.ground_truth.push(TimedPose { timestamp_ns: frame.depth_timestamp_ns, world_from_camera: pose });
        }
        self.tracking = report.state.name();
        match report.state {
            TrackingState::Lost(_) => self.lost_frames += 1,
            TrackingState::Recovered => self.recovered_frames += 1,
            _ => {}
        }
        if self.orbit.is_none() {
            // Look at a point 1.5 m in front of the first camera.
            let target = report.world_from_camera.transform_point(DVec3::new(0.0, 0.0, 1.5));
            self.orbit = Some(Orbit::looking_at(target, 3.0));
        }
        if self.ground_truth.len() >= 3 {
            self.ate = webfusion_core::eval::ate(&self.ground_truth, &self.trajectory, &Default::default()).ok();
        }
        let t_views = Instant::now();
        self.draw_frame_views(&frame).await?;
        let views_ms = t_views.elapsed().as_secs_f64() * 1e3;
        let t = report.gpu_ms.unwrap_or_default();
        self.stage_samples_ms.push([decode_ms, t.preprocess, t.track, t.integrate, t.raycast, views_ms]);
        let now = Instant::now();
        self.frame_instants.push_back(now);
        while self.frame_instants.len() > FPS_WINDOW {
            self.frame_instants.pop_front();
        }
        if self.first_frame_ms.is_none()
            && let Some(at) = self.connected_at
        {
            self.first_frame_ms = Some((now - at).as_secs_f64() * 1e3);
        }
        self.view_dirty = true;
        if self.playing && self.every_frame && !self.is_live() {
            self.request_next();
        }
        Ok(())
    }

    /// Colour, depth, normals and the model shaded from the tracked camera.
    async fn draw_frame_views(&self, frame: &webfusion_core::RgbdFrame) -> Result<(), String> {
        let Some(fusion) = &self.fusion else { return Ok(()) };
        let js = |e: JsValue| js_text(&e);
        let (w, h) = (frame.depth.width_px, frame.depth.height_px);
        view::draw_rgba(&ui::element("view-colour")?, w, h, &view::rgba_from_rgb(&frame.color.rgb8)).map_err(js)?;
        let scale = 1.0 / self.source.as_ref().map_or(1000.0, |s| s.calibration.depth_units_per_metre);
        view::draw_rgba(&ui::element("view-depth")?, w, h, &view::rgba_from_depth_m(frame.depth.units.iter().map(|&d| f32::from(d) * scale))).map_err(js)?;
        let n = (w * h) as usize;
        let normals: Vec<[f32; 4]> = self.gpu.read_buffer(&fusion.preprocessor().levels[0].normal_in_camera, n).await.map_err(|e| e.to_string())?;
        view::draw_rgba(&ui::element("view-normals")?, w, h, &view::rgba_from_normals(&normals)).map_err(js)?;
        let model: Vec<[f32; 4]> = self.gpu.read_buffer(&fusion.prediction().normal_in_world, n).await.map_err(|e| e.to_string())?;
        view::draw_rgba(&ui::element("view-model")?, w, h, &view::rgba_from_normals(&model)).map_err(js)?;
        Ok(())
    }

    /// Raycasts the model from the free viewer and draws the trajectories over it.
    async fn render_free_view(&mut self) -> Result<(), String> {
        self.view_dirty = false;
        let (Some(fusion), Some(orbit)) = (&self.fusion, self.orbit) else { return Ok(()) };
        if fusion.frames_submitted() == 0 {
            return Ok(());
        }
        let target = self.free_view.get_or_insert_with(|| RaycastTarget::new(&self.gpu, fusion.volume(), FREE_VIEW, "free_view"));
        let world_from_viewer = orbit.world_from_viewer();
        let mut encoder = self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("web.free_view") });
        target.render(&self.gpu, &mut encoder, fusion.volume(), &world_from_viewer, (0.05, 20.0)).map_err(|e| e.to_string())?;
        self.gpu.submit_and_wait(encoder).await.map_err(|e| e.to_string())?;
        let rgba = if self.view_colour {
            let pixels: Vec<u32> = self.gpu.read_buffer(&target.color_rgba8, FREE_VIEW.pixel_count()).await.map_err(|e| e.to_string())?;
            view::rgba_from_packed(&pixels)
        } else {
            let normals: Vec<[f32; 4]> = self.gpu.read_buffer(&target.normal_in_world, FREE_VIEW.pixel_count()).await.map_err(|e| e.to_string())?;
            view::rgba_from_normals(&normals)
        };
        let canvas: web_sys::HtmlCanvasElement = ui::element("view-free")?;
        let ctx = view::draw_rgba(&canvas, FREE_VIEW.width_px, FREE_VIEW.height_px, &rgba).map_err(|e| js_text(&e))?;
        if let Some(ate) = &self.ate {
            // Ground truth, moved into this reconstruction's frame by the ATE alignment.
            let est_from_gt = ate.alignment.gt_from_est.inverse();
            let scale = ate.alignment.scale;
            let gt = self.ground_truth.iter().map(|p| est_from_gt.transform_point(p.world_from_camera.translation_m) / scale);
            view::draw_path(&ctx, &FREE_VIEW, &world_from_viewer, gt, "#4caf50");
        }
        view::draw_path(&ctx, &FREE_VIEW, &world_from_viewer, self.trajectory.iter().map(|p| p.world_from_camera.translation_m), "#ffb300");
        if let Some(last) = self.trajectory.last() {
            view::draw_camera(&ctx, &FREE_VIEW, &world_from_viewer, &last.world_from_camera, "#ff5252");
        }
        Ok(())
    }

    async fn export_mesh(&self, glb: bool) -> Result<(), String> {
        let Some(fusion) = &self.fusion else { return Err("nothing fused yet".to_owned()) };
        let mesh = webfusion_core::mesh::extract_mesh(&self.gpu, fusion.volume()).await.map_err(|e| e.to_string())?;
        let mut bytes = Vec::new();
        if glb { webfusion_core::mesh::write_glb(&mesh, &mut bytes) } else { webfusion_core::mesh::write_ply(&mesh, &mut bytes) }.map_err(|e| e.to_string())?;
        let (name, mime) = if glb { ("mesh.glb", "model/gltf-binary") } else { ("mesh.ply", "application/octet-stream") };
        ui::download(name, &bytes, mime).map_err(|e| js_text(&e))
    }

    /// Median time of each stage over the frames so far (0 before the first).
    fn stage_medians_ms(&self) -> [f64; 6] {
        let mut medians = [0.0; 6];
        for (stage, median) in medians.iter_mut().enumerate() {
            let mut samples: Vec<f64> = self.stage_samples_ms.iter().map(|s| s[stage]).collect();
            if !samples.is_empty() {
                samples.sort_by(f64::total_cmp);
                *median = samples[samples.len() / 2];
            }
        }
        medians
    }

    /// Updates the status panel and `window.webfusion`.
    fn publish(&mut self) {
        let frames_total = self.source.as_ref().and_then(|s| s.frame_count);
        let frames_done = self.trajectory.len();
        let fps = match (self.frame_instants.front(), self.frame_instants.back()) {
            (Some(first), Some(last)) if self.frame_instants.len() >= 2 => (self.frame_instants.len() - 1) as f64 / (*last - *first).as_secs_f64().max(1e-9),
            _ => 0.0,
        };
        let medians = self.stage_medians_ms();
        let stages: serde_json::Map<String, serde_json::Value> = STAGES.iter().zip(medians).map(|(name, ms)| ((*name).to_owned(), serde_json::json!(ms))).collect();
        let state = match (self.link_state, self.playing, &self.server) {
            _ if self.last_error.is_some() => "error",
            (LinkState::Disconnected, ..) => "disconnected",
            (LinkState::Connecting, ..) => "connecting",
            (LinkState::Retrying, ..) => "reconnecting",
            (LinkState::Connected, true, _) => "running",
            (LinkState::Connected, false, Some(s)) if s.state == PlaybackState::Ended || frames_total.is_some_and(|n| frames_done as u64 == n && n > 0) => "ended",
            (LinkState::Connected, false, _) => "paused",
        };
        let volume = &self.settings.config.tsdf;
        let status = serde_json::json!({
            "state": state,
            "link": format!("{:?}", self.link_state).to_lowercase(),
            "message": self.last_error.clone().unwrap_or_default(),
            "source": self.source.as_ref().map(|s| s.name.clone()),
            "frames_done": frames_done,
            "frames_total": frames_total,
            "last_index": self.last_index,
            "fps": fps,
            "stages_ms": stages,
            "tracking": self.tracking,
            "lost_frames": self.lost_frames,
            "recovered_frames": self.recovered_frames,
            "ate_rmse_m": self.ate.as_ref().map(|a| a.error_m.rmse),
            "adapter": self.adapter,
            "volume": { "dims_voxels": volume.dims_voxels, "voxel_size_m": volume.voxel_size_m, "truncation_m": volume.truncation_m, "memory_bytes": volume.memory_bytes() },
            "latency_ms": self.latency_ms,
            "frames_dropped": self.dropped_here + self.server.as_ref().map_or(0, |s| s.frames_dropped),
            "reconnects": self.reconnects,
            "time_to_first_frame_ms": self.first_frame_ms,
        });
        let key = (self.run_id, self.trajectory.len());
        if self.trajectory_tum.0 != key {
            self.trajectory_tum = (key, format_tum_trajectory(&self.trajectory));
        }
        publish(&status, &self.trajectory_tum.1);
        ui::set_text("link-state", status["link"].as_str().unwrap_or(""));
        let mut lines = vec![format!(
            "{state} · {} · frame {frames_done}{} · {fps:.1} fps · tracking {} (lost {}, recovered {})",
            self.source.as_ref().map_or("no source", |s| s.name.as_str()),
            frames_total.map(|n| format!("/{n}")).unwrap_or_default(),
            self.tracking,
            self.lost_frames,
            self.recovered_frames
        )];
        lines.push("median ms: ".to_owned() + &STAGES.iter().zip(medians).map(|(name, ms)| format!("{name} {ms:.1}")).collect::<Vec<_>>().join(" · "));
        let ate = self.ate.as_ref().map_or_else(|| if self.source.as_ref().is_some_and(|s| s.has_ground_truth) { "ATE: waiting for 3 poses".to_owned() } else { "ATE: the source has no ground truth".to_owned() }, |a| format!("ATE {:.2} cm over {} poses", a.error_m.rmse * 100.0, a.error_m.count));
        lines.push(format!(
            "{ate} · latency {} · dropped {} · reconnects {} · volume {}³ × {:.1} mm = {:.0} MiB",
            self.latency_ms.map_or_else(|| "-".to_owned(), |ms| format!("{ms:.0} ms")),
            status["frames_dropped"],
            self.reconnects,
            volume.dims_voxels[0],
            volume.voxel_size_m * 1000.0,
            volume.memory_bytes() as f64 / (1 << 20) as f64,
        ));
        if let Some(message) = &self.last_error {
            lines.push(format!("⚠ {message}"));
        }
        ui::set_text("status", &lines.join("\n"));
        if let (Ok(seek), Some(index)) = (ui::element::<web_sys::HtmlInputElement>("seek"), self.last_index) {
            seek.set_value(&index.to_string());
        }
    }
}

/// Publishes `window.webfusion = { status, trajectory_tum }` for tests and tools.
fn publish(status: &serde_json::Value, trajectory_tum: &str) {
    let Some(window) = web_sys::window() else { return };
    let hook = js_sys::Reflect::get(&window, &"webfusion".into()).ok().filter(JsValue::is_object).unwrap_or_else(|| {
        let hook: JsValue = js_sys::Object::new().into();
        js_sys::Reflect::set(&window, &"webfusion".into(), &hook).ok();
        hook
    });
    if let Ok(value) = js_sys::JSON::parse(&status.to_string()) {
        js_sys::Reflect::set(&hook, &"status".into(), &value).ok();
    }
    js_sys::Reflect::set(&hook, &"trajectory_tum".into(), &trajectory_tum.into()).ok();
}
