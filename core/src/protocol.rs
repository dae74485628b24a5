// SPDX-License-Identifier: MIT
//! The bridge's WebSocket protocol, shared by the native bridge and the browser app.
//!
//! Pure encoding and decoding, no I/O: one [`Message`] per WebSocket binary message.
//! Every message starts with a 4-byte header, `b"WF"`, the protocol version
//! ([`PROTOCOL_VERSION`]) and a kind byte; all numbers after it are little-endian.
//!
//! | kind | direction | body |
//! |---|---|---|
//! | 1 `Hello` | server → client | source name, frame count, calibration, ground truth flag, delivery, depth noise |
//! | 2 `Frame` | server → client | sequence, index, timestamps, optional ground-truth pose, depth (RVL), colour |
//! | 3 `Status` | server → client | playback state, next index, rate, loop, delivery, sent/dropped/skipped counts |
//! | 4 `Error` | server → client | code and message; the server closes after it |
//! | 5 `RenderReply` | server → client | the request's id, then a rendered view (depth, optional colour and unknown mask) or why not |
//! | 16 `Control` | client → server | play, pause, step, seek, rate, loop, delivery |
//! | 17 `RenderRequest` | client → server | id, `world_from_camera`, intrinsics, depth scale and encoding, range, noise, colour, unknown mask |
//!
//! Render requests (`serve --map`) let any WebSocket client, a planner in any language, query
//! the virtual depth sensor at a pose; `scripts/render_client.py` is a stdlib-only example. A
//! request that does not decode is answered with a failed [`RenderReply`] naming the problem
//! when its id can be read ([`render_request_id`]), and the session stays open. Version 3 added
//! the unknown mask (the pixels whose ray crossed never-observed space before its return) and
//! the source's depth noise to `Hello` (a simulated log without noise is tracked as native
//! `reconstruct` tracks it).
//!
//! A message of another version is rejected with [`Error::Protocol`] naming both versions, so
//! old and new peers fail loudly instead of misreading each other. Decoding never allocates
//! more than the message's own length and never panics on hostile input (fuzzed in
//! `tests/protocol_fuzz.rs`).

use glam::{DQuat, DVec3};

use crate::codec::{ColorCodec, DepthCodec};
use crate::source::DepthNoise;
use crate::{ColorImage, DepthImage, Error, PinholeIntrinsics, Result, RgbdCalibration, RgbdFrame, Se3};

/// First two bytes of every message.
pub const PROTOCOL_MAGIC: [u8; 2] = *b"WF";
/// The protocol version this build speaks.
pub const PROTOCOL_VERSION: u8 = 3;
/// Largest message a client may send; control messages are a few bytes.
pub const MAX_CLIENT_MESSAGE_BYTES: usize = 1024;
/// Largest message a server may send (a raw 1280x1024 RGB frame plus depth fits easily).
pub const MAX_SERVER_MESSAGE_BYTES: usize = 16 << 20;
/// Longest source name or error message, in bytes.
pub const MAX_TEXT_BYTES: usize = 4096;
/// Fastest playback rate a client may ask for, times the source's own rate.
pub const MAX_RATE: f32 = 1000.0;

/// A playback rate the bridge accepts: a number in `0..=MAX_RATE` (0: as fast as possible).
/// The one rule the decoder and the page's inputs share, so a page never sends a rate the
/// bridge would close the session over.
pub fn checked_rate(rate: f32) -> std::result::Result<f32, String> {
    if (0.0..=MAX_RATE).contains(&rate) { Ok(rate) } else { Err(format!("rate {rate} is outside 0..={MAX_RATE} (0: as fast as possible)")) }
}

/// Parses a playback rate typed by a person or given in a URL ([`checked_rate`]).
pub fn parse_rate(text: &str) -> std::result::Result<f32, String> {
    let rate: f32 = text.trim().parse().map_err(|_| format!("rate {text:?} is not a number"))?;
    checked_rate(rate)
}

const KIND_HELLO: u8 = 1;
const KIND_FRAME: u8 = 2;
const KIND_STATUS: u8 = 3;
const KIND_ERROR: u8 = 4;
const KIND_RENDER_REPLY: u8 = 5;
const KIND_CONTROL: u8 = 16;
const KIND_RENDER_REQUEST: u8 = 17;

/// Largest image side a render request may ask for, pixels.
pub const MAX_RENDER_SIDE_PX: u32 = 4096;

/// How a server delivers frames to one client.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Delivery {
    /// Every frame, in order; the source waits for the client (replay, evaluation).
    Lossless,
    /// Newest frames first: a bounded queue drops stale frames for a slow client.
    Live,
}

/// Playback state of a client's session.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlaybackState {
    /// Waiting for `Play` or `Step`.
    Paused,
    /// Sending frames.
    Playing,
    /// Past the last frame and not looping.
    Ended,
}

/// Colour payload encoding on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WireColor {
    /// Packed RGB8, `3 * width * height` bytes.
    Raw,
    /// A compressed image file.
    Coded(ColorCodec),
}

/// Depth payload encoding on the wire of a render reply.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WireDepth {
    /// Row-major u16 little-endian, `2 * width * height` bytes (simplest to read anywhere).
    Raw,
    /// A lossless depth codec.
    Coded(DepthCodec),
}

impl WireDepth {
    fn id(self) -> u8 {
        match self {
            Self::Raw => 0,
            Self::Coded(codec) => codec.id(),
        }
    }

    fn from_id(id: u8) -> Option<Self> {
        if id == 0 { Some(Self::Raw) } else { DepthCodec::from_id(id).map(Self::Coded) }
    }

    /// `image` in this encoding.
    pub fn encode(self, image: &DepthImage) -> Vec<u8> {
        match self {
            Self::Raw => image.units.iter().flat_map(|u| u.to_le_bytes()).collect(),
            Self::Coded(codec) => codec.encode(image),
        }
    }

    /// A `width_px` x `height_px` image from `payload`; a payload of the wrong size is an error.
    pub fn decode(self, payload: &[u8], width_px: u32, height_px: u32) -> Result<DepthImage> {
        match self {
            Self::Raw => {
                let pixels = width_px as usize * height_px as usize;
                if payload.len() != 2 * pixels {
                    return Err(protocol_error(format!("raw depth payload has {} bytes, {width_px}x{height_px} u16 needs {}", payload.len(), 2 * pixels)));
                }
                DepthImage::new(width_px, height_px, payload.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect())
            }
            Self::Coded(codec) => codec.decode(payload, width_px, height_px),
        }
    }
}

