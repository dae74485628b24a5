// SPDX-License-Identifier: MIT
//! `webfusion serve --map` answers render requests over real WebSocket connections: a view at
//! a pose is the very frame `webfusion simulate` writes at that pose (exact and with seeded
//! Kinect noise, depth and colour), two clients are answered side by side, a bad request gets
//! a failed reply naming the problem and the session goes on, a server without a map says so,
//! a damaged map stops the server before it listens, the unknown masks of a server given the
//! map's occupancy grid are the ones `simulate --occupancy` writes, and the stdlib Python client
//! (`scripts/render_client.py`) gets the same views and masks.

use std::io::BufRead as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use futures_util::{SinkExt as _, StreamExt as _};
use tokio_tungstenite::tungstenite::Message as WsMessage;
use webfusion_core::codec::DepthCodec;
use webfusion_core::codec::png::{decode_depth16, decode_rgb8};
use webfusion_core::io::trajectory::{TimedPose, format_tum_trajectory};
use webfusion_core::protocol::{Message, PROTOCOL_VERSION, RenderFailure, RenderNoise, RenderOutcome, RenderRequest, RenderedView, WireDepth};
use webfusion_core::{PinholeIntrinsics, Se3};

mod common;
use common::{fused_room, ok, s, scratch, webfusion};

const RECV_TIMEOUT: Duration = Duration::from_secs(120);
const W: u32 = 160;
const H: u32 = 120;
/// The camera the views are asked for (not the room camera's, to prove the request's are used).
const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 120.0, fy_px: 122.0, cx_px: 81.0, cy_px: 58.5, width_px: W, height_px: H };
const K_ARG: &str = "120,122,81,58.5";
const SEED: u32 = 3;

type Socket = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// A room fused at its exact poses and saved, with the poses and `simulate`'s frames at the
/// first three of them (exact, and with Kinect noise of seed [`SEED`]), the map's occupancy
/// grid carved from those poses and `simulate --occupancy`'s unknown masks, built once.
struct Fixture {
    dir: PathBuf,
    map: PathBuf,
    room: PathBuf,
    poses: Vec<TimedPose>,
    grid: PathBuf,
}

fn fixture() -> &'static Fixture {
    static FIXTURE: std::sync::OnceLock<Fixture> = std::sync::OnceLock::new();
    FIXTURE.get_or_init(|| {
        let dir = scratch("render");
        let common::FusedRoom { room, gt, map, poses: all_poses, .. } = fused_room(&dir, 24, "0.04");
        let poses: Vec<TimedPose> = [0, 11, 23].iter().map(|&i| gt[i]).collect();
        let views = dir.join("views.txt");
        std::fs::write(&views, format_tum_trajectory(&poses)).expect("view poses");
        let size = format!("{W}x{H}");
        ok(&["simulate", "--map", s(&map), "--poses", s(&views), "--out", s(&dir.join("exact")), "--image-size", &size, "--intrinsics", K_ARG, "--color"]);
        ok(&["simulate", "--map", s(&map), "--poses", s(&views), "--out", s(&dir.join("noisy")), "--image-size", &size, "--intrinsics", K_ARG, "--noise", "kinect", "--seed", &SEED.to_string()]);
        // The room (x ±2, y -1..1.5, z ±2) and 0.5 m around it in 5 cm cells, carved from the
        // poses the map was fused at.
        let grid = dir.join("grid.json");
        ok(&["export-occupancy", "--map", s(&map), "--out", s(&dir.join("grid.bin")), "--voxel-size", "0.05", "--dims", "100,70,100", "--center", "0,0.25,0", "--poses", s(&all_poses)]);
        ok(&["simulate", "--map", s(&map), "--poses", s(&views), "--out", s(&dir.join("unknown")), "--image-size", &size, "--intrinsics", K_ARG, "--occupancy", s(&grid)]);
        Fixture { dir, map, room, poses, grid }
    })
}

/// The `i`-th frame `simulate` wrote into `sim` (depth, and colour when it wrote colour).
fn simulated(sim: &Path, i: usize) -> (Vec<u16>, Option<Vec<u8>>) {
    let entry = |list: &str| {
        let text = std::fs::read_to_string(sim.join(list)).ok()?;
        let name = text.lines().filter(|l| !l.starts_with('#')).nth(i)?.split_whitespace().nth(1)?.to_owned();
        std::fs::read(sim.join(name)).ok()
    };
    let depth = decode_depth16(&entry("depth.txt").expect("a simulated depth frame"), W, H).expect("depth png").units;
    let color = entry("rgb.txt").map(|png| decode_rgb8(&png, W, H).expect("rgb png").rgb8);
    (depth, color)
}

