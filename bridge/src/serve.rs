// SPDX-License-Identifier: MIT
//! `webfusion serve`: the web app's static files and the frame WebSocket on one port.
//!
//! Every WebSocket client gets its own session: its own reader of the source, its own
//! position, rate, loop flag and delivery mode, and its own bounded outgoing queue
//! ([`OutQueue`]). In lossless delivery the session waits for the client (every frame, in
//! order); in live delivery the queue keeps only the newest frames and counts what it drops.
//! A malformed message closes only the client that sent it, with the reason.
//!
//! A live camera (`--source openni2[:<uri>]`) is read by one capture thread that encodes each
//! frame once and broadcasts it ([`LiveHub`]); every client subscribes, plays or pauses on its
//! own, and a client that falls behind the camera loses the oldest frames, counted as drops.
//!
//! With `--map`, any client may also send render requests: the depth a virtual Kinect sees at
//! a pose in the saved map ([`render`]), answered in the same session between frames.

use std::collections::{HashMap, VecDeque};
use std::net::SocketAddr;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context as _;
use axum::Router;
use axum::body::Bytes;
use axum::extract::ws::{CloseFrame, Message as WsMessage, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::http::{HeaderMap, StatusCode, Uri, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use futures_util::{SinkExt as _, StreamExt as _};
use tokio::sync::{Notify, broadcast};
use tokio::time::Instant;
use webfusion_core::codec::{ColorCodec, DepthCodec};
use webfusion_core::protocol::{
    Control, Delivery, ErrorCode, FrameMessage, Hello, MAX_CLIENT_MESSAGE_BYTES, Message, PlaybackState, RenderFailure, RenderOutcome, RenderRequest, Status, WireColor, render_request_id,
};
use webfusion_core::recording::RecordingReader;
use webfusion_core::source::{DepthNoise, FrameSource, LiveSource, TimedPose, is_recording, open_recording};
use webfusion_core::{GpuOptions, RgbdCalibration, Se3};

use crate::calib::CalibrationArgs;

mod render;
use render::Renderer;

/// Largest |t_gt − t_depth| for a ground-truth pose to travel with a frame (TUM convention).
const GROUND_TRUTH_MAX_DIFFERENCE_NS: i64 = 20_000_000;

/// Colour encoding on the wire.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ColorArg {
    /// A recording's own colour bytes unchanged; JPEG for other sources.
    Auto,
    /// Baseline JPEG (lossy, ~15x smaller than raw).
    Jpeg,
    /// PNG (lossless, slow to encode).
    Png,
    /// Packed RGB8 (lossless, largest).
    Raw,
}

#[derive(clap::Args)]
pub(crate) struct ServeArgs {
    /// TUM RGB-D directory, `.wfr` recording, `.oni` recording, or live camera: `openni2`
    /// (the first) or `openni2:<uri>` (see `webfusion devices`); the last two need feature `openni2`.
    #[arg(long, default_value = crate::DEFAULT_SAMPLE)]
    source: PathBuf,
    /// Address to listen on. Anything but loopback needs --token or --insecure. Port 0 picks a free port.
    #[arg(long, default_value = "127.0.0.1:8080")]
    bind: SocketAddr,
    /// Secret that WebSocket clients must present as `?token=...`.
    #[arg(long, env = "WEBFUSION_TOKEN")]
    token: Option<String>,
    /// Allow binding to a non-loopback address without a token (anyone who can reach it gets the frames).
    #[arg(long)]
    insecure: bool,
    /// Extra allowed `Origin` for WebSocket clients (besides the page's own origin), e.g. `https://example.org`.
    #[arg(long)]
    allow_origin: Vec<String>,
    /// Directory of the built web app (`trunk build` output).
    #[arg(long, default_value = "dist")]
    web_dir: PathBuf,
    /// Colour encoding on the wire.
    #[arg(long, value_enum, default_value_t = ColorArg::Auto)]
    color: ColorArg,
    /// JPEG quality (1..=100) when colour is re-encoded as JPEG.
    #[arg(long, default_value_t = 90)]
    jpeg_quality: u8,
    /// Frames a live-delivery client may have queued before the oldest is dropped.
    #[arg(long, default_value_t = 2)]
    live_queue: usize,
    /// Skip damaged frames of a recording (each client's status counts them) instead of ending
    /// the session at the first one, and serve the intact blocks of a damaged --map.
    #[arg(long)]
    skip_corrupt: bool,
    /// A saved map (`reconstruct --save-map`) to answer render requests from: any WebSocket
    /// client may ask what a virtual Kinect sees at a pose (`scripts/render_client.py`).
    #[arg(long)]
    map: Option<PathBuf>,
    /// The map's occupancy grid (`export-occupancy`'s G.json): render requests may then ask
    /// which pixels looked through never-observed space (the reply's unknown mask).
    #[arg(long, requires = "map")]
    occupancy: Option<PathBuf>,
    #[command(flatten)]
    calibration: CalibrationArgs,
}

/// What every session shares: how to open the source and the server's policies.
struct Shared {
    source_path: PathBuf,
    calibration_override: Option<RgbdCalibration>,
    token: Option<String>,
    allowed_origins: Vec<String>,
    web_dir: PathBuf,
    color: ColorArg,
    jpeg_quality: u8,
    live_queue: usize,
    skip_corrupt: bool,
    /// The capture of a live camera; `None` for logs.
    live: Option<LiveHub>,
    /// The virtual sensor in the served map (`--map`).
    renderer: Option<Renderer>,
    /// The served map's file (`--map`), offered to pages at `/map.wfm`.
    map_path: Option<PathBuf>,
}

/// Frames a client may fall behind a live camera before it loses the oldest.
const LIVE_BROADCAST_FRAMES: usize = 4;

/// One live camera shared by every client: a capture thread encodes each frame once and
/// broadcasts it.
struct LiveHub {
    name: String,
    calibration: RgbdCalibration,
    frames: broadcast::Sender<LiveItem>,
    /// Frames captured so far.
    captured: Arc<AtomicU64>,
    /// Why the capture stopped, once it has.
    failure: Arc<Mutex<Option<String>>>,
}

#[derive(Clone)]
enum LiveItem {
    /// An encoded frame message.
    Frame(Bytes),
    /// The camera stopped; the reason.
    Failed(Arc<str>),
}

impl LiveHub {
    /// Starts the capture thread of `live`.
    fn start(mut live: Box<dyn LiveSource>, color: ColorArg, jpeg_quality: u8) -> Self {
        let (frames, _) = broadcast::channel(LIVE_BROADCAST_FRAMES);
        let captured = Arc::new(AtomicU64::new(0));
        let failure = Arc::new(Mutex::new(None));
        let hub = Self { name: live.name(), calibration: live.calibration(), frames: frames.clone(), captured: Arc::clone(&captured), failure: Arc::clone(&failure) };
        std::thread::Builder::new()
            .name("webfusion-capture".to_owned())
            .spawn(move || {
                loop {
                    // The camera's own frame number is the sequence: gaps at a client are its drops.
                    let encoded = live.next_frame().and_then(|frame| encode_frame(&frame, frame.index, color, jpeg_quality)).map(|message| Message::Frame(message).encode());
                    match encoded {
                        Ok(bytes) => {
                            captured.fetch_add(1, Ordering::Relaxed);
                            // No subscriber is not an error: frames are for whoever listens.
                            let _ = frames.send(LiveItem::Frame(bytes.into()));
                        }
                        Err(e) => {
                            let reason: Arc<str> = format!("live camera stopped: {e}").into();
                            eprintln!("{reason}");
                            *failure.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Some(reason.to_string());
                            let _ = frames.send(LiveItem::Failed(reason));
                            return;
                        }
                    }
                }
            })
            .expect("spawning the capture thread");
        hub
    }
}

pub(crate) fn run(options: &GpuOptions, args: ServeArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.bind.ip().is_loopback() || args.token.is_some() || args.insecure,
        "refusing to serve on {} without --token: anyone on the network could read the frames (pass --token SECRET, or --insecure if you mean it)",
        args.bind
    );
    anyhow::ensure!((1..=100).contains(&args.jpeg_quality), "--jpeg-quality must be in 1..=100");
    anyhow::ensure!(args.live_queue >= 1, "--live-queue must be at least 1");
    let calibration_override = args.calibration.resolve()?;
    let live = match crate::live_spec(&args.source) {
        Some(uri) => {
            let hub = LiveHub::start(crate::open_live(uri, calibration_override)?, args.color, args.jpeg_quality);
            eprintln!("source: live camera {} ({}x{})", hub.name, hub.calibration.intrinsics.width_px, hub.calibration.intrinsics.height_px);
            Some(hub)
        }
        None => {
            // Open once up front so a bad source fails here, not at the first client.
            let probe = SessionSource::open(&args.source, calibration_override)?;
            eprintln!("source: {} ({} frames, {}x{})", probe.name(), probe.frame_count(), probe.calibration().intrinsics.width_px, probe.calibration().intrinsics.height_px);
            None
        }
    };
    let renderer = match &args.map {
        Some(path) => {
            let (renderer, summary) = Renderer::start(options.clone(), path, args.occupancy.as_deref(), args.skip_corrupt)?;
            eprintln!("{summary}");
            Some(renderer)
        }
        None => None,
    };
    if !args.web_dir.join("index.html").is_file() {
        eprintln!("note: {} has no index.html; the WebSocket works but the page is not built (scripts/run.sh builds it)", args.web_dir.display());
    }
    let shared = Arc::new(Shared {
        source_path: args.source,
        calibration_override,
        token: args.token,
        allowed_origins: args.allow_origin,
        web_dir: args.web_dir,
        color: args.color,
        jpeg_quality: args.jpeg_quality,
        live_queue: args.live_queue,
        skip_corrupt: args.skip_corrupt,
        live,
        renderer,
        map_path: args.map,
    });
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build().context("starting the async runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(args.bind).await.with_context(|| format!("binding {}", args.bind))?;
        let addr = listener.local_addr()?;
        let token_query = shared.token.as_ref().map(|t| format!("?token={t}")).unwrap_or_default();
        // One line on stdout, flushed, that scripts and tests wait for.
        println!("webfusion serve: http://{addr}/ (frames: ws://{addr}/ws{token_query})");
        use std::io::Write as _;
        std::io::stdout().flush().ok();
        let app = Router::new().route("/ws", get(ws_handler)).route(MAP_ROUTE, get(map_handler)).fallback(get(static_handler)).with_state(shared);
        axum::serve(listener, app.into_make_service_with_connect_info::<SocketAddr>())
            .with_graceful_shutdown(async {
                tokio::signal::ctrl_c().await.ok();
            })
            .await
            .context("serving")
    })
}