/// Seeded depth noise for a render request: the Kinect v1 model of `webfusion simulate
/// --noise kinect`. A view's noise depends only on the seed, the frame index and the pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RenderNoise {
    /// The noise's seed.
    pub seed: u32,
    /// The frame index the noise is drawn for (two requests with the same seed and index at
    /// the same pose give the same view).
    pub frame_index: u32,
}

/// A client's request to render the served map (`serve --map`) at a pose.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderRequest {
    /// Chosen by the client; the reply carries it back.
    pub request_id: u32,
    /// The virtual camera's pose in the map's frame (`world_from_camera`, camera axes x right,
    /// y down, z forward).
    pub world_from_camera: Se3,
    /// The virtual camera's pinhole model and image size.
    pub intrinsics: PinholeIntrinsics,
    /// Raw depth units per metre of the reply (TUM: 5000).
    pub depth_units_per_metre: f32,
    /// Distance along each pixel's ray instead of depth along z.
    pub radial: bool,
    /// Nearest and farthest depth with a return, metres; `None`: the Kinect model's range.
    pub depth_range_m: Option<(f32, f32)>,
    /// Seeded Kinect noise; `None`: exact depth.
    pub noise: Option<RenderNoise>,
    /// Also return the map's colour at each pixel.
    pub color: bool,
    /// Also return which pixels looked through never-observed space before their return (or
    /// up to the far range, without one): a planner cannot trust those views' free space. Needs
    /// the server's occupancy grid (`serve --map M --occupancy G.json`).
    pub unknown: bool,
    /// How the reply's depth is encoded.
    pub depth_encoding: WireDepth,
}

/// A rendered view: what a depth sensor at the request's pose would see.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderedView {
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Raw depth units per metre.
    pub depth_units_per_metre: f32,
    /// Whether depth is the distance along each ray (else depth along z).
    pub radial: bool,
    /// Depth encoding.
    pub depth_encoding: WireDepth,
    /// Depth payload: one u16 per pixel once decoded, 0 where nothing was hit or out of range.
    pub depth_payload: Vec<u8>,
    /// The map's colour, packed RGB8 (`3 * width * height` bytes), when asked for.
    pub color_rgb8: Option<Vec<u8>>,
    /// One byte per pixel, row-major: 255 where the pixel's ray crossed never-observed space
    /// before its return, else 0 (as `simulate --occupancy`'s unknown/ images), when asked for.
    pub unknown_mask: Option<Vec<u8>>,
}

impl RenderedView {
    /// The depth image.
    pub fn depth_image(&self) -> Result<DepthImage> {
        self.depth_encoding.decode(&self.depth_payload, self.width_px, self.height_px)
    }
}

/// Why a render request was not answered with a view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum RenderFailure {
    /// The server has no map to render (start it with `serve --map`).
    NoMap = 1,
    /// The request is malformed or its values are out of range.
    InvalidRequest = 2,
    /// Rendering failed on the server (the GPU reported an error).
    RenderFailed = 3,
}

/// The answer to a render request.
#[derive(Clone, Debug, PartialEq)]
pub enum RenderOutcome {
    /// The rendered view.
    View(RenderedView),
    /// No view, and why.
    Failed {
        /// Machine-readable reason.
        code: RenderFailure,
        /// Human-readable reason.
        message: String,
    },
}

/// The largest reply a render request can produce: raw depth, colour, the unknown mask and
/// the fixed fields.
fn render_reply_bytes(width_px: u32, height_px: u32, color: bool, unknown: bool) -> usize {
    let pixels = width_px as usize * height_px as usize;
    64 + 2 * pixels + if color { 3 * pixels } else { 0 } + if unknown { pixels } else { 0 }
}

/// The id of a render request in `bytes` when at least its header and id can be read, whether
/// or not the rest decodes: the server answers a bad request instead of closing the session.
pub fn render_request_id(bytes: &[u8]) -> Option<u32> {
    match bytes {
        [m0, m1, version, KIND_RENDER_REQUEST, a, b, c, d, ..] if [*m0, *m1] == PROTOCOL_MAGIC && *version == PROTOCOL_VERSION => Some(u32::from_le_bytes([*a, *b, *c, *d])),
        _ => None,
    }
}

/// A command from a client.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Control {
    /// Start or resume sending.
    Play,
    /// Stop sending after the current frame.
    Pause,
    /// Send the next frame and pause.
    Step,
    /// Continue from this frame index.
    Seek(u64),
    /// Replay speed relative to the recorded timestamps; 0 sends as fast as the client reads.
    Rate(f32),
    /// Whether to restart at frame 0 after the last one.
    Loop(bool),
    /// Switch delivery mode.
    Delivery(Delivery),
}

/// What the server tells a client first.
#[derive(Clone, Debug, PartialEq)]
pub struct Hello {
    /// Source name (directory or file name, or device URI).
    pub source_name: String,
    /// Frames in the source; `None` for a live device.
    pub frame_count: Option<u64>,
    /// Calibration of every frame.
    pub calibration: RgbdCalibration,
    /// Whether frames carry ground-truth poses.
    pub has_ground_truth: bool,
    /// Delivery mode the session starts in.
    pub delivery: Delivery,
    /// The noise of the source's depth ([`FrameSource::depth_noise`](crate::source::FrameSource::depth_noise)).
    pub depth_noise: DepthNoise,
}

/// One RGB-D frame, compressed.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameMessage {
    /// Position in this client's stream, from 0, counting dropped frames too (gaps = drops).
    pub sequence: u64,
    /// Index of the frame in its source.
    pub index: u64,
    /// Depth capture time, nanoseconds.
    pub depth_timestamp_ns: i64,
    /// Colour capture time, nanoseconds.
    pub color_timestamp_ns: i64,
    /// Ground-truth `world_from_camera` at the depth timestamp, when the source has it.
    pub ground_truth: Option<Se3>,
    /// Depth encoding (lossless).
    pub depth_codec: DepthCodec,
    /// Depth payload.
    pub depth_payload: Vec<u8>,
    /// Colour encoding.
    pub color: WireColor,
    /// Colour payload.
    pub color_payload: Vec<u8>,
}

