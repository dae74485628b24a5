// SPDX-License-Identifier: MIT
//! The app shell: connects to a bridge, hands every frame it receives to the running mode
//! (KinectFusion, `fusion_mode.rs`), and keeps the status panel and the `window.webfusion`
//! hook current. It knows nothing of the pipeline beyond the mode's small interface.
//!
//! One async loop owns all state. It takes events from the inbox, decodes protocol messages,
//! keeps at most one frame waiting (in real-time mode a newer frame replaces it and the older
//! one counts as dropped), and submits it to the GPU without waiting for it: in every-frame
//! mode the next frame is requested as soon as one is submitted, so it downloads and decodes
//! while the GPU works. Reports come back a frame later; while any are due the loop polls on
//! a short timer.

use std::rc::Rc;

use wasm_bindgen::prelude::*;
use web_time::Instant;
use webfusion_core::fusion::FusionConfig;
use webfusion_core::map::{MapKind, pool_blocks_for_budget_mib, pool_budget_mib};
use webfusion_core::protocol::{Control, Delivery, FrameMessage, Hello, Message, PlaybackState, parse_rate};
use webfusion_core::tsdf::{DEFAULT_TRUNCATION_VOXELS, TsdfConfig, VolumePlacement};
use webfusion_core::source::DepthNoise;
use webfusion_core::{Gpu, GpuOptions, RgbdCalibration};

use crate::fusion_mode::{FREE_VIEW, FusionMode, PlanesFrom, Received, SensorPose};
use crate::sim::OpenedMap;
use crate::link::{Event, Inbox, Link, Ui, js_text, push_later};
use crate::status::Status;
use crate::ui;

/// First and longest wait before reconnecting, milliseconds.
const BACKOFF_FIRST_MS: i32 = 500;
const BACKOFF_MAX_MS: i32 = 8000;
/// How often the loop looks for frame reports while frames are in flight, milliseconds.
const POLL_MS: i32 = 4;
/// Default playback rate (the source's own).
const DEFAULT_RATE: f32 = 1.0;

/// Entry point: runs when the wasm module loads.
#[wasm_bindgen(start)]
pub fn start() {
    wasm_bindgen_futures::spawn_local(async {
        if let Err(message) = run().await {
            ui::set_text("status", &format!("error: {message}"));
            ui::set_text("link-state", "stopped");
            publish_json(&serde_json::json!({ "state": "error", "message": message }).to_string());
        }
    });
}

/// Settings from the form (and the URL that pre-fills it).
#[derive(Clone, Debug, PartialEq)]
struct Settings {
    config: FusionConfig,
    /// Feature odometry beside ICP (seed 002): initial guesses and relocalisation.
    features: bool,
    /// Plane segmentation (seed 003): off, of every frame, or of the fused map at each
    /// frame's pose.
    planes: Option<PlanesFrom>,
}