/// Compares secrets in time independent of where they differ.
fn same_secret(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0_u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Browsers always send `Origin` on WebSocket upgrades; accept the page's own origin and the
/// allowed list. Native clients send none and are governed by the bind address and token.
fn origin_allowed(headers: &HeaderMap, allowed: &[String]) -> bool {
    let Some(origin) = headers.get(header::ORIGIN).and_then(|v| v.to_str().ok()) else {
        return true;
    };
    let host = headers.get(header::HOST).and_then(|v| v.to_str().ok()).unwrap_or("");
    origin == format!("http://{host}") || origin == format!("https://{host}") || allowed.iter().any(|a| a == origin)
}

/// The edge checks of the frames and the map: the token, then the `Origin`; the refusal, if
/// any.
fn refused(headers: &HeaderMap, query: &HashMap<String, String>, shared: &Shared) -> Option<Response> {
    if let Some(token) = &shared.token
        && !query.get("token").is_some_and(|given| same_secret(given, token))
    {
        return Some((StatusCode::UNAUTHORIZED, "missing or wrong ?token=").into_response());
    }
    if !origin_allowed(headers, &shared.allowed_origins) {
        return Some((StatusCode::FORBIDDEN, "Origin not allowed (use --allow-origin)").into_response());
    }
    None
}

async fn ws_handler(ws: WebSocketUpgrade, headers: HeaderMap, Query(query): Query<HashMap<String, String>>, State(shared): State<Arc<Shared>>) -> Response {
    if let Some(refusal) = refused(&headers, &query, &shared) {
        return refusal;
    }
    ws.max_message_size(MAX_CLIENT_MESSAGE_BYTES).max_frame_size(MAX_CLIENT_MESSAGE_BYTES).on_upgrade(move |socket| session(socket, shared))
}

/// Where a page fetches the served map (`--map`) to explore it and run its own virtual
/// sensor.
const MAP_ROUTE: &str = "/map.wfm";

/// The `--map` file as it is on disk now (the page parses it and keeps its intact blocks),
/// behind the same token as the frames; pages of an allowed origin may fetch it cross-origin.
async fn map_handler(headers: HeaderMap, Query(query): Query<HashMap<String, String>>, State(shared): State<Arc<Shared>>) -> Response {
    if let Some(refusal) = refused(&headers, &query, &shared) {
        return refusal;
    }
    let Some(path) = &shared.map_path else {
        return (StatusCode::NOT_FOUND, "this bridge serves no map (start it with serve --map FILE.wfm)").into_response();
    };
    let origin = headers.get(header::ORIGIN).cloned();
    match tokio::fs::read(path).await {
        Ok(bytes) => {
            let mut response = ([(header::CONTENT_TYPE, "application/octet-stream"), (header::CACHE_CONTROL, "no-cache")], bytes).into_response();
            if let Some(origin) = origin {
                response.headers_mut().insert(header::ACCESS_CONTROL_ALLOW_ORIGIN, origin);
            }
            response
        }
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("reading the map {}: {e}", path.display())).into_response(),
    }
}

