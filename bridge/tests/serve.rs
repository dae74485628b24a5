// SPDX-License-Identifier: MIT
//! `webfusion serve` over real WebSocket connections on 127.0.0.1: lossless replay is
//! bit-identical, seek/pause/step work, live delivery drops only for a slow client, a
//! malformed client closes alone, and the token, Origin and bind rules hold.

use std::io::BufRead as _;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use futures_util::{SinkExt as _, StreamExt as _};
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
use tokio_tungstenite::tungstenite::{self, Message as WsMessage};
use webfusion_core::codec::DepthCodec;
use webfusion_core::protocol::{Control, Delivery, ErrorCode, FrameMessage, Hello, Message, PlaybackState, Status, WireColor};
use webfusion_core::recording::RecordingReader;
use webfusion_core::source::{FrameSource, open_source};

const SAMPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/sample/fr1_rpy.wfr");
/// Longest wait for any one message; generous for a loaded CI machine.
const RECV_TIMEOUT: Duration = Duration::from_secs(60);

type Socket = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// A running `webfusion serve`, killed on drop. Its stderr is echoed and kept in `log`.
struct Server {
    child: Child,
    addr: String,
    log: std::sync::Arc<std::sync::Mutex<String>>,
}

impl Server {
    fn start(args: &[&str]) -> Server {
        let mut child = Command::new(env!("CARGO_BIN_EXE_webfusion"))
            .arg("serve")
            .args(["--bind", "127.0.0.1:0"])
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("starting webfusion serve");
        let log = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        let stderr = child.stderr.take().expect("stderr");
        let sink = std::sync::Arc::clone(&log);
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stderr).lines().map_while(Result::ok) {
                eprintln!("{line}");
                if let Ok(mut log) = sink.lock() {
                    log.push_str(&line);
                    log.push('\n');
                }
            }
        });
        let stdout = child.stdout.take().expect("stdout");
        let mut line = String::new();
        std::io::BufReader::new(stdout).read_line(&mut line).expect("reading the URL line");
        let addr = line.split("http://").nth(1).and_then(|rest| rest.split('/').next()).unwrap_or_else(|| panic!("no URL in {line:?}")).to_owned();
        Server { child, addr, log }
    }

    /// Waits (up to 30 s) until the server's stderr contains `needle`.
    async fn log_contains(&self, needle: &str) -> bool {
        for _ in 0..300 {
            if self.log.lock().is_ok_and(|log| log.contains(needle)) {
                return true;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        false
    }

    async fn connect(&self) -> Socket {
        self.connect_with("", None).await.expect("connecting")
    }

    async fn connect_with(&self, query: &str, origin: Option<&str>) -> Result<Socket, tungstenite::Error> {
        let mut request = format!("ws://{}/ws{query}", self.addr).into_client_request()?;
        if let Some(origin) = origin {
            request.headers_mut().insert("Origin", origin.parse().expect("origin header"));
        }
        let (socket, _) = tokio_tungstenite::connect_async(request).await?;
        Ok(socket)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

async fn send(socket: &mut Socket, control: Control) {
    socket.send(WsMessage::Binary(Message::Control(control).encode().into())).await.expect("sending a control");
}

/// The next protocol message, or `None` when the server closed.
async fn recv(socket: &mut Socket) -> Option<Message> {
    loop {
        let message = tokio::time::timeout(RECV_TIMEOUT, socket.next()).await.expect("timed out waiting for the server")?;
        match message.expect("WebSocket error") {
            WsMessage::Binary(bytes) => return Some(Message::decode(&bytes).expect("server sent a malformed message")),
            WsMessage::Close(_) => return None,
            _ => {}
        }
    }
}

/// The session's greeting: hello, then the initial paused status.
async fn hello(socket: &mut Socket) -> Hello {
    let hello = match recv(socket).await {
        Some(Message::Hello(hello)) => hello,
        other => panic!("expected hello, got {other:?}"),
    };
    match recv(socket).await {
        Some(Message::Status(status)) => assert_eq!((status.state, status.next_index), (PlaybackState::Paused, 0), "initial status"),
        other => panic!("expected the initial status, got {other:?}"),
    }
    hello
}

async fn next_frame(socket: &mut Socket) -> FrameMessage {
    loop {
        match recv(socket).await {
            Some(Message::Frame(frame)) => return frame,
            Some(Message::Status(_)) => {}
            other => panic!("expected a frame, got {other:?}"),
        }
    }
}

/// Reads frames until a status with `state`; returns the frames and that status.
async fn frames_until(socket: &mut Socket, state: PlaybackState) -> (Vec<FrameMessage>, Status) {
    let mut frames = Vec::new();
    loop {
        match recv(socket).await {
            Some(Message::Frame(frame)) => frames.push(frame),
            Some(Message::Status(status)) if status.state == state => return (frames, status),
            Some(Message::Status(_)) => {}
            other => panic!("expected frames and a status, got {other:?}"),
        }
    }
}

/// The first `frames` frames of the sample written as a TUM directory (PNGs and lists) in a
/// fresh temporary folder, removed on drop.
struct SampleTum {
    root: std::path::PathBuf,
    dir: std::path::PathBuf,
}

impl SampleTum {
    fn write(frames: usize) -> SampleTum {
        let root = std::env::temp_dir().join(format!("webfusion-serve-tum-{}", std::process::id()));
        std::fs::remove_dir_all(&root).ok();
        let dir = root.join("rgbd_dataset_freiburg1_rpy");
        let mut sample = RecordingReader::open(SAMPLE).expect("opening the sample");
        webfusion_core::io::tum::write_tum_dataset(&dir, &mut sample, 0..frames).expect("writing the sample as a TUM directory");
        SampleTum { root, dir }
    }
}

impl Drop for SampleTum {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.root).ok();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn lossless_replay_of_a_tum_directory_is_bit_identical() {
    let tum = SampleTum::write(40);
    let tum_dir = tum.dir.to_str().expect("a UTF-8 temp path");
    let server = Server::start(&["--source", tum_dir, "--color", "raw"]);
    let mut socket = server.connect().await;
    let hello = hello(&mut socket).await;
    let mut dataset = open_source(Path::new(tum_dir), None).expect("opening the TUM frames");
    assert_eq!(hello.frame_count, Some(dataset.frame_count() as u64), "frame count");
    assert_eq!(hello.calibration, dataset.calibration(), "calibration");
    assert!(hello.has_ground_truth, "ground truth flag");
    assert_eq!(hello.delivery, Delivery::Lossless, "default delivery");
    send(&mut socket, Control::Rate(0.0)).await;
    send(&mut socket, Control::Play).await;
    let (frames, status) = frames_until(&mut socket, PlaybackState::Ended).await;
    assert_eq!(frames.len(), dataset.frame_count(), "every frame arrives");
    assert_eq!(status.frames_dropped, 0, "lossless drops nothing");
    for (i, message) in frames.iter().enumerate() {
        assert_eq!((message.sequence, message.index), (i as u64, i as u64), "in order");
        assert_eq!((message.depth_codec, message.color), (DepthCodec::Rvl, WireColor::Raw), "wire codecs");
        let received = message.decode_images(&hello.calibration).expect("decoding a frame");
        let expected = dataset.read_frame(i).expect("reading the frame from disk");
        assert_eq!(received, expected, "frame {i} differs from the file");
    }
    let with_pose = frames.iter().filter(|f| f.ground_truth.is_some()).count();
    assert!(with_pose * 20 >= frames.len() * 19, "only {with_pose} of {} frames carry ground truth", frames.len());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recording_streams_its_own_bytes() {
    let server = Server::start(&["--source", SAMPLE]);
    let mut socket = server.connect().await;
    let hello = hello(&mut socket).await;
    let mut reader = RecordingReader::open(SAMPLE).expect("opening the sample");
    assert_eq!(hello.calibration, reader.calibration(), "calibration");
    for index in [0_u64, 37, 99] {
        send(&mut socket, Control::Seek(index)).await;
        send(&mut socket, Control::Step).await;
        let frame = next_frame(&mut socket).await;
        let stored = reader.read_encoded_frame(index as usize).expect("reading the stored frame");
        assert_eq!(frame.index, index, "seeked frame");
        assert_eq!((frame.depth_codec, frame.color), (reader.depth_codec(), WireColor::Coded(reader.color_codec())), "codecs passed through");
        assert_eq!((&frame.depth_payload, &frame.color_payload), (&stored.depth_payload, &stored.color_payload), "payload bytes of frame {index}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn seek_pause_and_step_control_playback() {
    let server = Server::start(&["--source", SAMPLE]);
    let mut socket = server.connect().await;
    hello(&mut socket).await;
    send(&mut socket, Control::Seek(50)).await;
    send(&mut socket, Control::Step).await;
    let (frames, status) = frames_until(&mut socket, PlaybackState::Paused).await;
    // The first Paused status answers the seek; the step's frame and status follow.
    assert!(frames.is_empty(), "a frame before the step: {:?}", frames.iter().map(|f| f.index).collect::<Vec<_>>());
    assert_eq!(status.next_index, 50, "after seek");
    assert_eq!(next_frame(&mut socket).await.index, 50, "step sends the seeked frame");
    send(&mut socket, Control::Step).await;
    assert_eq!(next_frame(&mut socket).await.index, 51, "the next step sends the next frame");
    // Nothing else arrives while paused.
    let quiet = tokio::time::timeout(Duration::from_millis(800), async {
        loop {
            if let Some(Message::Frame(frame)) = recv(&mut socket).await {
                return frame.index;
            }
        }
    })
    .await;
    assert!(quiet.is_err(), "frame {quiet:?} arrived while paused");
    // Play as fast as the client reads from 90 to the end, then nothing more.
    send(&mut socket, Control::Seek(90)).await;
    send(&mut socket, Control::Rate(0.0)).await;
    send(&mut socket, Control::Play).await;
    let (frames, status) = frames_until(&mut socket, PlaybackState::Ended).await;
    assert_eq!(frames.iter().map(|f| f.index).collect::<Vec<_>>(), (90..100).collect::<Vec<_>>(), "frames 90..100");
    assert_eq!(status.next_index, 0, "ended rewinds");
    // Looping plays past the end.
    send(&mut socket, Control::Seek(98)).await;
    send(&mut socket, Control::Loop(true)).await;
    send(&mut socket, Control::Play).await;
    let indices: Vec<u64> = {
        let mut v = Vec::new();
        while v.len() < 4 {
            v.push(next_frame(&mut socket).await.index);
        }
        v
    };
    assert_eq!(indices, [98, 99, 0, 1], "looping");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn live_delivery_drops_frames_for_a_slow_client_only() {
    // A queue of 8 frames (0.5 s at 15 frames/s) absorbs scheduling stalls of a loaded CI
    // machine for the fast reader; the slow reader falls seconds behind and must drop.
    let server = Server::start(&["--source", SAMPLE, "--live-queue", "8"]);
    let mut fast = server.connect().await;
    let mut slow = server.connect().await;
    for socket in [&mut fast, &mut slow] {
        hello(socket).await;
        send(socket, Control::Delivery(Delivery::Live)).await;
        // Half the recorded rate (15 frames/s) leaves the fast reader slack on a loaded machine.
        send(socket, Control::Rate(0.5)).await;
        send(socket, Control::Play).await;
    }
    let fast_task = tokio::spawn(async move { frames_until(&mut fast, PlaybackState::Ended).await });
    // The slow client takes 300 ms per message for the first 5 s, then drains.
    let start = tokio::time::Instant::now();
    let mut slow_frames = Vec::new();
    let slow_status = loop {
        match recv(&mut slow).await {
            Some(Message::Frame(frame)) => slow_frames.push(frame.sequence),
            Some(Message::Status(status)) if status.state == PlaybackState::Ended => break status,
            Some(_) => {}
            None => panic!("server closed the slow client"),
        }
        if start.elapsed() < Duration::from_secs(5) {
            tokio::time::sleep(Duration::from_millis(300)).await;
        }
    };
    let (fast_frames, fast_status) = fast_task.await.expect("fast client task");
    assert_eq!(fast_frames.len(), 100, "the fast client got every frame (dropped {})", fast_status.frames_dropped);
    assert_eq!(fast_status.frames_dropped, 0, "fast client drops");
    assert!(slow_status.frames_dropped > 0, "the slow client dropped nothing; received {}", slow_frames.len());
    assert_eq!(slow_frames.len() as u64 + slow_status.frames_dropped, 100, "received + dropped = produced");
    assert!(slow_frames.windows(2).all(|w| w[0] < w[1]), "sequence numbers increase");
    assert!(slow_frames.windows(2).any(|w| w[1] > w[0] + 1), "gaps in the sequence show the drops");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_malformed_client_is_closed_alone() {
    let server = Server::start(&["--source", SAMPLE]);
    let mut good = server.connect().await;
    hello(&mut good).await;
    for (bytes, code) in [
        (b"hello".to_vec(), ErrorCode::MalformedMessage),
        ({
            let mut b = Message::Control(Control::Play).encode();
            b[2] = 9;
            b
        }, ErrorCode::UnsupportedVersion),
        (Message::Control(Control::Seek(100)).encode(), ErrorCode::InvalidControl),
        (vec![0; 4096], ErrorCode::MalformedMessage),
    ] {
        let mut bad = server.connect().await;
        hello(&mut bad).await;
        bad.send(WsMessage::Binary(bytes.into())).await.ok();
        let mut error = None;
        while let Some(message) = tokio::time::timeout(RECV_TIMEOUT, bad.next()).await.expect("timed out") {
            match message {
                Ok(WsMessage::Binary(b)) => {
                    if let Ok(Message::Error { code, message }) = Message::decode(&b) {
                        error = Some((code, message));
                    }
                }
                Ok(WsMessage::Close(frame)) => {
                    let frame = frame.expect("close frame with a reason");
                    assert!(!frame.reason.is_empty(), "empty close reason");
                    break;
                }
                Ok(_) => {}
                Err(_) => break,
            }
        }
        if code != ErrorCode::MalformedMessage || error.is_some() {
            // Oversized messages are cut by the WebSocket layer before the protocol sees them.
            let (got, text) = error.expect("an error message before the close");
            assert_eq!(got, code, "error code: {text}");
        }
        // The well-behaved client is unaffected.
        send(&mut good, Control::Step).await;
        next_frame(&mut good).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn token_and_origin_are_enforced() {
    let server = Server::start(&["--source", SAMPLE, "--token", "s3cret", "--allow-origin", "https://viewer.example"]);
    for query in ["", "?token=wrong", "?token=s3cre"] {
        match server.connect_with(query, None).await {
            Err(tungstenite::Error::Http(response)) => assert_eq!(response.status(), 401, "query {query:?}"),
            other => panic!("query {query:?} connected: {:?}", other.map(|_| ())),
        }
    }
    match server.connect_with("?token=s3cret", Some("http://evil.example")).await {
        Err(tungstenite::Error::Http(response)) => assert_eq!(response.status(), 403, "foreign origin"),
        other => panic!("foreign origin connected: {:?}", other.map(|_| ())),
    }
    let same_origin = format!("http://{}", server.addr);
    for origin in [None, Some("https://viewer.example"), Some(same_origin.as_str())] {
        let mut socket = server.connect_with("?token=s3cret", origin).await.unwrap_or_else(|e| panic!("origin {origin:?}: {e}"));
        hello(&mut socket).await;
    }
}

#[test]
fn binding_beyond_loopback_needs_a_token() {
    let output = Command::new(env!("CARGO_BIN_EXE_webfusion")).args(["serve", "--source", SAMPLE, "--bind", "0.0.0.0:0"]).output().expect("running");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "served on 0.0.0.0 without a token");
    assert!(stderr.contains("--token") && !stderr.contains("panicked"), "{stderr}");
    let output = Command::new(env!("CARGO_BIN_EXE_webfusion")).args(["serve", "--source", "/nonexistent.wfr"]).output().expect("running");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success() && stderr.contains("/nonexistent.wfr") && !stderr.contains("panicked"), "{stderr}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn static_files_are_served_from_the_web_dir_only() {
    let web_dir = std::env::temp_dir().join(format!("webfusion-serve-web-{}", std::process::id()));
    std::fs::create_dir_all(&web_dir).expect("web dir");
    std::fs::write(web_dir.join("index.html"), "<!doctype html><title>webfusion</title>").expect("index");
    std::fs::write(web_dir.join("app.wasm"), b"\0asm").expect("wasm");
    let server = Server::start(&["--source", SAMPLE, "--web-dir", web_dir.to_str().expect("utf-8")]);
    let get = |path: &'static str| {
        let addr = server.addr.clone();
        async move {
            let mut stream = tokio::net::TcpStream::connect(&addr).await.expect("connecting");
            stream.write_all(format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes()).await.expect("request");
            let mut response = String::new();
            stream.read_to_string(&mut response).await.expect("response");
            response
        }
    };
    let index = get("/").await;
    assert!(index.starts_with("HTTP/1.1 200") && index.contains("<title>webfusion</title>") && index.contains("text/html"), "{index}");
    let wasm = get("/app.wasm").await;
    assert!(wasm.starts_with("HTTP/1.1 200") && wasm.contains("application/wasm"), "{wasm}");
    for path in ["/../Cargo.toml", "/%2e%2e/Cargo.toml", "/.hidden", "/missing.js"] {
        let response = get(path).await;
        assert!(response.starts_with("HTTP/1.1 404") || response.starts_with("HTTP/1.1 400"), "{path}: {response}");
    }
    let _ = std::fs::remove_dir_all(&web_dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_corrupt_frame_closes_its_session_with_the_reason_and_the_server_lives_on() {
    let path = std::env::temp_dir().join(format!("webfusion-serve-corrupt-{}.wfr", std::process::id()));
    let mut bytes = std::fs::read(SAMPLE).expect("reading the sample");
    // Past the 64-byte header: inside frame 0's record, so its CRC check fails when read.
    bytes[300..304].copy_from_slice(&[0xff; 4]);
    std::fs::write(&path, bytes).expect("writing the corrupt copy");
    let server = Server::start(&["--source", path.to_str().expect("utf-8")]);
    let mut socket = server.connect().await;
    hello(&mut socket).await;
    send(&mut socket, Control::Step).await;
    let mut reply = recv(&mut socket).await;
    while let Some(Message::Status(_)) = reply {
        reply = recv(&mut socket).await;
    }
    match reply {
        Some(Message::Error { code, message }) => {
            assert_eq!(code, ErrorCode::SourceFailed, "{message}");
            assert!(message.contains("frame 0") && message.contains("CRC") && message.contains("--skip-corrupt"), "{message}");
        }
        other => panic!("expected an error naming the frame, got {other:?}"),
    }
    assert!(recv(&mut socket).await.is_none(), "the session closes after the error");
    // Other frames of the same file still stream to a new client.
    let mut other = server.connect().await;
    hello(&mut other).await;
    send(&mut other, Control::Seek(1)).await;
    send(&mut other, Control::Step).await;
    assert_eq!(next_frame(&mut other).await.index, 1, "frame 1 after the corrupt frame 0");
    let _ = std::fs::remove_file(&path);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn skip_corrupt_skips_damaged_frames_and_counts_them_in_the_status() {
    let path = std::env::temp_dir().join(format!("webfusion-serve-skip-{}.wfr", std::process::id()));
    let mut bytes = std::fs::read(SAMPLE).expect("reading the sample");
    // A payload byte of frames 0 and 50 (found by their record headers: magic, then index).
    for index in [0_u32, 50] {
        let mut head = b"WFRF".to_vec();
        head.extend_from_slice(&index.to_le_bytes());
        let at = bytes.windows(8).position(|w| w == head.as_slice()).unwrap_or_else(|| panic!("record {index}"));
        bytes[at + 36 + 10] ^= 0x5a;
    }
    std::fs::write(&path, &bytes).expect("writing the damaged copy");
    let server = Server::start(&["--source", path.to_str().expect("utf-8"), "--skip-corrupt"]);
    let mut socket = server.connect().await;
    hello(&mut socket).await;
    // A step over the damaged frame 0 delivers frame 1.
    send(&mut socket, Control::Step).await;
    assert_eq!(next_frame(&mut socket).await.index, 1, "the step goes on to the next readable frame");
    send(&mut socket, Control::Rate(0.0)).await;
    send(&mut socket, Control::Play).await;
    let (frames, status) = frames_until(&mut socket, PlaybackState::Ended).await;
    let indices: Vec<u64> = frames.iter().map(|f| f.index).collect();
    let want: Vec<u64> = (2..100).filter(|&i| i != 50).collect();
    assert_eq!(indices, want, "every readable frame, in order");
    assert_eq!(status.frames_skipped, 2, "both damaged frames counted");
    let mut original = RecordingReader::open(SAMPLE).expect("the sample");
    for frame in frames.iter().step_by(16) {
        let encoded = original.read_encoded_frame(frame.index as usize).expect("original frame");
        assert_eq!((&frame.depth_payload, &frame.color_payload), (&encoded.depth_payload, &encoded.color_payload), "frame {} unchanged", frame.index);
    }
    assert!(server.log_contains("skipping a damaged frame").await, "the server says what it skipped");
    let _ = std::fs::remove_file(&path);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_vanishing_mid_stream_does_not_disturb_the_others() {
    let server = Server::start(&["--source", SAMPLE]);
    let mut steady = server.connect().await;
    hello(&mut steady).await;
    for _ in 0..3 {
        let mut leaver = server.connect().await;
        hello(&mut leaver).await;
        send(&mut leaver, Control::Rate(0.0)).await;
        send(&mut leaver, Control::Play).await;
        next_frame(&mut leaver).await;
        // Drop the TCP connection without a close handshake while frames are in flight.
        drop(leaver);
        send(&mut steady, Control::Step).await;
        next_frame(&mut steady).await;
    }
    send(&mut steady, Control::Rate(0.0)).await;
    send(&mut steady, Control::Play).await;
    let (frames, _) = frames_until(&mut steady, PlaybackState::Ended).await;
    assert_eq!(frames.first().map(|f| f.index), Some(3), "continues after the three steps");
    assert_eq!(frames.len(), 97, "every remaining frame");
    // The vanished clients' failed sends are reported in the server's log, not dropped.
    assert!(server.log_contains("sending failed, session ended").await, "log: {}", server.log.lock().map(|l| l.clone()).unwrap_or_default());
}

/// `serve`'s calibration flags for OpenNI2's Dummy device (it reports no field of view).
#[cfg(feature = "openni2")]
const DUMMY_CALIBRATION: [&str; 4] = ["--intrinsics", "285,285,159.5,119.5,320,240", "--depth-scale", "1000"];

/// A live camera (OpenNI2's Dummy device, no hardware needed) streams to every playing client
/// from the newest frame on, with the camera's own frame numbers; it refuses to seek.
#[cfg(feature = "openni2")]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_live_camera_streams_to_each_playing_client() {
    let mut args = vec!["--source", "openni2:Dummy"];
    args.extend(DUMMY_CALIBRATION);
    let server = Server::start(&args);
    let (mut a, mut b) = (server.connect().await, server.connect().await);
    for socket in [&mut a, &mut b] {
        match recv(socket).await {
            Some(Message::Hello(hello)) => {
                assert_eq!(hello.frame_count, None, "a camera has no end");
                assert_eq!(hello.delivery, Delivery::Live, "live by default");
                assert_eq!((hello.calibration.intrinsics.width_px, hello.calibration.intrinsics.height_px), (320, 240), "Dummy size");
                assert!(hello.source_name.contains("Dummy"), "{}", hello.source_name);
            }
            other => panic!("expected hello, got {other:?}"),
        }
        assert!(matches!(recv(socket).await, Some(Message::Status(Status { state: PlaybackState::Paused, .. }))), "starts paused");
    }
    send(&mut a, Control::Play).await;
    let frames: Vec<FrameMessage> = {
        let mut frames = Vec::new();
        while frames.len() < 6 {
            frames.push(next_frame(&mut a).await);
        }
        frames
    };
    for pair in frames.windows(2) {
        assert!(pair[1].sequence > pair[0].sequence, "camera frame numbers increase");
        assert!(pair[1].depth_timestamp_ns > pair[0].depth_timestamp_ns, "timestamps increase");
    }
    let hello_calibration = webfusion_core::RgbdCalibration {
        intrinsics: webfusion_core::PinholeIntrinsics { fx_px: 285.0, fy_px: 285.0, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 },
        depth_units_per_metre: 1000.0,
    };
    let decoded = frames[0].decode_images(&hello_calibration).expect("a live frame decodes");
    assert_eq!((decoded.depth.width_px, decoded.color.width_px, decoded.depth.units.len()), (320, 320, 320 * 240), "decoded sizes");
    // b never pressed play: it got nothing but may still step one frame.
    send(&mut b, Control::Step).await;
    let stepped = loop {
        match recv(&mut b).await {
            Some(Message::Frame(frame)) => break frame,
            Some(Message::Status(_)) => {}
            other => panic!("expected a stepped frame, got {other:?}"),
        }
    };
    assert!(stepped.sequence > frames[0].sequence, "a step delivers a current frame, not an old one");
    // Seeking a camera is refused with the reason, and closes only that client.
    send(&mut b, Control::Seek(0)).await;
    let refused = loop {
        match recv(&mut b).await {
            Some(Message::Error { code, message }) => break (code, message),
            Some(Message::Frame(_) | Message::Status(_)) => {}
            other => panic!("expected an error, got {other:?}"),
        }
    };
    assert_eq!(refused.0, ErrorCode::InvalidControl, "{}", refused.1);
    assert!(refused.1.contains("cannot seek"), "{}", refused.1);
    let after = next_frame(&mut a).await;
    assert!(after.sequence > frames[5].sequence, "a keeps streaming");
}

/// A missing camera fails at start-up with what to check, not at the first client.
#[cfg(feature = "openni2")]
#[test]
fn a_missing_camera_is_a_clear_start_up_error() {
    let output = Command::new(env!("CARGO_BIN_EXE_webfusion"))
        .args(["serve", "--bind", "127.0.0.1:0", "--source", "openni2:no-such-camera"])
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("running webfusion serve");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "serve must not start: {stderr}");
    assert!(stderr.contains("openni2:no-such-camera") && stderr.contains("webfusion devices") && !stderr.contains("panicked"), "{stderr}");
}