impl Settings {
    /// Reads the settings form.
    fn from_form() -> Result<Self, String> {
        let number = |id: &str, what: &str| -> Result<f32, String> {
            let text = ui::value(id);
            text.trim().parse::<f32>().ok().filter(|v| v.is_finite()).ok_or_else(|| format!("{what}: {text:?} is not a finite number"))
        };
        let dims: u32 = ui::value("set-volume").parse().map_err(|_| "volume size must be a whole number of voxels".to_owned())?;
        let voxel_m = number("set-voxel-mm", "voxel size")? / 1000.0;
        let truncation_voxels = number("set-trunc-vox", "truncation")?;
        let kind: MapKind = ui::value("set-map").parse().map_err(|e: webfusion_core::Error| e.to_string())?;
        // The sparse map's GPU memory (its pool of blocks with colour); a big GPU holds fine
        // voxels of a whole room at 261 MiB, the largest pool.
        let pool_blocks = pool_blocks_for_budget_mib(f64::from(number("set-map-mib", "map memory")?)).map_err(|e| e.to_string())?;
        let tsdf = TsdfConfig {
            kind,
            pool_blocks,
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
        let planes = match (ui::value("set-planes").is_empty(), ui::value("set-planes-model").is_empty()) {
            (true, _) => None,
            (false, true) => Some(PlanesFrom::Frames),
            (false, false) => Some(PlanesFrom::FusedMap),
        };
        Ok(Self { config, features: !ui::value("set-features").is_empty(), planes })
    }
}

/// Fills the settings form with the native defaults, then applies the URL's overrides one by
/// one: an override the settings reject (`?volume=abc`, `?icp_dist_cm=-1`) is put back to the
/// default and named in the returned warnings, so a bad link still opens a working app.
fn fill_settings_form(query: &std::collections::HashMap<String, String>) -> (Settings, Vec<String>) {
    let defaults = FusionConfig::default();
    let t = &defaults.tsdf;
    let icp = &defaults.icp;
    let iterations: Vec<String> = icp.iterations_per_level.iter().map(u32::to_string).collect();
    let fields = [
        ("set-map", "map", t.kind.name().to_owned()),
        ("set-volume", "volume", t.dims_voxels[0].to_string()),
        ("set-voxel-mm", "voxel_mm", format!("{:.2}", t.voxel_size_m * 1000.0)),
        ("set-trunc-vox", "trunc_vox", DEFAULT_TRUNCATION_VOXELS.to_string()),
        ("set-map-mib", "map_mib", format!("{:.1}", pool_budget_mib(t.pool_blocks))),
        ("set-centred", "centred", String::new()),
        ("set-icp-iters", "icp", iterations.join(",")),
        ("set-icp-dist-cm", "icp_dist_cm", format!("{}", icp.dist_thresh_m * 100.0)),
        ("set-icp-angle-deg", "icp_angle_deg", format!("{}", icp.angle_thresh_rad.to_degrees().round())),
        ("set-rgb-weight", "rgb_weight", icp.rgb_weight.to_string()),
        ("set-features", "features", "1".to_owned()),
        ("set-planes", "planes", "1".to_owned()),
        ("set-planes-model", "planes_model", String::new()),
    ];
    for (id, _, value) in &fields {
        ui::set_value(id, value);
    }
    let mut warnings = Vec::new();
    for (id, key, default) in &fields {
        let Some(given) = query.get(*key) else { continue };
        ui::set_value(id, given);
        if let Err(message) = Settings::from_form() {
            warnings.push(format!("?{key}={given} ignored ({message}); using {default:?}"));
            ui::set_value(id, default);
        }
    }
    // The defaults always validate; should they not, say so rather than start half-configured.
    let settings = Settings::from_form().unwrap_or_else(|message| {
        warnings.push(format!("the default settings are invalid: {message}"));
        Settings { config: defaults, features: true, planes: Some(PlanesFrom::Frames) }
    });
    (settings, warnings)
}

/// What the bridge said about its source.
#[derive(Clone, Debug, PartialEq)]
struct SourceInfo {
    name: String,
    frame_count: Option<u64>,
    calibration: RgbdCalibration,
    has_ground_truth: bool,
    depth_noise: DepthNoise,
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
    /// Why URL settings were ignored, shown until the next error replaces it.
    settings_warnings: Vec<String>,
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
    server: Option<webfusion_core::protocol::Status>,
    playing: bool,
    every_frame: bool,
    rate: f32,
    looping: bool,
    /// A frame waiting to be submitted, and when it arrived.
    pending: Option<(FrameMessage, Instant)>,
    dropped_here: u64,
    /// A poll for reports is scheduled.
    poll_scheduled: bool,
    /// Playback was stopped by an error (not by the user): a device rebuild resumes it.
    stopped_by_error: bool,
    // The mode.
    mode: FusionMode,
    device_rebuilds: u32,
    /// Connecting to the first fused frame.
    connected_at: Option<Instant>,
    first_frame_ms: Option<f64>,
    /// Pipelines compiled when the first frame was fused (those it ran, in the browser).
    first_frame_kernels: Option<usize>,
    /// When the page's loop started.
    started_at: Instant,
    /// Milestones up to the first fused frame (connected, hello, frame received,
    /// decoded, submitted, fused), milliseconds after the page started: where the time to the
    /// first frame goes.
    startup_ms: Vec<(&'static str, f64)>,
}

async fn run() -> Result<(), String> {
    let has_webgpu = web_sys::window().is_some_and(|w| js_sys::Reflect::has(&w.navigator(), &"gpu".into()).unwrap_or(false));
    if !has_webgpu {
        return Err("this browser has no WebGPU (navigator.gpu is missing). Use Chrome or Edge 113+ (on Linux: chrome://flags/#enable-unsafe-webgpu, or start Chromium with --enable-unsafe-webgpu), Firefox 141+ on Windows, or Safari 26+. The native `webfusion reconstruct` runs the same pipeline without a browser.".into());
    }
    ui::set_text("status", "requesting a WebGPU adapter…");
    let started_at = Instant::now();
    let gpu = new_gpu().await?;
    // Browsers keep the adapter's name to themselves; say what is known.
    let adapter = if gpu.adapter_info.name.is_empty() { format!("browser WebGPU, {:?} adapter", gpu.adapter_info.device_type) } else { gpu.adapter_summary() };
    ui::set_text("adapter", &adapter);
    let query = ui::query();
    let (settings, mut settings_warnings) = fill_settings_form(&query);
    let bridge = query.get("bridge").cloned().or_else(|| ui::local_get("webfusion.bridge")).unwrap_or_else(ui::own_bridge_url);
    let token = query.get("token").cloned().or_else(|| ui::local_get("webfusion.token")).unwrap_or_default();
    ui::set_value("bridge-url", &bridge);
    ui::set_value("bridge-token", &token);
    let every_frame = query.get("every").is_none_or(|v| v != "0");
    ui::set_value("every-frame", if every_frame { "1" } else { "" });
    let rate = match query.get("rate").map(|r| parse_rate(r)) {
        None => DEFAULT_RATE,
        Some(Ok(rate)) => rate,
        Some(Err(message)) => {
            settings_warnings.push(format!("?rate ignored ({message}); using {DEFAULT_RATE}"));
            DEFAULT_RATE
        }
    };
    ui::set_value("rate", &rate.to_string());

    let inbox = Rc::new(Inbox::default());
    ui::bind_controls(&inbox);
    let overlay: web_sys::HtmlCanvasElement = ui::element("view-free-overlay")?;
    ui::bind_gestures(&inbox, &overlay);
    let mode = FusionMode::new(settings.config.clone(), settings.features, settings.planes);
    install_hooks(&inbox, &mode);
    let mut app = App {
        inbox: Rc::clone(&inbox),
        gpu,
        adapter,
        settings,
        settings_warnings,
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
        dropped_here: 0,
        poll_scheduled: false,
        stopped_by_error: false,
        mode,
        device_rebuilds: 0,
        connected_at: None,
        first_frame_ms: None,
        first_frame_kernels: None,
        started_at,
        startup_ms: Vec::new(),
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
        // A lost device first: nothing below may touch it (or the canvases configured on it).
        if app.gpu.check_lost().is_err() {
            app.rebuild_after_device_loss().await;
        }
        if let Some((frame, arrived)) = app.pending.take()
            && let Err(message) = app.submit(frame, arrived).await
        {
            app.fail(&message);
        }
        app.collect_reports();
        app.send_bridge_requests();
        if let Err(message) = app.mode.draw_free_view(&app.gpu) {
            app.fail(&message);
        }
        let errors = app.gpu.take_errors();
        if !errors.is_empty() {
            app.fail(&format!("WebGPU reported errors: {}", errors.join("; ")));
        }
        app.schedule_poll();
        app.publish();
    }
}

/// The browser's WebGPU device, with every pipeline compiled.
async fn new_gpu() -> Result<Gpu, String> {
    Gpu::new(&GpuOptions::default())
        .await
        .map_err(|e| format!("this browser has WebGPU but gave no usable adapter ({e}). On Linux, Chrome/Chromium needs --enable-unsafe-webgpu (and --ignore-gpu-blocklist on blocklisted GPUs); check chrome://gpu."))
}

/// `window.webfusion.trajectory_tum()` (the trajectory so far, TUM text, built as reports
/// arrive and copied only when asked for) and `window.webfusion.lose_device()` (test hook).
fn install_hooks(inbox: &Rc<Inbox>, mode: &FusionMode) {
    let hook = hook_object();
    let text = mode.trajectory_tum();
    let trajectory = Closure::<dyn Fn() -> JsValue>::new(move || JsValue::from_str(&text.borrow()));
    js_sys::Reflect::set(&hook, &"trajectory_tum".into(), trajectory.as_ref()).ok();
    trajectory.forget();
    let inbox = Rc::clone(inbox);
    let lose = Closure::<dyn Fn()>::new(move || inbox.push(Event::Ui(Ui::LoseDevice)));
    js_sys::Reflect::set(&hook, &"lose_device".into(), lose.as_ref()).ok();
    lose.forget();
}

impl App {
    fn fail(&mut self, message: &str) {
        self.last_error = Some(message.to_owned());
        // A failure caused by a lost device is followed by the rebuild, which resumes.
        self.stopped_by_error |= self.playing;
        self.playing = false;
        web_sys::console::error_1(&message.into());
    }