async fn static_handler(uri: Uri, State(shared): State<Arc<Shared>>) -> Response {
    let path = uri.path().trim_start_matches('/');
    let path = if path.is_empty() { "index.html" } else { path };
    let relative = Path::new(path);
    if !relative.components().all(|c| matches!(c, Component::Normal(s) if !s.to_string_lossy().starts_with('.'))) {
        return (StatusCode::NOT_FOUND, "not found").into_response();
    }
    let file = shared.web_dir.join(relative);
    match tokio::fs::read(&file).await {
        Ok(bytes) => ([(header::CONTENT_TYPE, content_type(&file)), (header::CACHE_CONTROL, "no-cache")], bytes).into_response(),
        Err(_) if path == "index.html" => {
            (StatusCode::NOT_FOUND, format!("the web app is not built in {}: run scripts/run.sh (or trunk build)", shared.web_dir.display())).into_response()
        }
        Err(_) => (StatusCode::NOT_FOUND, "not found").into_response(),
    }
}

fn content_type(path: &Path) -> &'static str {
    match path.extension().and_then(|e| e.to_str()).unwrap_or("") {
        "html" => "text/html; charset=utf-8",
        "js" => "text/javascript",
        "wasm" => "application/wasm",
        "css" => "text/css",
        "json" => "application/json",
        "png" => "image/png",
        "svg" => "image/svg+xml",
        _ => "application/octet-stream",
    }
}

/// A client's own reader of the source.
enum SessionSource {
    /// Frames pass through in their recorded encoding.
    Recording(RecordingReader),
    /// Frames are decoded and re-encoded (TUM directories).
    Decoded(Box<dyn FrameSource>),
}

impl SessionSource {
    fn open(path: &Path, calibration_override: Option<RgbdCalibration>) -> anyhow::Result<Self> {
        if path.is_file() && is_recording(path)? {
            return Ok(Self::Recording(open_recording(path, calibration_override)?));
        }
        Ok(Self::Decoded(crate::open_with(path, calibration_override)?))
    }