/// A session's playback status, sent after every control and at the end.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Status {
    /// Playback state.
    pub state: PlaybackState,
    /// Index of the next frame to send.
    pub next_index: u64,
    /// Replay rate (0 = as fast as the client reads).
    pub rate: f32,
    /// Whether playback loops.
    pub looping: bool,
    /// Delivery mode.
    pub delivery: Delivery,
    /// Frames sent to this client.
    pub frames_sent: u64,
    /// Frames dropped for this client (live delivery only).
    pub frames_dropped: u64,
    /// Damaged frames of the source skipped for this client (`serve --skip-corrupt`).
    pub frames_skipped: u64,
}

/// Why the server is closing a session.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum ErrorCode {
    /// The client sent a message the server cannot decode.
    MalformedMessage = 1,
    /// The client speaks another protocol version.
    UnsupportedVersion = 2,
    /// The source failed (unreadable frame, device gone).
    SourceFailed = 3,
    /// A control had an invalid argument (seek past the end, negative rate).
    InvalidControl = 4,
}

/// One protocol message.
#[derive(Clone, Debug, PartialEq)]
pub enum Message {
    /// Server → client, first message of a session.
    Hello(Hello),
    /// Server → client.
    Frame(FrameMessage),
    /// Server → client.
    Status(Status),
    /// Server → client; the server closes after it.
    Error {
        /// Machine-readable reason.
        code: ErrorCode,
        /// Human-readable reason.
        message: String,
    },
    /// Server → client: the answer to the client's [`Message::RenderRequest`] of the same id.
    RenderReply {
        /// The request's id.
        request_id: u32,
        /// The view, or why there is none.
        outcome: RenderOutcome,
    },
    /// Client → server.
    Control(Control),
    /// Client → server: render the served map at a pose.
    RenderRequest(RenderRequest),
}

impl FrameMessage {
    /// Decodes the payloads into a frame of `calibration`'s size.
    pub fn decode_images(&self, calibration: &RgbdCalibration) -> Result<RgbdFrame> {
        let (w, h) = (calibration.intrinsics.width_px, calibration.intrinsics.height_px);
        let depth: DepthImage = self.depth_codec.decode(&self.depth_payload, w, h)?;
        let color = match self.color {
            WireColor::Raw => ColorImage::new(w, h, self.color_payload.clone())
                .map_err(|_| protocol_error(format!("raw colour payload has {} bytes, {w}x{h} RGB needs {}", self.color_payload.len(), 3 * w as usize * h as usize)))?,
            WireColor::Coded(codec) => codec.decode(&self.color_payload, w, h)?,
        };
        Ok(RgbdFrame { index: self.index, depth_timestamp_ns: self.depth_timestamp_ns, color_timestamp_ns: self.color_timestamp_ns, depth, color })
    }
}

fn protocol_error(message: String) -> Error {
    Error::Protocol { message }
}