/// A running `webfusion serve`, killed on drop.
struct Server {
    child: Child,
    addr: String,
}

impl Server {
    fn start(args: &[&str]) -> Server {
        let mut child = Command::new(env!("CARGO_BIN_EXE_webfusion"))
            .args(["serve", "--bind", "127.0.0.1:0"])
            .args(args)
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("starting webfusion serve");
        let mut line = String::new();
        std::io::BufReader::new(child.stdout.take().expect("stdout")).read_line(&mut line).expect("reading the URL line");
        let addr = line.split("http://").nth(1).and_then(|rest| rest.split('/').next()).unwrap_or_else(|| panic!("no URL in {line:?}")).to_owned();
        Server { child, addr }
    }

    fn url(&self) -> String {
        format!("ws://{}/ws", self.addr)
    }

    async fn connect(&self) -> Socket {
        tokio_tungstenite::connect_async(self.url()).await.expect("connecting").0
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn request(id: u32, pose: &Se3) -> RenderRequest {
    RenderRequest {
        request_id: id,
        world_from_camera: *pose,
        intrinsics: K,
        depth_units_per_metre: 5000.0,
        radial: false,
        depth_range_m: None,
        noise: None,
        color: false,
        unknown: false,
        depth_encoding: WireDepth::Raw,
    }
}

/// The `i`-th unknown mask `simulate --occupancy` wrote into `sim` (255 marked, 0 not).
fn simulated_mask(sim: &Path, i: usize) -> Vec<u8> {
    let text = std::fs::read_to_string(sim.join("unknown.txt")).expect("unknown.txt");
    let name = text.lines().filter(|l| !l.starts_with('#')).nth(i).and_then(|l| l.split_whitespace().nth(1)).expect("a mask per frame").to_owned();
    // The 8-bit grey PNG, read through the RGB decoder (grey expands to three equal channels).
    decode_rgb8(&std::fs::read(sim.join(name)).expect("mask png"), W, H).expect("an 8-bit mask").rgb8.chunks(3).map(|c| c[0]).collect()
}

/// The reply to request `id`, skipping the session's hello and status.
async fn reply(socket: &mut Socket, id: u32) -> RenderOutcome {
    loop {
        let message = tokio::time::timeout(RECV_TIMEOUT, socket.next()).await.expect("timed out waiting for the server").expect("the server closed").expect("WebSocket error");
        let WsMessage::Binary(bytes) = message else { continue };
        match Message::decode(&bytes).expect("the server sent a malformed message") {
            Message::RenderReply { request_id, outcome } => {
                assert_eq!(request_id, id, "replies come in request order");
                return outcome;
            }
            Message::Error { code, message } => panic!("the server closed the session: {code:?} {message}"),
            _ => {}
        }
    }
}

async fn render(socket: &mut Socket, request: RenderRequest) -> RenderOutcome {
    let id = request.request_id;
    socket.send(WsMessage::Binary(Message::RenderRequest(request).encode().into())).await.expect("sending a request");
    reply(socket, id).await
}

fn view(outcome: RenderOutcome) -> RenderedView {
    match outcome {
        RenderOutcome::View(view) => view,
        RenderOutcome::Failed { code, message } => panic!("no view: {code:?} {message}"),
    }
}

fn failure(outcome: RenderOutcome) -> (RenderFailure, String) {
    match outcome {
        RenderOutcome::Failed { code, message } => (code, message),
        RenderOutcome::View(_) => panic!("a view where a failure was expected"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn render_requests_answer_with_the_views_simulate_writes() {
    let fx = fixture();
    let server = Server::start(&["--source", s(&fx.room), "--map", s(&fx.map)]);
    let mut a = server.connect().await;
    let mut b = server.connect().await;

    // Exact depth and colour at every pose: the frames `simulate` wrote, bit for bit, in every
    // depth encoding.
    for (i, pose) in fx.poses.iter().enumerate() {
        let (depth, color) = simulated(&fx.dir.join("exact"), i);
        assert!(depth.iter().filter(|&&u| u > 0).count() > depth.len() / 2, "the room fills the view");
        let encoding = [WireDepth::Raw, WireDepth::Coded(DepthCodec::Rvl), WireDepth::Coded(DepthCodec::RvlDeflate)][i];
        let got = view(render(&mut a, RenderRequest { color: true, depth_encoding: encoding, ..request(10 + i as u32, &pose.world_from_camera) }).await);
        assert_eq!((got.width_px, got.height_px, got.depth_encoding, got.radial), (W, H, encoding, false));
        assert!(got.depth_image().expect("depth decodes").units == depth, "view {i} ({encoding:?}) is simulate's frame");
        assert!(got.color_rgb8 == color, "view {i}'s colour is simulate's");
    }

    // With seeded Kinect noise: simulate's noisy frames, whose noise index is the frame's.
    for (i, pose) in fx.poses.iter().enumerate() {
        let (depth, _) = simulated(&fx.dir.join("noisy"), i);
        let noise = Some(RenderNoise { seed: SEED, frame_index: i as u32 });
        let got = view(render(&mut b, RenderRequest { noise, ..request(20 + i as u32, &pose.world_from_camera) }).await);
        assert!(got.depth_image().expect("depth").units == depth, "noisy view {i} is simulate's");
        assert!(got.color_rgb8.is_none(), "no colour unless asked");
    }
    // Negative control: another seed gives another view (the comparison above can fail).
    let (noisy0, _) = simulated(&fx.dir.join("noisy"), 0);
    let other = view(render(&mut b, RenderRequest { noise: Some(RenderNoise { seed: SEED + 1, frame_index: 0 }), ..request(30, &fx.poses[0].world_from_camera) }).await);
    assert!(other.depth_image().expect("depth").units != noisy0, "a different seed changed nothing");

    // Two clients at once, each answered with its own view.
    let (pa, pb) = (&fx.poses[1].world_from_camera, &fx.poses[2].world_from_camera);
    a.send(WsMessage::Binary(Message::RenderRequest(request(40, pa)).encode().into())).await.expect("send");
    b.send(WsMessage::Binary(Message::RenderRequest(request(41, pb)).encode().into())).await.expect("send");
    let (ra, rb) = tokio::join!(reply(&mut a, 40), reply(&mut b, 41));
    assert!(view(ra).depth_image().expect("depth").units == simulated(&fx.dir.join("exact"), 1).0, "client a's view");
    assert!(view(rb).depth_image().expect("depth").units == simulated(&fx.dir.join("exact"), 2).0, "client b's view");

    // Radial distance is longer than z depth off the optical axis, equal on it.
    let z = view(render(&mut a, request(50, pa)).await).depth_image().expect("depth").units;
    let r = view(render(&mut a, RenderRequest { radial: true, ..request(51, pa) }).await).depth_image().expect("depth").units;
    let corner = (0..(W * H) as usize).find(|&p| z[p] > 0 && r[p] > 0).expect("a return near the corner");
    assert!(r[corner] > z[corner], "radial {} vs z {} at pixel {corner}", r[corner], z[corner]);

    // Bad requests: a failed reply naming the problem, and the session goes on.
    let mut nan = Message::RenderRequest(request(60, pa)).encode();
    nan[8..16].copy_from_slice(&f64::NAN.to_le_bytes());
    a.send(WsMessage::Binary(nan.into())).await.expect("send");
    let (code, message) = failure(reply(&mut a, 60).await);
    assert!(code == RenderFailure::InvalidRequest && message.contains("not finite"), "{code:?} {message}");
    let (code, message) = failure(render(&mut a, RenderRequest { depth_range_m: Some((0.4, 20.0)), ..request(61, pa) }).await);
    assert!(code == RenderFailure::InvalidRequest && message.contains("u16"), "a range past the u16 scale: {code:?} {message}");
    let (code, message) = failure(render(&mut a, RenderRequest { intrinsics: PinholeIntrinsics { width_px: 5000, ..K }, ..request(62, pa) }).await);
    assert!(code == RenderFailure::InvalidRequest && message.contains("5000x120"), "{code:?} {message}");
    let again = view(render(&mut a, request(63, pa)).await);
    assert!(again.depth_image().expect("depth").units == z, "the session still renders after bad requests");

    // A render request of another version is not answered but refused, as any other message.
    let mut foreign = Message::RenderRequest(request(70, pa)).encode();
    foreign[2] = PROTOCOL_VERSION + 1;
    a.send(WsMessage::Binary(foreign.into())).await.expect("send");
    let closed = loop {
        let message = tokio::time::timeout(RECV_TIMEOUT, a.next()).await.expect("timed out");
        match message {
            Some(Ok(WsMessage::Binary(bytes))) => {
                if let Ok(Message::Error { message, .. }) = Message::decode(&bytes) {
                    break message;
                }
            }
            Some(Ok(_)) => {}
            None | Some(Err(_)) => panic!("closed without an error message"),
        }
    };
    assert!(closed.contains("version"), "{closed}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unknown_masks_are_the_ones_simulate_writes() {
    let fx = fixture();
    let server = Server::start(&["--source", s(&fx.room), "--map", s(&fx.map), "--occupancy", s(&fx.grid)]);
    let mut socket = server.connect().await;
    for (i, pose) in fx.poses.iter().enumerate() {
        let want = simulated_mask(&fx.dir.join("unknown"), i);
        let marked = want.iter().filter(|&&m| m == 255).count();
        // Negative control: the comparison can fail (some pixels marked, not all).
        assert!(marked > 0 && marked < want.len(), "view {i}: simulate marked {marked} of {} pixels", want.len());
        let got = view(render(&mut socket, RenderRequest { unknown: true, ..request(80 + i as u32, &pose.world_from_camera) }).await);
        assert!(got.unknown_mask.as_ref() == Some(&want), "view {i}: the served mask is simulate's ({marked} marked)");
        assert!(got.depth_image().expect("depth").units == simulated(&fx.dir.join("exact"), i).0, "view {i}: the depth is unchanged by asking for the mask");
        let plain = view(render(&mut socket, request(90 + i as u32, &pose.world_from_camera)).await);
        assert!(plain.unknown_mask.is_none(), "no mask unless asked");
    }
    // Without a grid a request for the mask is refused by name, and the session goes on.
    let no_grid = Server::start(&["--source", s(&fx.room), "--map", s(&fx.map)]);
    let mut socket = no_grid.connect().await;
    let (code, message) = failure(render(&mut socket, RenderRequest { unknown: true, ..request(1, &fx.poses[0].world_from_camera) }).await);
    assert!(code == RenderFailure::InvalidRequest && message.contains("--occupancy"), "{code:?} {message}");
    assert!(view(render(&mut socket, request(2, &fx.poses[0].world_from_camera)).await).unknown_mask.is_none());
    // A grid without a map, and a missing grid, stop the server before it listens.
    let o = webfusion(&["serve", "--bind", "127.0.0.1:0", "--source", s(&fx.room), "--occupancy", s(&fx.grid)]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--map"), "{}", String::from_utf8_lossy(&o.stderr));
    let o = webfusion(&["serve", "--bind", "127.0.0.1:0", "--source", s(&fx.room), "--map", s(&fx.map), "--occupancy", s(&fx.dir.join("missing.json"))]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("missing.json") && !stderr.contains("panicked"), "{stderr}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_without_a_map_says_so_and_a_damaged_map_stops_it_before_it_listens() {
    let fx = fixture();
    let server = Server::start(&["--source", s(&fx.room)]);
    let mut socket = server.connect().await;
    let (code, message) = failure(render(&mut socket, request(1, &Se3::IDENTITY)).await);
    assert!(code == RenderFailure::NoMap && message.contains("--map"), "{code:?} {message}");

    let bytes = std::fs::read(&fx.map).expect("map");
    let truncated = fx.dir.join("truncated.wfm");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).expect("write");
    let o = webfusion(&["serve", "--bind", "127.0.0.1:0", "--source", s(&fx.room), "--map", s(&truncated)]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("truncated") && !stderr.contains("panicked"), "{stderr}");
    assert!(!String::from_utf8_lossy(&o.stdout).contains("webfusion serve: http://"), "it never listened");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_python_client_gets_the_same_views() {
    let fx = fixture();
    let server = Server::start(&["--source", s(&fx.room), "--map", s(&fx.map), "--occupancy", s(&fx.grid)]);
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../scripts/render_client.py");
    let poses = fx.dir.join("views.txt");
    let run = |args: &[&str]| {
        let o = Command::new("python3").arg(script).arg(server.url()).args(args).output().expect("python3 is needed for the render client's test (any Python 3.8+, standard library only)");
        let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
        (o.status.success(), String::from_utf8_lossy(&o.stdout).into_owned(), stderr)
    };
    let size = format!("{W}x{H}");
    let out = fx.dir.join("python");
    let (success, stdout, stderr) = tokio::task::block_in_place(|| run(&["--poses", s(&poses), "--size", &size, "--intrinsics", K_ARG, "--color", "--out", s(&out)]));
    assert!(success, "render_client.py failed: {stderr}");
    let lines: Vec<serde_json::Value> = stdout.lines().map(|l| serde_json::from_str(l).expect("one JSON line per view")).collect();
    assert_eq!(lines.len(), fx.poses.len(), "a line per pose: {stdout}");
    for (i, line) in lines.iter().enumerate() {
        let (depth, color) = simulated(&fx.dir.join("exact"), i);
        let png = std::fs::read(line["depth_png"].as_str().expect("depth_png")).expect("the client's depth PNG");
        assert!(decode_depth16(&png, W, H).expect("a 16-bit PNG").units == depth, "the Python client's view {i} is simulate's");
        let rgb = std::fs::read(line["rgb_png"].as_str().expect("rgb_png")).expect("the client's colour PNG");
        assert!(Some(decode_rgb8(&rgb, W, H).expect("an RGB PNG").rgb8) == color, "the Python client's colour {i}");
        let valid = depth.iter().filter(|&&u| u > 0).count();
        assert_eq!(line["valid_pixels"].as_u64(), Some(valid as u64), "its summary counts the returns");
    }
    // Noise through the client: the frame index counts up from --frame-index.
    let noisy_out = fx.dir.join("python-noisy");
    let (success, _, stderr) = tokio::task::block_in_place(|| run(&["--poses", s(&poses), "--size", &size, "--intrinsics", K_ARG, "--noise", "kinect", "--seed", &SEED.to_string(), "--out", s(&noisy_out)]));
    assert!(success, "{stderr}");
    let png = std::fs::read(noisy_out.join("depth_000002.png")).expect("the third noisy view");
    assert!(decode_depth16(&png, W, H).expect("png").units == simulated(&fx.dir.join("noisy"), 2).0, "the client's noisy view");
    // Unknown masks through the client: the ones simulate wrote.
    let masks_out = fx.dir.join("python-unknown");
    let (success, stdout, stderr) = tokio::task::block_in_place(|| run(&["--poses", s(&poses), "--size", &size, "--intrinsics", K_ARG, "--unknown", "--out", s(&masks_out)]));
    assert!(success, "{stderr}");
    for (i, line) in stdout.lines().enumerate() {
        let line: serde_json::Value = serde_json::from_str(line).expect("json");
        let want = simulated_mask(&fx.dir.join("unknown"), i);
        let png = std::fs::read(line["unknown_png"].as_str().expect("unknown_png")).expect("the client's mask PNG");
        let got: Vec<u8> = decode_rgb8(&png, W, H).expect("an 8-bit grey PNG").rgb8.chunks(3).map(|c| c[0]).collect();
        assert!(got == want, "the Python client's mask {i} is simulate's");
        assert_eq!(line["unknown_pixels"].as_u64(), Some(want.iter().filter(|&&m| m == 255).count() as u64), "its summary counts the marks");
    }
    // A bad request: a clear message and a failing exit, no traceback.
    let (success, _, stderr) = tokio::task::block_in_place(|| run(&["--pose", "0,0,0,0,0,0,1", "--size", "5000x10"]));
    assert!(!success && stderr.contains("invalid request") && stderr.contains("5000x10") && !stderr.contains("Traceback"), "{stderr}");
    // A pose given by hand and the default camera: the Kinect's 525 px at 640x480, scaled.
    let pose = fx.poses[1].world_from_camera;
    let (t, q) = (pose.translation_m, pose.rotation);
    // `--pose=` keeps a leading minus sign from reading as an option.
    let pose_arg = format!("{},{},{},{},{},{},{}", t.x, t.y, t.z, q.x, q.y, q.z, q.w);
    let (success, stdout, stderr) = tokio::task::block_in_place(|| run(&[&format!("--pose={pose_arg}"), "--size", &size]));
    assert!(success, "{stderr}");
    let line: serde_json::Value = serde_json::from_str(stdout.trim()).expect("json");
    let f = 525.0 * W as f32 / 640.0;
    let kinect = PinholeIntrinsics { fx_px: f, fy_px: f, cx_px: 0.5 * W as f32 - 0.5, cy_px: 0.5 * H as f32 - 0.5, width_px: W, height_px: H };
    let mut socket = server.connect().await;
    let depth = view(render(&mut socket, RenderRequest { intrinsics: kinect, ..request(1, &pose) }).await).depth_image().expect("depth").units;
    let valid = depth.iter().filter(|&&u| u > 0).count() as u64;
    assert!(valid > 0 && line["valid_pixels"].as_u64() == Some(valid), "the client's default camera: {line} vs {valid} returns");
    let sha = line["depth_sha256"].as_str().expect("sha");
    assert_eq!(sha.len(), 64, "a SHA-256 of the raw depth");
}

/// A raw HTTP/1.1 GET of `path` (with an `Origin` header, if given): the status code, the
/// headers (lower-cased names) and the body.
fn http_get(addr: &str, path: &str, origin: Option<&str>) -> (u16, String, Vec<u8>) {
    use std::io::{Read as _, Write as _};
    let mut stream = std::net::TcpStream::connect(addr).expect("connecting");
    let origin = origin.map(|o| format!("Origin: {o}\r\n")).unwrap_or_default();
    write!(stream, "GET {path} HTTP/1.1\r\nHost: {addr}\r\n{origin}Connection: close\r\n\r\n").expect("request");
    let mut response = Vec::new();
    stream.read_to_end(&mut response).expect("response");
    let split = response.windows(4).position(|w| w == b"\r\n\r\n").expect("a header block");
    let head = String::from_utf8_lossy(&response[..split]).to_lowercase();
    let status = head.split_whitespace().nth(1).and_then(|c| c.parse().ok()).expect("a status code");
    let mut body = response[split + 4..].to_vec();
    if head.contains("transfer-encoding: chunked") {
        // De-chunk: size line, data, CRLF, until the zero-sized chunk.
        let (mut out, mut rest) = (Vec::new(), body.as_slice());
        loop {
            let line_end = rest.windows(2).position(|w| w == b"\r\n").expect("a chunk size");
            let size = usize::from_str_radix(std::str::from_utf8(&rest[..line_end]).expect("hex").trim(), 16).expect("a chunk size");
            if size == 0 {
                break;
            }
            out.extend_from_slice(&rest[line_end + 2..line_end + 2 + size]);
            rest = &rest[line_end + 4 + size..];
        }
        body = out;
    }
    (status, head, body)
}

#[test]
fn the_served_map_is_offered_to_pages_behind_the_token() {
    let fx = fixture();
    let bytes = std::fs::read(&fx.map).expect("map");
    let server = Server::start(&["--source", s(&fx.room), "--map", s(&fx.map), "--token", "sesame"]);
    let (status, head, body) = http_get(&server.addr, "/map.wfm?token=sesame", None);
    assert_eq!(status, 200, "{head}");
    assert!(body == bytes, "the file's {} bytes, byte for byte (got {})", bytes.len(), body.len());
    assert!(webfusion_core::map::file::parse_map_bytes(&body, "served").is_ok_and(|m| m.damage.is_none() && !m.blocks.is_empty()), "a map the page can parse");
    // A page of the bridge's own origin may read it (CORS), a foreign one may not fetch it.
    let own = format!("http://{}", server.addr);
    let (status, head, _) = http_get(&server.addr, "/map.wfm?token=sesame", Some(&own));
    assert!(status == 200 && head.contains(&format!("access-control-allow-origin: {own}")), "{head}");
    assert_eq!(http_get(&server.addr, "/map.wfm?token=sesame", Some("http://evil.example")).0, 403);
    assert_eq!(http_get(&server.addr, "/map.wfm?token=wrong", None).0, 401);
    assert_eq!(http_get(&server.addr, "/map.wfm", None).0, 401);
    drop(server);
    let bare = Server::start(&["--source", s(&fx.room)]);
    let (status, _, body) = http_get(&bare.addr, "/map.wfm", None);
    assert!(status == 404 && String::from_utf8_lossy(&body).contains("--map"), "{status} {}", String::from_utf8_lossy(&body));
}