    fn source(&self) -> &dyn FrameSource {
        match self {
            Self::Recording(reader) => reader,
            Self::Decoded(source) => source.as_ref(),
        }
    }

    fn name(&self) -> String {
        self.source().name()
    }
    fn frame_count(&self) -> usize {
        self.source().frame_count()
    }
    fn calibration(&self) -> RgbdCalibration {
        self.source().calibration()
    }

    /// Reads frame `index` and encodes it for the wire.
    fn frame_message(&mut self, index: usize, sequence: u64, color: ColorArg, jpeg_quality: u8) -> webfusion_core::Result<FrameMessage> {
        let calibration = self.calibration();
        let (w, h) = (calibration.intrinsics.width_px, calibration.intrinsics.height_px);
        let mut message = match self {
            Self::Recording(reader) => {
                let encoded = reader.read_encoded_frame(index)?;
                let recorded = reader.color_codec();
                let (wire_color, color_payload) = match color {
                    ColorArg::Auto => (WireColor::Coded(recorded), encoded.color_payload),
                    other => {
                        let image = recorded.decode(&encoded.color_payload, w, h)?;
                        encode_color(&image, other, jpeg_quality)?
                    }
                };
                FrameMessage {
                    sequence,
                    index: index as u64,
                    depth_timestamp_ns: encoded.depth_timestamp_ns,
                    color_timestamp_ns: encoded.color_timestamp_ns,
                    ground_truth: None,
                    depth_codec: reader.depth_codec(),
                    depth_payload: encoded.depth_payload,
                    color: wire_color,
                    color_payload,
                }
            }
            Self::Decoded(source) => FrameMessage { index: index as u64, ..encode_frame(&source.read_frame(index)?, sequence, color, jpeg_quality)? },
        };
        message.ground_truth = self.source().ground_truth().and_then(|poses| pose_near(poses, message.depth_timestamp_ns));
        Ok(message)
    }
}

/// A decoded frame as a frame message: RVL depth and `color` colour, no ground truth.
fn encode_frame(frame: &webfusion_core::RgbdFrame, sequence: u64, color: ColorArg, jpeg_quality: u8) -> webfusion_core::Result<FrameMessage> {
    let (wire_color, color_payload) = encode_color(&frame.color, color, jpeg_quality)?;
    Ok(FrameMessage {
        sequence,
        index: frame.index,
        depth_timestamp_ns: frame.depth_timestamp_ns,
        color_timestamp_ns: frame.color_timestamp_ns,
        ground_truth: None,
        depth_codec: DepthCodec::Rvl,
        depth_payload: DepthCodec::Rvl.encode(&frame.depth),
        color: wire_color,
        color_payload,
    })
}

fn encode_color(image: &webfusion_core::ColorImage, color: ColorArg, jpeg_quality: u8) -> webfusion_core::Result<(WireColor, Vec<u8>)> {
    Ok(match color {
        ColorArg::Auto | ColorArg::Jpeg => (WireColor::Coded(ColorCodec::Jpeg), ColorCodec::Jpeg.encode(image, jpeg_quality)?),
        ColorArg::Png => (WireColor::Coded(ColorCodec::Png), ColorCodec::Png.encode(image, jpeg_quality)?),
        ColorArg::Raw => (WireColor::Raw, image.rgb8.clone()),
    })
}

/// The ground-truth pose nearest in time to `timestamp_ns`, if within 20 ms (`poses` sorted).
fn pose_near(poses: &[TimedPose], timestamp_ns: i64) -> Option<Se3> {
    let after = poses.partition_point(|p| p.timestamp_ns < timestamp_ns);
    [after.checked_sub(1), Some(after)]
        .into_iter()
        .flatten()
        .filter_map(|i| poses.get(i))
        .min_by_key(|p| (p.timestamp_ns - timestamp_ns).unsigned_abs())
        .filter(|p| (p.timestamp_ns - timestamp_ns).abs() <= GROUND_TRUTH_MAX_DIFFERENCE_NS)
        .map(|p| p.world_from_camera)
}

/// One client's outgoing messages in order: replies (never dropped) and frames, at most
/// `capacity` frames queued.
struct OutQueue {
    state: Mutex<OutState>,
    /// Wakes the writer when something is queued, and a waiting producer when space frees.
    changed: Notify,
    capacity: usize,
}

#[derive(Default)]
struct OutState {
    /// Messages with a flag: `true` for a frame (droppable in live delivery).
    items: VecDeque<(WsMessage, bool)>,
    frames_queued: usize,
    frames_sent: u64,
    frames_dropped: u64,
    closed: bool,
}