impl Message {
    /// Encodes the message as one WebSocket binary payload.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer(Vec::with_capacity(self.encoded_len_hint()));
        w.bytes(&PROTOCOL_MAGIC);
        w.u8(PROTOCOL_VERSION);
        match self {
            Message::Hello(hello) => {
                w.u8(KIND_HELLO);
                w.text(&hello.source_name);
                w.u64(hello.frame_count.unwrap_or(u64::MAX));
                let k = &hello.calibration.intrinsics;
                w.u32(k.width_px);
                w.u32(k.height_px);
                for v in [k.fx_px, k.fy_px, k.cx_px, k.cy_px, hello.calibration.depth_units_per_metre] {
                    w.f32(v);
                }
                w.u8(u8::from(hello.has_ground_truth));
                w.u8(delivery_id(hello.delivery));
                w.u8(match hello.depth_noise {
                    DepthNoise::KinectV1 => 0,
                    DepthNoise::None => 1,
                });
            }
            Message::Frame(frame) => {
                w.u8(KIND_FRAME);
                w.u64(frame.sequence);
                w.u64(frame.index);
                w.i64(frame.depth_timestamp_ns);
                w.i64(frame.color_timestamp_ns);
                match &frame.ground_truth {
                    None => w.u8(0),
                    Some(pose) => {
                        w.u8(1);
                        w.pose(pose);
                    }
                }
                w.u8(frame.depth_codec.id());
                w.blob(&frame.depth_payload);
                w.u8(match frame.color {
                    WireColor::Raw => 0,
                    WireColor::Coded(codec) => codec.id(),
                });
                w.blob(&frame.color_payload);
            }
            Message::Status(status) => {
                w.u8(KIND_STATUS);
                w.u8(match status.state {
                    PlaybackState::Paused => 0,
                    PlaybackState::Playing => 1,
                    PlaybackState::Ended => 2,
                });
                w.u64(status.next_index);
                w.f32(status.rate);
                w.u8(u8::from(status.looping));
                w.u8(delivery_id(status.delivery));
                w.u64(status.frames_sent);
                w.u64(status.frames_dropped);
                w.u64(status.frames_skipped);
            }
            Message::Error { code, message } => {
                w.u8(KIND_ERROR);
                w.u16(*code as u16);
                w.text(message);
            }
            Message::Control(control) => {
                w.u8(KIND_CONTROL);
                match *control {
                    Control::Play => w.u8(1),
                    Control::Pause => w.u8(2),
                    Control::Step => w.u8(3),
                    Control::Seek(index) => {
                        w.u8(4);
                        w.u64(index);
                    }
                    Control::Rate(rate) => {
                        w.u8(5);
                        w.f32(rate);
                    }
                    Control::Loop(on) => {
                        w.u8(6);
                        w.u8(u8::from(on));
                    }
                    Control::Delivery(delivery) => {
                        w.u8(7);
                        w.u8(delivery_id(delivery));
                    }
                }
            }
            Message::RenderRequest(request) => {
                w.u8(KIND_RENDER_REQUEST);
                w.u32(request.request_id);
                w.pose(&request.world_from_camera);
                let k = &request.intrinsics;
                w.u32(k.width_px);
                w.u32(k.height_px);
                for v in [k.fx_px, k.fy_px, k.cx_px, k.cy_px, request.depth_units_per_metre] {
                    w.f32(v);
                }
                w.u8(u8::from(request.radial));
                w.u8(u8::from(request.color));
                w.u8(request.depth_encoding.id());
                match request.depth_range_m {
                    None => w.u8(0),
                    Some((near_m, far_m)) => {
                        w.u8(1);
                        w.f32(near_m);
                        w.f32(far_m);
                    }
                }
                match request.noise {
                    None => w.u8(0),
                    Some(noise) => {
                        w.u8(1);
                        w.u32(noise.seed);
                        w.u32(noise.frame_index);
                    }
                }
                w.u8(u8::from(request.unknown));
            }
            Message::RenderReply { request_id, outcome } => {
                w.u8(KIND_RENDER_REPLY);
                w.u32(*request_id);
                match outcome {
                    RenderOutcome::View(view) => {
                        w.u8(0);
                        w.u32(view.width_px);
                        w.u32(view.height_px);
                        w.f32(view.depth_units_per_metre);
                        w.u8(u8::from(view.radial));
                        w.u8(view.depth_encoding.id());
                        w.blob(&view.depth_payload);
                        for optional in [&view.color_rgb8, &view.unknown_mask] {
                            match optional {
                                None => w.u8(0),
                                Some(bytes) => {
                                    w.u8(1);
                                    w.blob(bytes);
                                }
                            }
                        }
                    }
                    RenderOutcome::Failed { code, message } => {
                        w.u8(*code as u8);
                        w.text(message);
                    }
                }
            }
        }
        w.0
    }

    fn encoded_len_hint(&self) -> usize {
        match self {
            Message::Frame(f) => 128 + f.depth_payload.len() + f.color_payload.len(),
            Message::RenderReply { outcome: RenderOutcome::View(v), .. } => 64 + v.depth_payload.len() + v.color_rgb8.as_ref().map_or(0, Vec::len) + v.unknown_mask.as_ref().map_or(0, Vec::len),
            _ => 64,
        }
    }

    /// Decodes one message; every malformed input is an [`Error::Protocol`] naming the problem.
    pub fn decode(bytes: &[u8]) -> Result<Message> {
        let mut r = Reader { bytes, at: 0 };
        let magic = r.take(2, "magic")?;
        if magic != PROTOCOL_MAGIC {
            return Err(protocol_error(format!("not a webfusion message (starts with {magic:02x?}, expected \"WF\")")));
        }
        let version = r.u8("version")?;
        if version != PROTOCOL_VERSION {
            return Err(Error::ProtocolVersion { got: version, supported: PROTOCOL_VERSION });
        }
        let kind = r.u8("kind")?;
        let message = match kind {
            KIND_HELLO => {
                let source_name = r.text("source name")?;
                let frame_count = match r.u64("frame count")? {
                    u64::MAX => None,
                    n => Some(n),
                };
                let width_px = r.u32("width")?;
                let height_px = r.u32("height")?;
                let [fx_px, fy_px, cx_px, cy_px, depth_units_per_metre] =
                    [r.f32("fx")?, r.f32("fy")?, r.f32("cx")?, r.f32("cy")?, r.f32("depth units per metre")?];
                if width_px == 0 || height_px == 0 || width_px > 8192 || height_px > 8192 {
                    return Err(protocol_error(format!("hello: image size {width_px}x{height_px} out of range")));
                }
                if !([fx_px, fy_px, cx_px, cy_px, depth_units_per_metre].iter().all(|v| v.is_finite()) && fx_px > 0.0 && fy_px > 0.0 && depth_units_per_metre > 0.0) {
                    return Err(protocol_error("hello: calibration values must be finite and positive".to_owned()));
                }
                let intrinsics = PinholeIntrinsics { fx_px, fy_px, cx_px, cy_px, width_px, height_px };
                let has_ground_truth = r.bool("ground truth flag")?;
                let delivery = r.delivery()?;
                let depth_noise = match r.u8("depth noise")? {
                    0 => DepthNoise::KinectV1,
                    1 => DepthNoise::None,
                    other => return Err(protocol_error(format!("hello: unknown depth noise {other} (0 kinect, 1 none)"))),
                };
                Message::Hello(Hello { source_name, frame_count, calibration: RgbdCalibration { intrinsics, depth_units_per_metre }, has_ground_truth, delivery, depth_noise })
            }
            KIND_FRAME => {
                let sequence = r.u64("sequence")?;
                let index = r.u64("index")?;
                let depth_timestamp_ns = r.i64("depth timestamp")?;
                let color_timestamp_ns = r.i64("colour timestamp")?;
                let ground_truth = if r.bool("ground truth flag")? { Some(r.pose("frame: ground-truth pose")?) } else { None };
                let depth_id = r.u8("depth codec")?;
                let depth_codec = DepthCodec::from_id(depth_id).ok_or_else(|| protocol_error(format!("frame: unknown depth codec id {depth_id}")))?;
                let depth_payload = r.blob("depth payload")?.to_vec();
                let color = match r.u8("colour codec")? {
                    0 => WireColor::Raw,
                    id => WireColor::Coded(ColorCodec::from_id(id).ok_or_else(|| protocol_error(format!("frame: unknown colour codec id {id}")))?),
                };
                let color_payload = r.blob("colour payload")?.to_vec();
                Message::Frame(FrameMessage { sequence, index, depth_timestamp_ns, color_timestamp_ns, ground_truth, depth_codec, depth_payload, color, color_payload })
            }
            KIND_STATUS => {
                let state = match r.u8("state")? {
                    0 => PlaybackState::Paused,
                    1 => PlaybackState::Playing,
                    2 => PlaybackState::Ended,
                    other => return Err(protocol_error(format!("status: unknown playback state {other}"))),
                };
                let next_index = r.u64("next index")?;
                let rate = r.f32("rate")?;
                let looping = r.bool("loop flag")?;
                let delivery = r.delivery()?;
                let frames_sent = r.u64("frames sent")?;
                let frames_dropped = r.u64("frames dropped")?;
                let frames_skipped = r.u64("frames skipped")?;
                Message::Status(Status { state, next_index, rate, looping, delivery, frames_sent, frames_dropped, frames_skipped })
            }
            KIND_ERROR => {
                let code = match r.u16("error code")? {
                    1 => ErrorCode::MalformedMessage,
                    2 => ErrorCode::UnsupportedVersion,
                    3 => ErrorCode::SourceFailed,
                    4 => ErrorCode::InvalidControl,
                    other => return Err(protocol_error(format!("error: unknown code {other}"))),
                };
                Message::Error { code, message: r.text("error message")? }
            }
            KIND_CONTROL => {
                let op = r.u8("control op")?;
                Message::Control(match op {
                    1 => Control::Play,
                    2 => Control::Pause,
                    3 => Control::Step,
                    4 => Control::Seek(r.u64("seek index")?),
                    5 => {
                        let rate = r.f32("rate")?;
                        Control::Rate(checked_rate(rate).map_err(|e| protocol_error(format!("control: {e}")))?)
                    }
                    6 => Control::Loop(r.bool("loop flag")?),
                    7 => Control::Delivery(r.delivery()?),
                    other => return Err(protocol_error(format!("control: unknown op {other}"))),
                })
            }
            KIND_RENDER_REQUEST => Message::RenderRequest(r.render_request()?),
            KIND_RENDER_REPLY => {
                let request_id = r.u32("request id")?;
                let outcome = match r.u8("render status")? {
                    0 => {
                        let width_px = r.u32("width")?;
                        let height_px = r.u32("height")?;
                        check_render_size(width_px, height_px, false, false).map_err(|e| protocol_error(format!("render reply: {e}")))?;
                        let depth_units_per_metre = r.f32("depth units per metre")?;
                        if !(depth_units_per_metre.is_finite() && depth_units_per_metre > 0.0) {
                            return Err(protocol_error(format!("render reply: depth units per metre must be finite and positive, not {depth_units_per_metre}")));
                        }
                        let radial = r.bool("radial flag")?;
                        let depth_encoding = r.wire_depth()?;
                        let depth_payload = r.blob("depth payload")?.to_vec();
                        let color_rgb8 = r.optional_image("colour payload", "RGB", 3, width_px, height_px)?;
                        let unknown_mask = r.optional_image("unknown mask", "mask", 1, width_px, height_px)?;
                        RenderOutcome::View(RenderedView { width_px, height_px, depth_units_per_metre, radial, depth_encoding, depth_payload, color_rgb8, unknown_mask })
                    }
                    status => {
                        let code = match status {
                            1 => RenderFailure::NoMap,
                            2 => RenderFailure::InvalidRequest,
                            3 => RenderFailure::RenderFailed,
                            other => return Err(protocol_error(format!("render reply: unknown status {other}"))),
                        };
                        RenderOutcome::Failed { code, message: r.text("render failure message")? }
                    }
                };
                Message::RenderReply { request_id, outcome }
            }
            other => return Err(protocol_error(format!("unknown message kind {other}"))),
        };
        if r.at != bytes.len() {
            return Err(protocol_error(format!("{} trailing bytes after the message", bytes.len() - r.at)));
        }
        Ok(message)
    }
}