    fn send(&self, control: Control) {
        if let Some(link) = &self.link {
            link.send(&Message::Control(control).encode());
        }
    }

    /// Sends the render request due (the virtual sensor's unknown mask), if the link is open.
    fn send_bridge_requests(&mut self) {
        if let Some(link) = &self.link
            && let Some(request) = self.mode.bridge_request()
            && !link.send(&Message::RenderRequest(request).encode())
        {
            // Not sent (the socket is not open): no reply will come.
            self.mode.bridge_lost();
        }
    }

    fn is_live(&self) -> bool {
        self.source.as_ref().is_some_and(|s| s.frame_count.is_none())
    }

    async fn handle(&mut self, event: Event) {
        match event {
            Event::Opened { generation } if generation == self.generation => {
                self.link_state = LinkState::Connected;
                if self.connected_at.is_none() {
                    self.connected_at = Some(Instant::now());
                    self.milestone("connected");
                }
            }
            Event::Received { generation, bytes } if generation == self.generation => match Message::decode(&bytes) {
                Ok(Message::Hello(hello)) => {
                    self.milestone("hello");
                    self.on_hello(hello);
                }
                Ok(Message::Status(status)) => {
                    if status.state == PlaybackState::Ended {
                        self.playing = false;
                    }
                    self.server = Some(status);
                }
                Ok(Message::Frame(frame)) => {
                    self.milestone("frame received");
                    if self.pending.replace((frame, Instant::now())).is_some() {
                        self.dropped_here += 1;
                    }
                }
                Ok(Message::Error { code, message }) => self.last_error = Some(format!("bridge: {message} ({code:?})")),
                Ok(Message::Control(_) | Message::RenderRequest(_)) => self.last_error = Some("the bridge sent a client's message".to_owned()),
                Ok(Message::RenderReply { request_id, outcome }) => {
                    if let Err(message) = self.mode.on_bridge_reply(request_id, outcome) {
                        self.last_error = Some(format!("virtual sensor: {message}"));
                    }
                }
                Err(e) => self.last_error = Some(format!("undecodable message from the bridge: {e}")),
            },
            Event::Closed { generation, code, reason } if generation == self.generation => {
                self.link = None;
                self.mode.bridge_lost();
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
            Event::Poll => self.poll_scheduled = false,
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
        let info = SourceInfo { name: hello.source_name, frame_count: hello.frame_count, calibration: hello.calibration, has_ground_truth: hello.has_ground_truth, depth_noise: hello.depth_noise };
        if self.source.as_ref() != Some(&info) {
            self.source = Some(info);
            self.mode.drop_pipeline(false);
            self.pending = None;
        } else {
            // A reconnect to the same log: carry on after the last frame submitted.
            self.resume_after(self.mode.last_submitted());
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

    /// Seeks the bridge to the frame after `last` (a recorded source), so playback carries on.
    fn resume_after(&self, last: Option<u64>) {
        if let (Some(last), Some(count)) = (last, self.source.as_ref().and_then(|s| s.frame_count))
            && last + 1 < count
        {
            self.send(Control::Seek(last + 1));
        }
    }

    /// Asks for frames: one at a time in every-frame mode (lossless, paced by this page), or
    /// streamed at the source's rate in real-time mode.
    fn start_playing(&mut self) {
        self.playing = true;
        self.stopped_by_error = false;
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
        let next = self.mode.last_submitted().map_or(0, |i| i + 1);
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
                let count = self.source.as_ref().and_then(|s| s.frame_count);
                if self.server.as_ref().is_some_and(|s| s.state == PlaybackState::Ended) || self.mode.last_submitted().is_some_and(|i| Some(i + 1) == count) {
                    // Play after the end starts a new pass.
                    self.reset_run();
                    self.send(Control::Seek(0));
                }
                self.start_playing();
            }
            Ui::Playback(Control::Pause) => {
                self.playing = false;
                self.stopped_by_error = false;
                self.send(Control::Pause);
            }
            Ui::Playback(Control::Step) => {
                self.playing = false;
                self.send(Control::Delivery(Delivery::Lossless));
                self.send(Control::Step);
            }
            Ui::OdometryStage => {
                let count = self.source.as_ref().and_then(|s| s.frame_count);
                let next = self.mode.last_submitted().map_or(0, |i| i + 1);
                // Past the last stage: the next frame, one at a time, if the log has one (a
                // step past the end would start a new pass).
                if self.mode.next_odometry_stage() && count.is_none_or(|n| next < n) {
                    self.playing = false;
                    self.send(Control::Pause);
                    self.send(Control::Delivery(Delivery::Lossless));
                    self.send(Control::Step);
                }
            }
            Ui::Playback(Control::Seek(index)) => {
                // A jump in time is a new reconstruction from that frame.
                self.reset_run();
                self.send(Control::Seek(index));
                if self.playing {
                    self.start_playing();
                }
            }
            Ui::Playback(Control::Rate(rate)) => self.set_rate(&rate.to_string()),
            Ui::Rate(text) => self.set_rate(&text),
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
                    self.mode.set_config(settings.config.clone(), settings.features, settings.planes);
                    self.settings = settings;
                    self.settings_warnings.clear();
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
            Ui::ExportScene => {
                let scene = self.mode.scene_glb(&self.gpu).await;
                if let Err(message) = scene.and_then(|bytes| ui::download("scene.glb", &bytes, "model/gltf-binary").map_err(|e| js_text(&e))) {
                    self.last_error = Some(format!("scene export: {message}"));
                }
            }
            Ui::ExportTrajectory => {
                let text = self.mode.trajectory_tum();
                if let Err(e) = ui::download("trajectory.txt", text.borrow().as_bytes(), "text/plain") {
                    self.last_error = Some(format!("trajectory export: {}", js_text(&e)));
                }
            }
            Ui::Orbit(dx, dy) => {
                if let Some(orbit) = self.mode.orbit_mut() {
                    orbit.orbit(dx, dy);
                }
            }
            Ui::Pan(dx, dy) => {
                if let Some(orbit) = self.mode.orbit_mut() {
                    orbit.pan(dx, dy, FREE_VIEW.fx_px);
                }
            }
            Ui::Zoom(factor) => {
                if let Some(orbit) = self.mode.orbit_mut() {
                    orbit.zoom(factor);
                }
            }
            Ui::ViewColour(on) => self.mode.set_free_colour(on),
            Ui::ViewPlanes(on) => self.mode.set_free_planes(on),
            Ui::SimRender => match crate::sim::parse_pose(&ui::value("sim-pose")) {
                Ok(pose) => self.render_sensor(SensorPose::At(pose)),
                Err(message) => self.last_error = Some(format!("virtual sensor pose: {message}")),
            },
            Ui::SimFromView => self.render_sensor(SensorPose::FreeView),
            Ui::SimAtFrame => self.render_sensor(SensorPose::LastFrame),
            Ui::SimAtTrajectory => match ui::value("sim-trajectory").trim().parse::<usize>() {
                Ok(i) => self.render_sensor(SensorPose::Trajectory(i)),
                Err(_) => self.last_error = Some(format!("virtual sensor: trajectory pose {:?} is not a whole number", ui::value("sim-trajectory"))),
            },
            Ui::SimFollow(on) => self.mode.set_sensor_follow(on),
            Ui::SimNoise => match sensor_noise_from_form() {
                Ok(seed) => {
                    self.mode.set_sensor_noise(seed);
                    self.render_sensor(SensorPose::Again);
                }
                Err(message) => self.last_error = Some(format!("virtual sensor: {message}")),
            },
            Ui::SimDownload => {
                if let Err(message) = self.mode.download_sensor() {
                    self.last_error = Some(format!("simulated depth download: {message}"));
                }
            }
            Ui::OpenMapFile => match ui::chosen_file("open-map").await {
                Ok(Some((name, bytes))) => self.open_map(&bytes, &name, false),
                Ok(None) => {}
                Err(message) => self.last_error = Some(format!("opening the map: {message}")),
            },
            Ui::MapFromBridge => match map_url(&ui::value("bridge-url"), &ui::value("bridge-token")) {
                Ok(url) => match ui::fetch_bytes(&url).await {
                    Ok(bytes) => self.open_map(&bytes, "the bridge's map", true),
                    Err(message) => self.last_error = Some(format!("the bridge's map: {message}")),
                },
                Err(message) => self.last_error = Some(format!("the bridge's map: {message}")),
            },
            Ui::CloseMap => {
                self.mode.close_map();
                self.pending = None;
            }
            Ui::LoseDevice => self.gpu.device.destroy(),
        }
    }

    fn render_sensor(&mut self, at: SensorPose) {
        if let Err(message) = self.mode.render_sensor(&self.gpu, at) {
            self.last_error = Some(message);
        }
    }

    /// Opens a saved map's bytes: playback pauses, the fused run is dropped and the free view
    /// and the virtual sensor show the map.
    fn open_map(&mut self, bytes: &[u8], name: &str, from_bridge: bool) {
        // The map memory setting bounds an opened map's GPU pool too: a larger map is shown
        // through a window (`map::window`).
        match OpenedMap::load(&self.gpu, bytes, name, from_bridge, self.settings.config.tsdf.pool_blocks).and_then(|map| self.mode.open_map(&self.gpu, map)) {
            Ok(()) => {
                if self.playing {
                    self.playing = false;
                    self.send(Control::Pause);
                }
                self.pending = None;
                self.last_error = None;
            }
            Err(message) => self.last_error = Some(format!("opening the map: {message}")),
        }
    }

    /// Takes a rate typed into the page (or given by a control): only a rate the bridge
    /// accepts is sent; anything else is named in the status and the input shows the rate
    /// in force again.
    fn set_rate(&mut self, text: &str) {
        match parse_rate(text) {
            Ok(rate) => {
                self.rate = rate;
                if !self.every_frame {
                    self.send(Control::Rate(rate));
                }
            }
            Err(message) => {
                self.last_error = Some(format!("{message}; keeping {}", self.rate));
                ui::set_value("rate", &self.rate.to_string());
            }
        }
    }

    /// Forgets the trajectory and statistics; the next frame starts a new reconstruction.
    fn reset_run(&mut self) {
        self.mode.reset(&self.gpu);
        self.pending = None;
    }

    /// Decodes a frame and hands it to the mode (which submits it without waiting); in
    /// every-frame mode the next frame is requested at once.
    async fn submit(&mut self, message: FrameMessage, arrived: Instant) -> Result<(), String> {
        let Some(source) = self.source.clone() else { return Err("a frame arrived before the bridge's hello".to_owned()) };
        let t0 = Instant::now();
        let frame = message.decode_images(&source.calibration).map_err(|e| format!("frame {}: {e}", message.index))?;
        let decode_ms = t0.elapsed().as_secs_f64() * 1e3;
        if self.mode.last_submitted().is_some_and(|last| message.index <= last) {
            // The log looped (or was sought backwards): a new pass.
            self.reset_run();
        }
        self.milestone("decoded");
        // Until the first frame is fused its pipelines are compiling in the GPU process, and
        // drawing into the views' canvases would block this thread until then (seen: 3 s on
        // SwiftShader; the page freezes) and compile the view kernels ahead of the frame's:
        // the frames submitted meanwhile are fused, their views skipped.
        let draw_views = self.first_frame_ms.is_some();
        let received = Received { ground_truth: message.ground_truth, arrived, decode_ms };
        self.mode.submit(&self.gpu, source.calibration, source.depth_noise, &frame, received, draw_views).await?;
        self.milestone("submitted");
        if self.playing && self.every_frame && !self.is_live() {
            self.request_next();
        }
        Ok(())
    }

    /// Notes `what` happening now, until the first frame is fused.
    fn milestone(&mut self, what: &'static str) {
        if self.first_frame_ms.is_none() && !self.startup_ms.iter().any(|(w, _)| *w == what) {
            self.startup_ms.push((what, self.started_at.elapsed().as_secs_f64() * 1e3));
        }
    }

    /// Takes the reports that came back and notes the first fused frame.
    fn collect_reports(&mut self) {
        match self.mode.poll(&self.gpu) {
            Ok(true) => {
                if self.first_frame_ms.is_none()
                    && let Some(at) = self.connected_at
                {
                    self.milestone("fused");
                    self.first_frame_ms = Some(at.elapsed().as_secs_f64() * 1e3);
                    self.first_frame_kernels = Some(self.gpu.kernels.compiled_count());
                }
                // The pipelines the first frame did not run (tracking, matching, planes,
                // meshing) are compiled once it is fused: before, their compilation would hold
                // up its report.
                if !self.gpu.kernels.all_compiled() {
                    self.gpu.kernels.compile_deferred();
                }
            }
            Ok(false) => {}
            Err(message) => self.fail(&message),
        }
    }

    /// While reports are due, wakes the loop again shortly to collect them; while the free
    /// view waits to follow the model, wakes it when that is due.
    fn schedule_poll(&mut self) {
        if self.poll_scheduled {
            return;
        }
        let delay_ms = match (self.mode.awaiting_gpu(), self.mode.free_view_due_in_ms()) {
            (true, _) => POLL_MS,
            (false, Some(ms)) => (ms.ceil() as i32).max(1),
            (false, None) => return,
        };
        self.poll_scheduled = true;
        push_later(&self.inbox, delay_ms, Event::Poll);
    }

    /// The device is gone (driver reset, GPU process crash): a new device, the pipeline
    /// rebuilt on it, and playback resumed after the last frame fused, as a reconnect does.
    /// The model starts again from that frame; the trajectory carries on from its last pose.
    async fn rebuild_after_device_loss(&mut self) {
        let reason = self.gpu.check_lost().err().map(|e| e.to_string()).unwrap_or_default();
        web_sys::console::warn_1(&format!("rebuilding after {reason}").into());
        self.gpu.take_errors();
        match new_gpu().await {
            Ok(gpu) => self.gpu = gpu,
            Err(message) => {
                self.fail(&format!("{reason}; no new device: {message}"));
                return;
            }
        }
        self.device_rebuilds += 1;
        let last = self.mode.last_reported();
        self.mode.drop_pipeline(true);
        self.mode.rewind_to(last);
        self.pending = None;
        self.last_error = None;
        self.resume_after(last);
        if self.playing || std::mem::take(&mut self.stopped_by_error) {
            self.start_playing();
        }
    }

    async fn export_mesh(&mut self, glb: bool) -> Result<(), String> {
        let Some(fusion) = self.mode.fusion_mut() else { return Err("nothing fused yet".to_owned()) };
        // Every block: a swapping map's on the host (wasm memory) too.
        let mesh = fusion.mapper_mut().extract_mesh(&self.gpu).await.map_err(|e| e.to_string())?;
        let mut bytes = Vec::new();
        if glb { webfusion_core::mesh::write_glb(&mesh, &mut bytes) } else { webfusion_core::mesh::write_ply(&mesh, &mut bytes) }.map_err(|e| e.to_string())?;
        let (name, mime) = if glb { ("mesh.glb", "model/gltf-binary") } else { ("mesh.ply", "application/octet-stream") };
        ui::download(name, &bytes, mime).map_err(|e| js_text(&e))
    }

    /// Updates the status panel and `window.webfusion.status`: one typed struct, serialised
    /// once.
    fn publish(&mut self) {
        let fusion = self.mode.status();
        let frames_total = self.source.as_ref().and_then(|s| s.frame_count);
        let state = match (self.link_state, self.playing, &self.server) {
            _ if self.last_error.is_some() => "error",
            (LinkState::Disconnected, ..) => "disconnected",
            (LinkState::Connecting, ..) => "connecting",
            (LinkState::Retrying, ..) => "reconnecting",
            (LinkState::Connected, true, _) => "running",
            _ if fusion.frames_in_flight > 0 => "running",
            (LinkState::Connected, false, Some(s)) if s.state == PlaybackState::Ended || frames_total.is_some_and(|n| fusion.frames_done as u64 == n && n > 0) => "ended",
            (LinkState::Connected, false, _) => "paused",
        };
        let message = self.last_error.clone().unwrap_or_else(|| self.settings_warnings.join("; "));
        let status = Status {
            state,
            link: self.link_state.name(),
            message,
            source: self.source.as_ref().map(|s| s.name.clone()),
            frames_total,
            adapter: self.adapter.clone(),
            frames_dropped: self.dropped_here + self.server.as_ref().map_or(0, |s| s.frames_dropped),
            frames_skipped: self.server.as_ref().map_or(0, |s| s.frames_skipped),
            reconnects: self.reconnects,
            device_rebuilds: self.device_rebuilds,
            time_to_first_frame_ms: self.first_frame_ms,
            first_frame_kernels: self.first_frame_kernels.map(|n| [n, webfusion_core::kernels::Kernels::COUNT]),
            startup_ms: self.startup_ms.iter().map(|(w, ms)| ((*w).to_owned(), *ms)).collect(),
            fusion,
            sensor: self.mode.sensor_status(),
        };
        match serde_json::to_string(&status) {
            Ok(json) => publish_json(&json),
            Err(e) => web_sys::console::error_1(&format!("status: {e}").into()),
        }
        ui::set_text("link-state", status.link);
        ui::set_text("status", &status_text(&status, self.source.as_ref().is_some_and(|s| s.has_ground_truth)));
        if let (Ok(seek), Some(index)) = (ui::element::<web_sys::HtmlInputElement>("seek"), status.fusion.last_index) {
            seek.set_value(&index.to_string());
        }
    }
}

impl LinkState {
    fn name(self) -> &'static str {
        match self {
            LinkState::Disconnected => "disconnected",
            LinkState::Connecting => "connecting",
            LinkState::Connected => "connected",
            LinkState::Retrying => "retrying",
        }
    }
}

/// The status panel's text.
fn status_text(s: &Status, has_ground_truth: bool) -> String {
    let f = &s.fusion;
    let m = &f.stages_ms;
    let mut lines = vec![
        format!(
            "{} · {} · frame {}{} · {:.1} fps · tracking {} (lost {}, recovered {})",
            s.state,
            s.source.as_deref().unwrap_or("no source"),
            f.frames_done,
            s.frames_total.map(|n| format!("/{n}")).unwrap_or_default(),
            f.fps,
            f.tracking,
            f.lost_frames,
            f.recovered_frames
        ),
        format!(
            "median ms ({}): decode {:.1} · preprocess {:.1} · features {:.1} · track {:.1} · integrate {:.1} · raycast {:.1} · views {:.1}",
            if f.gpu_timestamps { "GPU timestamps" } else { "no GPU timestamps: GPU stages unknown" },
            m.decode,
            m.preprocess,
            m.features,
            m.track,
            m.integrate,
            m.raycast,
            m.views
        ),
    ];
    let ate = match f.ate_rmse_m {
        Some(rmse) => format!("ATE {:.2} cm over {} poses", rmse * 100.0, f.ate_pairs),
        None if has_ground_truth => "ATE: waiting for 3 poses".to_owned(),
        None => "ATE: the source has no ground truth".to_owned(),
    };
    let v = &f.volume;
    let pressure = if v.swap_margin_percent > 0 && v.swap_margin_percent < 100 { format!(", swap margins at {} % (the pool is tight)", v.swap_margin_percent) } else { String::new() };
    let on_host = if v.blocks_on_host > 0 { format!(", {} swapped out to memory ({:.0} MiB){pressure}", v.blocks_on_host, v.host_bytes as f64 / 1048576.0) } else { String::new() };
    let map = if v.pool_blocks > 0 { format!("sparse map, {} of {} blocks of 8³ on the GPU{on_host}{}", v.blocks_used, v.pool_blocks, if v.full { " (FULL: new surfaces are not fused; raise the voxel size or the map memory)" } else { "" }) } else { format!("volume {}³", v.dims_voxels[0]) };
    lines.push(format!(
        "{ate} · latency {} · in flight {} · dropped {} · reconnects {} · {map} × {:.1} mm = {:.0} MiB",
        f.latency_ms.map_or_else(|| "-".to_owned(), |ms| format!("{ms:.0} ms")),
        f.frames_in_flight,
        s.frames_dropped,
        s.reconnects,
        v.voxel_size_m * 1000.0,
        v.memory_bytes as f64 / (1 << 20) as f64,
    ));
    lines.push(match &f.features {
        Some(x) => format!(
            "feature odometry: {} guesses · {} relocalisations ({} confirmed by ICP) · {} withheld after gaps · {} keyframes · {:.0} ms/frame with tracking",
            x.guesses, x.relocalisations, x.relocalisations_confirmed, x.withheld, x.keyframes, x.median_ms
        ),
        None => "feature odometry off".to_owned(),
    });
    lines.push(match &f.planes {
        Some(p) => format!("planes: {} {} {} ({} curved surfaces rejected) · {:.0} ms/frame", p.count, p.source.seen_in(), p.frame, p.curved_rejected, p.median_ms),
        None => "plane segmentation off".to_owned(),
    });
    if let Some(line) = s.sensor.line() {
        lines.push(line);
    }
    if s.frames_skipped > 0 {
        lines.push(format!("⚠ the bridge skipped {} damaged frame(s) of the source", s.frames_skipped));
    }
    if !s.message.is_empty() {
        lines.push(format!("⚠ {}", s.message));
    }
    lines.join("\n")
}

/// The noise setting of the virtual sensor's form: the seed, or `None` for exact depth.
fn sensor_noise_from_form() -> Result<Option<u32>, String> {
    if ui::value("sim-noise").is_empty() {
        return Ok(None);
    }
    let text = ui::value("sim-seed");
    text.trim().parse::<u32>().map(Some).map_err(|_| format!("the noise seed {text:?} is not a whole number in 0..=4294967295"))
}

/// Where a bridge at WebSocket URL `bridge` offers its map (`serve --map`): the same host,
/// over HTTP(S), at `/map.wfm`, with the token.
fn map_url(bridge: &str, token: &str) -> Result<String, String> {
    let url = web_sys::Url::new(bridge).map_err(|_| format!("{bridge:?} is not a URL"))?;
    let scheme = match url.protocol().as_str() {
        "ws:" | "http:" => "http:",
        "wss:" | "https:" => "https:",
        other => return Err(format!("{bridge:?}: a bridge URL is ws:// or wss://, not {other}")),
    };
    url.set_protocol(scheme);
    url.set_pathname("/map.wfm");
    url.set_search("");
    if !token.is_empty() {
        url.search_params().set("token", token);
    }
    Ok(url.href())
}

/// The `window.webfusion` object (created on first use).
fn hook_object() -> JsValue {
    let Some(window) = web_sys::window() else { return JsValue::UNDEFINED };
    js_sys::Reflect::get(&window, &"webfusion".into()).ok().filter(JsValue::is_object).unwrap_or_else(|| {
        let hook: JsValue = js_sys::Object::new().into();
        js_sys::Reflect::set(&window, &"webfusion".into(), &hook).ok();
        hook
    })
}

/// Publishes `window.webfusion.status` from its JSON.
fn publish_json(status_json: &str) {
    let hook = hook_object();
    if let Ok(value) = js_sys::JSON::parse(status_json) {
        js_sys::Reflect::set(&hook, &"status".into(), &value).ok();
    }
}