impl OutQueue {
    fn new(capacity: usize) -> Self {
        Self { state: Mutex::new(OutState::default()), changed: Notify::new(), capacity }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, OutState> {
        self.state.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn reply(&self, message: WsMessage) {
        self.lock().items.push_back((message, false));
        self.changed.notify_waiters();
    }

    /// Queues a frame. Lossless: waits for room. Live: drops the oldest queued frame when full.
    /// Returns false once the client is gone.
    async fn push_frame(&self, bytes: Bytes, delivery: Delivery) -> bool {
        loop {
            let notified = self.changed.notified();
            {
                let mut state = self.lock();
                if state.closed {
                    return false;
                }
                if state.frames_queued < self.capacity || delivery == Delivery::Live {
                    if state.frames_queued >= self.capacity
                        && let Some(oldest) = state.items.iter().position(|(_, is_frame)| *is_frame)
                    {
                        state.items.remove(oldest);
                        state.frames_queued -= 1;
                        state.frames_dropped += 1;
                    }
                    state.items.push_back((WsMessage::Binary(bytes), true));
                    state.frames_queued += 1;
                    drop(state);
                    self.changed.notify_waiters();
                    return true;
                }
            }
            notified.await;
        }
    }

    /// Next message for the writer; `None` once closed and drained.
    async fn next(&self) -> Option<WsMessage> {
        loop {
            let notified = self.changed.notified();
            {
                let mut state = self.lock();
                if let Some((message, is_frame)) = state.items.pop_front() {
                    if is_frame {
                        state.frames_queued -= 1;
                        state.frames_sent += 1;
                    }
                    drop(state);
                    self.changed.notify_waiters();
                    return Some(message);
                }
                if state.closed {
                    return None;
                }
            }
            notified.await;
        }
    }

    /// Counts frames lost before they reached this queue (a client behind a live camera).
    fn add_dropped(&self, frames: u64) {
        self.lock().frames_dropped += frames;
    }

    fn close(&self) {
        self.lock().closed = true;
        self.changed.notify_waiters();
    }

    /// Frames sent and dropped so far; frames still queued count as sent (they are ahead of
    /// any status that reports these numbers).
    fn counts(&self) -> (u64, u64) {
        let state = self.lock();
        (state.frames_sent + state.frames_queued as u64, state.frames_dropped)
    }
}

/// Playback state of one session.
struct Playback {
    state: PlaybackState,
    next_index: usize,
    rate: f32,
    looping: bool,
    delivery: Delivery,
    /// Send one frame, then pause.
    stepping: bool,
    /// Wall-clock instant and source timestamp that pace real-rate replay; reset on any jump.
    anchor: Option<(Instant, i64)>,
    /// Damaged frames skipped (`--skip-corrupt`).
    frames_skipped: u64,
}

impl Playback {
    /// This session's status as a message, with the queue's frame counts.
    fn status(&self, queue: &OutQueue) -> WsMessage {
        let (frames_sent, frames_dropped) = queue.counts();
        let status = Status {
            state: self.state,
            next_index: self.next_index as u64,
            rate: self.rate,
            looping: self.looping,
            delivery: self.delivery,
            frames_sent,
            frames_dropped,
            frames_skipped: self.frames_skipped,
        };
        WsMessage::Binary(Message::Status(status).encode().into())
    }

    /// Moves past the frame just sent (or skipped): at the end it wraps to frame 0, and
    /// without looping the playback ends. Whether the client should hear of it.
    fn advance(&mut self, frame_count: usize) -> bool {
        self.next_index += 1;
        if self.next_index < frame_count {
            return false;
        }
        self.next_index = 0;
        self.anchor = None;
        if self.looping {
            return false;
        }
        self.state = PlaybackState::Ended;
        self.stepping = false;
        true
    }
}

async fn session(socket: WebSocket, shared: Arc<Shared>) {
    static SESSIONS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let id = SESSIONS.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
    let (mut sink, mut stream) = socket.split();
    let queue = Arc::new(OutQueue::new(shared.live_queue));
    let writer_queue = Arc::clone(&queue);
    // Sends what the session queues; a failed send ends it and is reported below.
    let writer = tokio::spawn(async move {
        let mut sent = Ok(());
        while let Some(message) = writer_queue.next().await {
            let is_close = matches!(message, WsMessage::Close(_));
            if let Err(e) = sink.send(message).await {
                sent = Err(e.to_string());
                break;
            }
            if is_close {
                break;
            }
        }
        writer_queue.close();
        sink.close().await.ok();
        sent
    });

    let outcome = match &shared.live {
        Some(hub) => drive_live_session(&mut stream, hub, shared.renderer.as_ref(), &queue).await,
        None => drive_session(&mut stream, &shared, &queue).await,
    };
    let client_left = outcome.is_ok();
    if let Err((code, reason)) = outcome {
        queue.reply(WsMessage::Binary(Message::Error { code, message: reason.clone() }.encode().into()));
        let close_code = if code == ErrorCode::SourceFailed { 1011 } else { 1008 };
        let mut reason_utf8 = reason;
        reason_utf8.truncate(reason_utf8.char_indices().map(|(i, _)| i).take_while(|&i| i <= 120).last().unwrap_or(0));
        queue.reply(WsMessage::Close(Some(CloseFrame { code: close_code, reason: reason_utf8.into() })));
    } else {
        // The client left: its close was answered by the WebSocket layer, and nothing more can
        // reach it.
        queue.close();
    }
    // Let the writer drain what is queued, but never wait forever on a stuck client.
    match tokio::time::timeout(Duration::from_secs(5), writer).await {
        Ok(Ok(Ok(()))) => {}
        // Messages still queued when the client closed cannot be sent: not a failure.
        Ok(Ok(Err(_))) if client_left => {}
        Ok(Ok(Err(e))) => eprintln!("serve: client #{id}: sending failed, session ended: {e}"),
        Ok(Err(e)) => eprintln!("serve: client #{id}: the sending task failed: {e}"),
        Err(_) => eprintln!("serve: client #{id}: took none of its last messages within 5 s; closed"),
    }
    queue.close();
}

/// Runs a session until the client leaves (`Ok`) or must be closed with an error.
async fn drive_session(stream: &mut futures_util::stream::SplitStream<WebSocket>, shared: &Shared, queue: &OutQueue) -> Result<(), (ErrorCode, String)> {
    let source_failed = |e: &dyn std::fmt::Display| (ErrorCode::SourceFailed, e.to_string());
    let mut source = SessionSource::open(&shared.source_path, shared.calibration_override).map_err(|e| source_failed(&e))?;
    let frame_count = source.frame_count();
    queue.reply(WsMessage::Binary(
        Message::Hello(Hello {
            source_name: source.name(),
            frame_count: Some(frame_count as u64),
            calibration: source.calibration(),
            has_ground_truth: source.source().ground_truth().is_some(),
            delivery: Delivery::Lossless,
            depth_noise: source.source().depth_noise(),
        })
        .encode()
        .into(),
    ));
    let mut playback =
        Playback { state: PlaybackState::Paused, next_index: 0, rate: 1.0, looping: false, delivery: Delivery::Lossless, stepping: false, anchor: None, frames_skipped: 0 };
    let mut sequence = 0_u64;
    // Damaged frames skipped since the last one sent: a source with nothing readable left
    // ends the session instead of skipping around a loop forever.
    let mut skipped_in_a_row = 0_usize;
    let status = |playback: &Playback| playback.status(queue);
    queue.reply(status(&playback));
    // The frame read ahead and the instant it is due.
    let mut pending: Option<(FrameMessage, Instant)> = None;
    loop {
        let active = playback.state == PlaybackState::Playing || playback.stepping;
        if active && pending.is_none() {
            let index = playback.next_index;
            let frame = match tokio::task::block_in_place(|| source.frame_message(index, sequence, shared.color, shared.jpeg_quality)) {
                Ok(frame) => frame,
                Err(e @ webfusion_core::Error::CorruptFrame { .. }) if shared.skip_corrupt => {
                    eprintln!("serve: skipping a damaged frame: {e}");
                    playback.frames_skipped += 1;
                    skipped_in_a_row += 1;
                    if skipped_in_a_row >= frame_count {
                        return Err((ErrorCode::SourceFailed, format!("every frame of the source is damaged (last: {e})")));
                    }
                    // A step goes on to the next readable frame.
                    if playback.advance(frame_count) {
                        queue.reply(status(&playback));
                    }
                    continue;
                }
                Err(e @ webfusion_core::Error::CorruptFrame { .. }) => return Err((ErrorCode::SourceFailed, format!("{e} (serve --skip-corrupt skips damaged frames)"))),
                Err(e) => return Err(source_failed(&e)),
            };
            skipped_in_a_row = 0;
            let now = Instant::now();
            let due = match playback.anchor {
                _ if playback.stepping || playback.rate == 0.0 => now,
                None => now,
                Some((wall, stamp_ns)) => {
                    let offset_s = (frame.depth_timestamp_ns - stamp_ns).max(0) as f64 * 1e-9 / f64::from(playback.rate);
                    wall + Duration::from_secs_f64(offset_s.min(10.0))
                }
            };
            if playback.anchor.is_none() {
                playback.anchor = Some((now, frame.depth_timestamp_ns));
            }
            pending = Some((frame, due));
        }
        let due = pending.as_ref().map(|(_, due)| *due);
        tokio::select! {
            incoming = stream.next() => {
                let control = match from_client(incoming)? {
                    FromClient::Left => return Ok(()),
                    FromClient::Nothing => continue,
                    FromClient::Render(request) => {
                        answer_render(shared.renderer.as_ref(), queue, request).await;
                        continue;
                    }
                    FromClient::Control(control) => control,
                };
                apply_control(&mut playback, control, frame_count).map_err(|reason| (ErrorCode::InvalidControl, reason))?;
                pending = None;
                queue.reply(status(&playback));
            }
            () = sleep_until_or_forever(due) => {
                let Some((frame, _)) = pending.take() else { continue };
                if !queue.push_frame(Message::Frame(frame).encode().into(), playback.delivery).await {
                    return Ok(());
                }
                sequence += 1;
                let stepped = std::mem::take(&mut playback.stepping);
                let ended = playback.advance(frame_count);
                if stepped || ended {
                    queue.reply(status(&playback));
                }
            }
        }
    }
}

/// What a client's WebSocket message asks for.
enum FromClient {
    /// The client left.
    Left,
    /// A ping or pong: nothing to do.
    Nothing,
    /// A playback control.
    Control(Control),
    /// A render request (its id, and the request or why it does not decode).
    Render((u32, Result<RenderRequest, String>)),
}

/// Reads a client's WebSocket message; an error (the close reason) for anything malformed,
/// except a render request whose id can be read: that is answered, not closed over.
fn from_client(incoming: Option<Result<WsMessage, axum::Error>>) -> Result<FromClient, (ErrorCode, String)> {
    let bytes = match incoming {
        None | Some(Ok(WsMessage::Close(_))) => return Ok(FromClient::Left),
        Some(Err(e)) => return Err((ErrorCode::MalformedMessage, format!("WebSocket error: {e}"))),
        Some(Ok(WsMessage::Binary(bytes))) => bytes,
        Some(Ok(WsMessage::Ping(_) | WsMessage::Pong(_))) => return Ok(FromClient::Nothing),
        Some(Ok(WsMessage::Text(_))) => return Err((ErrorCode::MalformedMessage, "text messages are not part of the protocol; send binary control messages".to_owned())),
    };
    match Message::decode(&bytes) {
        Ok(Message::Control(control)) => Ok(FromClient::Control(control)),
        Ok(Message::RenderRequest(request)) => Ok(FromClient::Render((request.request_id, Ok(request)))),
        Ok(other) => Err((ErrorCode::MalformedMessage, format!("clients may only send control and render request messages, got {}", kind_name(&other)))),
        Err(e @ webfusion_core::Error::ProtocolVersion { .. }) => Err((ErrorCode::UnsupportedVersion, e.to_string())),
        Err(e) => match render_request_id(&bytes) {
            Some(request_id) => Ok(FromClient::Render((request_id, Err(e.to_string())))),
            None => Err((ErrorCode::MalformedMessage, e.to_string())),
        },
    }
}

/// Answers a render request in the session's queue (after whatever is queued before it): the
/// view, or why there is none. The session stays open either way.
async fn answer_render(renderer: Option<&Renderer>, queue: &OutQueue, (request_id, request): (u32, Result<RenderRequest, String>)) {
    let outcome = match (renderer, request) {
        (_, Err(reason)) => RenderOutcome::Failed { code: RenderFailure::InvalidRequest, message: reason },
        (None, Ok(_)) => RenderOutcome::Failed { code: RenderFailure::NoMap, message: "this server has no map to render: start it with `webfusion serve --map MAP.wfm`".to_owned() },
        (Some(renderer), Ok(request)) => renderer.render(request).await,
    };
    queue.reply(WsMessage::Binary(Message::RenderReply { request_id, outcome }.encode().into()));
}

/// Runs a client of a live camera: frames flow while it plays, from the newest on.
async fn drive_live_session(stream: &mut futures_util::stream::SplitStream<WebSocket>, hub: &LiveHub, renderer: Option<&Renderer>, queue: &OutQueue) -> Result<(), (ErrorCode, String)> {
    let mut frames = hub.frames.subscribe();
    if let Some(reason) = hub.failure.lock().unwrap_or_else(std::sync::PoisonError::into_inner).clone() {
        return Err((ErrorCode::SourceFailed, reason));
    }
    queue.reply(WsMessage::Binary(
        Message::Hello(Hello { source_name: hub.name.clone(), frame_count: None, calibration: hub.calibration, has_ground_truth: false, delivery: Delivery::Live, depth_noise: DepthNoise::KinectV1 }).encode().into(),
    ));
    let mut playback = Playback { state: PlaybackState::Paused, next_index: 0, rate: 1.0, looping: false, delivery: Delivery::Live, stepping: false, anchor: None, frames_skipped: 0 };
    // A camera's "next index" is the number of frames it has captured.
    let status = |playback: &mut Playback| {
        playback.next_index = hub.captured.load(Ordering::Relaxed) as usize;
        playback.status(queue)
    };
    queue.reply(status(&mut playback));
    loop {
        tokio::select! {
            incoming = stream.next() => {
                let control = match from_client(incoming)? {
                    FromClient::Left => return Ok(()),
                    FromClient::Nothing => continue,
                    FromClient::Render(request) => {
                        answer_render(renderer, queue, request).await;
                        continue;
                    }
                    FromClient::Control(control) => control,
                };
                apply_live_control(&mut playback, control).map_err(|reason| (ErrorCode::InvalidControl, reason))?;
                queue.reply(status(&mut playback));
            }
            item = frames.recv() => {
                let active = playback.state == PlaybackState::Playing || playback.stepping;
                match item {
                    Ok(LiveItem::Frame(bytes)) if active => {
                        if !queue.push_frame(bytes, playback.delivery).await {
                            return Ok(());
                        }
                        if playback.stepping {
                            playback.stepping = false;
                            queue.reply(status(&mut playback));
                        }
                    }
                    Ok(LiveItem::Frame(_)) => {}
                    Ok(LiveItem::Failed(reason)) => return Err((ErrorCode::SourceFailed, reason.to_string())),
                    Err(broadcast::error::RecvError::Lagged(missed)) => {
                        if active {
                            queue.add_dropped(missed);
                        }
                    }
                    Err(broadcast::error::RecvError::Closed) => return Err((ErrorCode::SourceFailed, "the live capture ended".to_owned())),
                }
            }
        }
    }
}

/// Applies a control to a live session: play, pause, step and delivery; a camera cannot
/// seek, loop or change its rate.
fn apply_live_control(playback: &mut Playback, control: Control) -> Result<(), String> {
    match control {
        Control::Play => playback.state = PlaybackState::Playing,
        Control::Pause => {
            playback.state = PlaybackState::Paused;
            playback.stepping = false;
        }
        Control::Step => {
            playback.state = PlaybackState::Paused;
            playback.stepping = true;
        }
        Control::Delivery(delivery) => playback.delivery = delivery,
        Control::Seek(_) => return Err("the source is a live camera: it cannot seek".to_owned()),
        Control::Rate(_) => return Err("the source is a live camera: it runs at its own rate".to_owned()),
        Control::Loop(_) => return Err("the source is a live camera: there is nothing to loop".to_owned()),
    }
    Ok(())
}

async fn sleep_until_or_forever(due: Option<Instant>) {
    match due {
        Some(due) => tokio::time::sleep_until(due).await,
        None => std::future::pending().await,
    }
}

fn kind_name(message: &Message) -> &'static str {
    match message {
        Message::Hello(_) => "hello",
        Message::Frame(_) => "frame",
        Message::Status(_) => "status",
        Message::Error { .. } => "error",
        Message::RenderReply { .. } => "render reply",
        Message::Control(_) => "control",
        Message::RenderRequest(_) => "render request",
    }
}

/// Applies a client's control; an invalid argument is the reason the session closes.
fn apply_control(playback: &mut Playback, control: Control, frame_count: usize) -> Result<(), String> {
    playback.anchor = None;
    match control {
        Control::Play => {
            if playback.state == PlaybackState::Ended {
                playback.next_index = 0;
            }
            playback.state = PlaybackState::Playing;
        }
        Control::Pause => {
            playback.state = PlaybackState::Paused;
            playback.stepping = false;
        }
        Control::Step => {
            if playback.state == PlaybackState::Ended {
                playback.next_index = 0;
            }
            playback.state = PlaybackState::Paused;
            playback.stepping = true;
        }
        Control::Seek(index) => {
            if index >= frame_count as u64 {
                return Err(format!("seek to frame {index}, but the source has {frame_count} frames (0..{frame_count})"));
            }
            playback.next_index = index as usize;
            if playback.state == PlaybackState::Ended {
                playback.state = PlaybackState::Paused;
            }
        }
        Control::Rate(rate) => playback.rate = rate,
        Control::Loop(on) => playback.looping = on,
        Control::Delivery(delivery) => playback.delivery = delivery,
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use glam::{DQuat, DVec3};

    use super::*;

    #[test]
    fn ground_truth_is_the_nearest_pose_within_20_ms() {
        let pose = |t: i64, x: f64| TimedPose { timestamp_ns: t, world_from_camera: Se3::new(DQuat::IDENTITY, DVec3::new(x, 0.0, 0.0)) };
        let poses = [pose(0, 0.0), pose(10_000_000, 1.0), pose(100_000_000, 2.0)];
        assert_eq!(pose_near(&poses, 4_000_000).map(|p| p.translation_m.x), Some(0.0), "nearer the first");
        assert_eq!(pose_near(&poses, 6_000_000).map(|p| p.translation_m.x), Some(1.0), "nearer the second");
        assert_eq!(pose_near(&poses, 55_000_000), None, "45 ms from both");
        assert_eq!(pose_near(&poses, 119_000_000).map(|p| p.translation_m.x), Some(2.0), "19 ms after the last");
        assert_eq!(pose_near(&[], 0), None, "no poses");
    }

    #[test]
    fn origins_must_match_the_host_or_the_allowed_list() {
        let headers = |origin: Option<&str>| {
            let mut h = HeaderMap::new();
            h.insert(header::HOST, "127.0.0.1:8080".parse().expect("header"));
            if let Some(o) = origin {
                h.insert(header::ORIGIN, o.parse().expect("header"));
            }
            h
        };
        let allowed = vec!["https://viewer.example".to_owned()];
        assert!(origin_allowed(&headers(None), &allowed), "native client");
        assert!(origin_allowed(&headers(Some("http://127.0.0.1:8080")), &allowed), "same origin");
        assert!(origin_allowed(&headers(Some("https://viewer.example")), &allowed), "allowed origin");
        assert!(!origin_allowed(&headers(Some("http://evil.example")), &allowed), "foreign origin");
        assert!(!origin_allowed(&headers(Some("http://127.0.0.1:8081")), &allowed), "other port");
    }

    #[test]
    fn secrets_compare_exactly() {
        assert!(same_secret("abc", "abc"), "equal");
        assert!(!same_secret("abc", "abd"), "differs");
        assert!(!same_secret("abc", "abcd"), "longer");
        assert!(!same_secret("", "a"), "empty");
    }

    #[test]
    fn seek_past_the_end_is_refused_and_play_restarts_after_the_end() {
        let mut playback = Playback { state: PlaybackState::Ended, next_index: 0, rate: 1.0, looping: false, delivery: Delivery::Lossless, stepping: false, anchor: None, frames_skipped: 0 };
        assert!(apply_control(&mut playback, Control::Seek(10), 10).is_err(), "seek to 10 of 10");
        apply_control(&mut playback, Control::Seek(9), 10).expect("seek to 9");
        assert_eq!((playback.next_index, playback.state), (9, PlaybackState::Paused), "after seek");
        apply_control(&mut playback, Control::Step, 10).expect("step");
        assert!(playback.stepping, "stepping");
    }
}