/// Whether a `width_px` x `height_px` view (with colour: `color`, with the unknown mask:
/// `unknown`) is one the protocol carries.
fn check_render_size(width_px: u32, height_px: u32, color: bool, unknown: bool) -> std::result::Result<(), String> {
    if width_px == 0 || height_px == 0 || width_px > MAX_RENDER_SIDE_PX || height_px > MAX_RENDER_SIDE_PX {
        return Err(format!("image size {width_px}x{height_px} is outside 1..={MAX_RENDER_SIDE_PX} per side"));
    }
    let bytes = render_reply_bytes(width_px, height_px, color, unknown);
    if bytes > MAX_SERVER_MESSAGE_BYTES {
        return Err(format!(
            "a {width_px}x{height_px} view{}{} needs a {:.1} MiB reply, more than the {} MiB a server may send",
            if color { " with colour" } else { "" },
            if unknown { " and its unknown mask" } else { "" },
            bytes as f64 / 1048576.0,
            MAX_SERVER_MESSAGE_BYTES >> 20
        ));
    }
    Ok(())
}

fn delivery_id(delivery: Delivery) -> u8 {
    match delivery {
        Delivery::Lossless => 0,
        Delivery::Live => 1,
    }
}

struct Writer(Vec<u8>);

impl Writer {
    fn bytes(&mut self, b: &[u8]) {
        self.0.extend_from_slice(b);
    }
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
    fn i64(&mut self, v: i64) {
        self.bytes(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.bytes(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.bytes(&v.to_le_bytes());
    }
    /// Translation x, y, z then quaternion x, y, z, w, as f64.
    fn pose(&mut self, pose: &Se3) {
        let (t, q) = (pose.translation_m, pose.rotation);
        for v in [t.x, t.y, t.z, q.x, q.y, q.z, q.w] {
            self.f64(v);
        }
    }
    /// u16 length + UTF-8, cut at [`MAX_TEXT_BYTES`] on a character boundary.
    fn text(&mut self, s: &str) {
        let mut end = s.len().min(MAX_TEXT_BYTES);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        self.u16(end as u16);
        self.bytes(&s.as_bytes()[..end]);
    }
    /// u32 length + bytes.
    fn blob(&mut self, b: &[u8]) {
        self.u32(u32::try_from(b.len()).unwrap_or(u32::MAX));
        self.bytes(b);
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let remaining = self.bytes.len() - self.at;
        if n > remaining {
            return Err(protocol_error(format!("message truncated in the {what}: needs {n} bytes at offset {}, {remaining} left", self.at)));
        }
        let slice = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(slice)
    }
    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let mut out = [0_u8; N];
        out.copy_from_slice(self.take(N, what)?);
        Ok(out)
    }
    fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.take(1, what)?[0])
    }
    fn bool(&mut self, what: &str) -> Result<bool> {
        match self.u8(what)? {
            0 => Ok(false),
            1 => Ok(true),
            other => Err(protocol_error(format!("{what} must be 0 or 1, got {other}"))),
        }
    }
    fn u16(&mut self, what: &str) -> Result<u16> {
        Ok(u16::from_le_bytes(self.array(what)?))
    }
    fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
    fn u64(&mut self, what: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }
    fn i64(&mut self, what: &str) -> Result<i64> {
        Ok(i64::from_le_bytes(self.array(what)?))
    }
    fn f32(&mut self, what: &str) -> Result<f32> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }
    fn f64(&mut self, what: &str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }
    fn text(&mut self, what: &str) -> Result<String> {
        let len = usize::from(self.u16(what)?);
        if len > MAX_TEXT_BYTES {
            return Err(protocol_error(format!("{what} is {len} bytes, more than {MAX_TEXT_BYTES}")));
        }
        let bytes = self.take(len, what)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| protocol_error(format!("{what} is not UTF-8")))
    }
    fn blob(&mut self, what: &str) -> Result<&'a [u8]> {
        let len = self.u32(what)? as usize;
        self.take(len, what)
    }
    /// A render reply's optional per-pixel image (colour, the unknown mask): a flag, then a
    /// blob of exactly `bytes_per_pixel` bytes for each of the `width_px` x `height_px` pixels.
    fn optional_image(&mut self, what: &str, kind: &str, bytes_per_pixel: usize, width_px: u32, height_px: u32) -> Result<Option<Vec<u8>>> {
        if !self.bool(&format!("{what} flag"))? {
            return Ok(None);
        }
        let bytes = self.blob(what)?;
        let expected = bytes_per_pixel * width_px as usize * height_px as usize;
        if bytes.len() != expected {
            return Err(protocol_error(format!("render reply: {what} has {} bytes, {width_px}x{height_px} {kind} needs {expected}", bytes.len())));
        }
        Ok(Some(bytes.to_vec()))
    }
    /// A pose as [`Writer::pose`] writes it: finite, with a unit quaternion (to 1e-3, then
    /// normalised).
    fn pose(&mut self, what: &str) -> Result<Se3> {
        let mut v = [0.0_f64; 7];
        for slot in &mut v {
            *slot = self.f64(what)?;
        }
        let rotation = DQuat::from_xyzw(v[3], v[4], v[5], v[6]);
        if !v.iter().all(|x| x.is_finite()) || (rotation.length() - 1.0).abs() > 1e-3 {
            return Err(protocol_error(format!("{what} is not finite or its quaternion is not unit")));
        }
        Ok(Se3::new(rotation.normalize(), DVec3::new(v[0], v[1], v[2])))
    }
    fn wire_depth(&mut self) -> Result<WireDepth> {
        let id = self.u8("depth encoding")?;
        WireDepth::from_id(id).ok_or_else(|| protocol_error(format!("unknown depth encoding {id} (0 raw u16, 1 RVL, 2 RVL+DEFLATE)")))
    }
    /// A render request's body, every value checked.
    fn render_request(&mut self) -> Result<RenderRequest> {
        let invalid = |what: String| protocol_error(format!("render request: {what}"));
        let request_id = self.u32("request id")?;
        let world_from_camera = self.pose("render request: world_from_camera")?;
        let width_px = self.u32("width")?;
        let height_px = self.u32("height")?;
        let [fx_px, fy_px, cx_px, cy_px, depth_units_per_metre] = [self.f32("fx")?, self.f32("fy")?, self.f32("cx")?, self.f32("cy")?, self.f32("depth units per metre")?];
        if !([fx_px, fy_px, cx_px, cy_px].iter().all(|v| v.is_finite()) && fx_px > 0.0 && fy_px > 0.0) {
            return Err(invalid(format!("intrinsics fx {fx_px}, fy {fy_px}, cx {cx_px}, cy {cy_px} must be finite with positive focal lengths")));
        }
        if !(depth_units_per_metre.is_finite() && depth_units_per_metre > 0.0) {
            return Err(invalid(format!("depth units per metre must be finite and positive, not {depth_units_per_metre}")));
        }
        let radial = self.bool("radial flag")?;
        let color = self.bool("colour flag")?;
        let depth_encoding = self.wire_depth()?;
        let depth_range_m = if self.bool("depth range flag")? {
            let (near_m, far_m) = (self.f32("nearest depth")?, self.f32("farthest depth")?);
            if !(near_m.is_finite() && far_m.is_finite() && near_m >= 0.0 && far_m > near_m) {
                return Err(invalid(format!("depth range [{near_m}, {far_m}] m is empty or not finite")));
            }
            Some((near_m, far_m))
        } else {
            None
        };
        let noise = match self.u8("noise model")? {
            0 => None,
            1 => Some(RenderNoise { seed: self.u32("noise seed")?, frame_index: self.u32("noise frame index")? }),
            other => return Err(invalid(format!("unknown noise model {other} (0 none, 1 kinect)"))),
        };
        let unknown = self.bool("unknown mask flag")?;
        check_render_size(width_px, height_px, color, unknown).map_err(invalid)?;
        let intrinsics = PinholeIntrinsics { fx_px, fy_px, cx_px, cy_px, width_px, height_px };
        Ok(RenderRequest { request_id, world_from_camera, intrinsics, depth_units_per_metre, radial, depth_range_m, noise, color, unknown, depth_encoding })
    }
    fn delivery(&mut self) -> Result<Delivery> {
        match self.u8("delivery mode")? {
            0 => Ok(Delivery::Lossless),
            1 => Ok(Delivery::Live),
            other => Err(protocol_error(format!("unknown delivery mode {other}"))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::TUM_FREIBURG1;

    fn calibration() -> RgbdCalibration {
        RgbdCalibration { intrinsics: TUM_FREIBURG1, depth_units_per_metre: 5000.0 }
    }

    fn samples() -> Vec<Message> {
        vec![
            Message::Hello(Hello { source_name: "fr1_rpy ü".into(), frame_count: Some(100), calibration: calibration(), has_ground_truth: true, delivery: Delivery::Lossless, depth_noise: DepthNoise::KinectV1 }),
            Message::Hello(Hello { source_name: String::new(), frame_count: None, calibration: calibration(), has_ground_truth: false, delivery: Delivery::Live, depth_noise: DepthNoise::None }),
            Message::Frame(FrameMessage {
                sequence: 7,
                index: 3,
                depth_timestamp_ns: 1_305_031_910_765_238_000,
                color_timestamp_ns: -5,
                ground_truth: Some(Se3::new(DQuat::from_rotation_y(0.3), DVec3::new(1.0, -2.0, 0.5))),
                depth_codec: DepthCodec::Rvl,
                depth_payload: vec![1, 2, 3],
                color: WireColor::Coded(ColorCodec::Jpeg),
                color_payload: vec![9; 10],
            }),
            Message::Frame(FrameMessage {
                sequence: 0,
                index: 0,
                depth_timestamp_ns: 0,
                color_timestamp_ns: 0,
                ground_truth: None,
                depth_codec: DepthCodec::RvlDeflate,
                depth_payload: vec![],
                color: WireColor::Raw,
                color_payload: vec![],
            }),
            Message::Status(Status { state: PlaybackState::Ended, next_index: 100, rate: 1.5, looping: true, delivery: Delivery::Live, frames_sent: 90, frames_dropped: 10, frames_skipped: 3 }),
            Message::Error { code: ErrorCode::MalformedMessage, message: "bad".into() },
            Message::Control(Control::Play),
            Message::Control(Control::Pause),
            Message::Control(Control::Step),
            Message::Control(Control::Seek(42)),
            Message::Control(Control::Rate(0.0)),
            Message::Control(Control::Loop(true)),
            Message::Control(Control::Delivery(Delivery::Live)),
            Message::RenderRequest(render_request()),
            Message::RenderRequest(RenderRequest {
                request_id: 0,
                world_from_camera: Se3::IDENTITY,
                depth_range_m: None,
                noise: None,
                radial: false,
                color: false,
                unknown: false,
                depth_encoding: WireDepth::Coded(DepthCodec::RvlDeflate),
                ..render_request()
            }),
            Message::RenderReply {
                request_id: 9,
                outcome: RenderOutcome::View(RenderedView {
                    width_px: 2,
                    height_px: 1,
                    depth_units_per_metre: 5000.0,
                    radial: true,
                    depth_encoding: WireDepth::Raw,
                    depth_payload: vec![1, 0, 2, 0],
                    color_rgb8: Some(vec![7; 6]),
                    unknown_mask: Some(vec![255, 0]),
                }),
            },
            Message::RenderReply {
                request_id: u32::MAX,
                outcome: RenderOutcome::View(RenderedView {
                    width_px: 640,
                    height_px: 480,
                    depth_units_per_metre: 1000.0,
                    radial: false,
                    depth_encoding: WireDepth::Coded(DepthCodec::Rvl),
                    depth_payload: vec![3; 5],
                    color_rgb8: None,
                    unknown_mask: None,
                }),
            },
            Message::RenderReply { request_id: 1, outcome: RenderOutcome::Failed { code: RenderFailure::NoMap, message: "start the server with --map".into() } },
            Message::RenderReply { request_id: 2, outcome: RenderOutcome::Failed { code: RenderFailure::InvalidRequest, message: String::new() } },
            Message::RenderReply { request_id: 3, outcome: RenderOutcome::Failed { code: RenderFailure::RenderFailed, message: "lost".into() } },
        ]
    }

    fn render_request() -> RenderRequest {
        RenderRequest {
            request_id: 77,
            world_from_camera: Se3::new(DQuat::from_rotation_x(-0.4), DVec3::new(0.5, 1.2, -3.0)),
            intrinsics: TUM_FREIBURG1,
            depth_units_per_metre: 5000.0,
            radial: true,
            depth_range_m: Some((0.3, 6.0)),
            noise: Some(RenderNoise { seed: 5, frame_index: 12 }),
            color: true,
            unknown: true,
            depth_encoding: WireDepth::Raw,
        }
    }

    #[test]
    fn render_requests_with_bad_values_are_refused_by_name_and_their_id_is_still_read() {
        let bad = |f: &dyn Fn(&mut RenderRequest)| {
            let mut request = render_request();
            f(&mut request);
            let bytes = Message::RenderRequest(request).encode();
            assert_eq!(render_request_id(&bytes), Some(77), "the id is readable whatever follows");
            Message::decode(&bytes).expect_err("a bad request decoded").to_string()
        };
        type Spoil = dyn Fn(&mut RenderRequest);
        let cases: [(&str, &Spoil); 10] = [
            ("not finite", &|r| r.world_from_camera.translation_m.x = f64::NAN),
            ("not unit", &|r| r.world_from_camera.rotation = DQuat::from_xyzw(0.0, 0.0, 0.0, 2.0)),
            ("image size 0x480", &|r| r.intrinsics.width_px = 0),
            ("outside 1..=4096", &|r| r.intrinsics.height_px = 5000),
            ("more than the 16 MiB", &|r| (r.intrinsics.width_px, r.intrinsics.height_px) = (2048, 2048)),
            ("with colour and its unknown mask needs", &|r| (r.intrinsics.width_px, r.intrinsics.height_px) = (1700, 1700)),
            ("positive focal lengths", &|r| r.intrinsics.fx_px = -1.0),
            ("finite with", &|r| r.intrinsics.cy_px = f32::INFINITY),
            ("depth units per metre", &|r| r.depth_units_per_metre = 0.0),
            ("depth range [2, 1]", &|r| r.depth_range_m = Some((2.0, 1.0))),
        ];
        for (needle, f) in cases {
            let message = bad(f);
            assert!(message.contains(needle), "{needle:?} not in {message:?}");
        }
        // 2048x2048 fits without colour; the reply is the limit, not the side.
        let mut big = render_request();
        (big.intrinsics.width_px, big.intrinsics.height_px, big.color) = (2048, 2048, false);
        assert!(Message::decode(&Message::RenderRequest(big).encode()).is_ok(), "2048x2048 depth only");
        let mut noise = Message::RenderRequest(render_request()).encode();
        let noise_at = noise.len() - 10;
        noise[noise_at] = 2;
        assert!(Message::decode(&noise).expect_err("noise model 2").to_string().contains("noise model 2"));
        assert_eq!(render_request_id(&Message::Control(Control::Play).encode()), None, "not a render request");
        assert_eq!(render_request_id(&Message::RenderRequest(render_request()).encode()[..7]), None, "no whole id");
        let mut other_version = Message::RenderRequest(render_request()).encode();
        other_version[2] = PROTOCOL_VERSION + 1;
        assert_eq!(render_request_id(&other_version), None, "another version is not read");
    }

    #[test]
    fn rendered_depth_decodes_in_every_encoding_and_wrong_sizes_are_errors() {
        let depth = DepthImage::new(4, 3, (0..12).map(|i| i * 1000).collect()).expect("depth");
        for encoding in [WireDepth::Raw, WireDepth::Coded(DepthCodec::Rvl), WireDepth::Coded(DepthCodec::RvlDeflate)] {
            let view = RenderedView { width_px: 4, height_px: 3, depth_units_per_metre: 5000.0, radial: false, depth_encoding: encoding, depth_payload: encoding.encode(&depth), color_rgb8: None, unknown_mask: None };
            assert_eq!(view.depth_image().expect("decoding"), depth, "{encoding:?}");
            assert!(encoding.decode(&view.depth_payload, 4, 4).is_err(), "{encoding:?} at the wrong size");
        }
        assert_eq!(WireDepth::Raw.encode(&depth)[2..4], 1000_u16.to_le_bytes(), "raw is u16 little-endian, row-major");
        let mut short_color = Message::RenderReply {
            request_id: 1,
            outcome: RenderOutcome::View(RenderedView { width_px: 2, height_px: 1, depth_units_per_metre: 5000.0, radial: false, depth_encoding: WireDepth::Raw, depth_payload: vec![0; 4], color_rgb8: Some(vec![0; 5]), unknown_mask: None }),
        }
        .encode();
        assert!(Message::decode(&short_color).expect_err("5 bytes of colour for 2 pixels").to_string().contains("needs 6"));
        let long_mask = Message::RenderReply {
            request_id: 1,
            outcome: RenderOutcome::View(RenderedView { width_px: 2, height_px: 1, depth_units_per_metre: 5000.0, radial: false, depth_encoding: WireDepth::Raw, depth_payload: vec![0; 4], color_rgb8: None, unknown_mask: Some(vec![0; 3]) }),
        }
        .encode();
        assert!(Message::decode(&long_mask).expect_err("3 mask bytes for 2 pixels").to_string().contains("unknown mask has 3 bytes"));
        short_color[9..13].copy_from_slice(&0_u32.to_le_bytes());
        assert!(Message::decode(&short_color).is_err(), "a 0-pixel view");
    }

    #[test]
    fn every_message_round_trips() {
        for message in samples() {
            let bytes = message.encode();
            assert_eq!(Message::decode(&bytes).expect("decoding"), message, "round trip");
        }
    }

    #[test]
    fn every_truncation_and_extension_is_an_error() {
        for message in samples() {
            let bytes = message.encode();
            for len in 0..bytes.len() {
                assert!(Message::decode(&bytes[..len]).is_err(), "{message:?} cut to {len} bytes decoded");
            }
            let mut longer = bytes.clone();
            longer.push(0);
            assert!(Message::decode(&longer).is_err(), "trailing byte accepted");
        }
    }

    #[test]
    fn other_versions_are_rejected_by_name() {
        let mut bytes = Message::Control(Control::Play).encode();
        bytes[2] = PROTOCOL_VERSION + 1;
        let err = Message::decode(&bytes).expect_err("version 4 accepted");
        assert!(matches!(err, Error::ProtocolVersion { got: 4, supported: 3 }), "{err}");
        assert!(err.to_string().contains("version 4"), "{err}");
        // Older peers are refused by name too: version 1 (no skipped count in its status) and 2
        // (no unknown mask in render requests and replies).
        for old in [1, 2] {
            bytes[2] = old;
            assert!(matches!(Message::decode(&bytes), Err(Error::ProtocolVersion { got, supported: 3 }) if got == old), "version {old} accepted");
        }
    }

    #[test]
    fn invalid_fields_are_rejected() {
        let mut hello = Message::Hello(Hello { source_name: "sim".into(), frame_count: Some(3), calibration: calibration(), has_ground_truth: true, delivery: Delivery::Lossless, depth_noise: DepthNoise::None }).encode();
        let last = hello.len() - 1;
        assert_eq!(hello[last], 1, "the depth noise is the hello's last byte");
        hello[last] = 2;
        assert!(Message::decode(&hello).expect_err("depth noise 2").to_string().contains("unknown depth noise 2"));
        let mut rate = Message::Control(Control::Rate(1.0)).encode();
        rate[5..9].copy_from_slice(&(-1.0_f32).to_le_bytes());
        assert!(Message::decode(&rate).is_err(), "negative rate");
        rate[5..9].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(Message::decode(&rate).is_err(), "NaN rate");
        let mut op = Message::Control(Control::Play).encode();
        op[4] = 99;
        assert!(Message::decode(&op).is_err(), "unknown op");
        let mut kind = Message::Control(Control::Play).encode();
        kind[3] = 200;
        assert!(Message::decode(&kind).is_err(), "unknown kind");
        assert!(Message::decode(b"XX\x01\x10\x01").is_err(), "bad magic");
        // A blob length far beyond the message must fail without allocating it.
        let mut frame = samples()[3].encode();
        let depth_len_at = 4 + 8 + 8 + 8 + 8 + 1 + 1;
        frame[depth_len_at..depth_len_at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(Message::decode(&frame).is_err(), "huge blob length");
    }

    #[test]
    fn frame_images_decode_with_the_calibration() {
        let cal = calibration();
        let (w, h) = (cal.intrinsics.width_px, cal.intrinsics.height_px);
        let depth = DepthImage::new(w, h, (0..w * h).map(|i| (i % 7000) as u16).collect()).expect("depth");
        let color = ColorImage::new(w, h, (0..3 * w * h).map(|i| (i % 251) as u8).collect()).expect("colour");
        let message = FrameMessage {
            sequence: 0,
            index: 5,
            depth_timestamp_ns: 1,
            color_timestamp_ns: 2,
            ground_truth: None,
            depth_codec: DepthCodec::Rvl,
            depth_payload: DepthCodec::Rvl.encode(&depth),
            color: WireColor::Raw,
            color_payload: color.rgb8.clone(),
        };
        let frame = message.decode_images(&cal).expect("decoding");
        assert_eq!(frame.depth, depth, "depth");
        assert_eq!(frame.color, color, "colour");
        let mut short = message.clone();
        short.color_payload.pop();
        assert!(matches!(short.decode_images(&cal), Err(Error::Protocol { .. })), "short raw colour");
    }

    #[test]
    fn rates_from_people_and_urls_are_checked_as_the_decoder_checks_them() {
        assert_eq!(parse_rate(" 2.5 "), Ok(2.5), "spaces trimmed");
        assert_eq!(parse_rate("0"), Ok(0.0), "0: as fast as possible");
        assert_eq!(parse_rate("1000"), Ok(MAX_RATE), "the fastest");
        for bad in ["NaN", "nan", "inf", "-inf", "-1", "1000.5", "abc", ""] {
            assert!(parse_rate(bad).is_err(), "{bad:?} accepted");
        }
        // Whatever the page lets through, the bridge accepts.
        for rate in [0.0f32, 0.25, 1.0, 999.0, MAX_RATE] {
            let bytes = Message::Control(Control::Rate(rate)).encode();
            assert_eq!(Message::decode(&bytes).expect("a checked rate decodes"), Message::Control(Control::Rate(rate)));
        }
        let nan = Message::Control(Control::Rate(f32::NAN)).encode();
        assert!(Message::decode(&nan).is_err(), "NaN is refused on the wire too");
    }
}
