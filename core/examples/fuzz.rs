// SPDX-License-Identifier: MIT
//! Mutation fuzzing (a tool, not a test; `scripts/fuzz.sh` runs it in release): every decoder
//! that reads outside input (the `.wfr` reader, strict and recovering; the protocol decoder
//! with the frame images it carries; RVL, RVL+DEFLATE and 16-bit PNG depth) is fed mutated
//! copies of valid inputs, and must return `Ok` or `Err`, never panic.
//!
//!   cargo run --release -p webfusion-core --example fuzz -- [CASES_PER_TARGET] [SEED]
//!
//! Mutations (1 to 8 per case, from a seeded xorshift generator, so a run repeats exactly):
//! flip a bit, set a byte, set a little-endian u32 to an extreme, truncate, insert random
//! bytes, duplicate a slice. Prints per target: cases, ok/err counts, panics, seconds; exits
//! non-zero on any panic.

use std::io::Cursor;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::Instant;

use glam::{DQuat, DVec3};
use webfusion_core::codec::{ColorCodec, DepthCodec, png, rvl};
use webfusion_core::io::trajectory::TimedPose;
use webfusion_core::protocol::{Control, Delivery, FrameMessage, Hello, Message, PlaybackState, RenderNoise, RenderOutcome, RenderRequest, RenderedView, Status, WireColor, WireDepth};
use webfusion_core::recording::{RecordingOptions, RecordingReader, RecordingWriter, TakeStats};
use webfusion_core::source::FrameSource as _;
use webfusion_core::{ColorImage, DepthImage, PinholeIntrinsics, RgbdCalibration, RgbdFrame, Se3};

/// A seeded xorshift64* generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Applies 1..=8 random mutations to a copy of `seed`.
fn mutate(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    let mut bytes = seed.to_vec();
    for _ in 0..1 + rng.below(8) {
        let len = bytes.len();
        match rng.below(6) {
            0 if len > 0 => {
                let i = rng.below(len);
                bytes[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                bytes[i] = rng.next() as u8;
            }
            2 if len >= 4 => {
                let i = rng.below(len - 3);
                let v = [0u32, 1, u32::MAX, u32::MAX / 2, 0x8000_0000][rng.below(5)];
                bytes[i..i + 4].copy_from_slice(&v.to_le_bytes());
            }
            3 => bytes.truncate(rng.below(len + 1)),
            4 => {
                let at = rng.below(len + 1);
                let extra: Vec<u8> = (0..1 + rng.below(64)).map(|_| rng.next() as u8).collect();
                bytes.splice(at..at, extra);
            }
            _ if len > 1 => {
                let (a, b) = (rng.below(len), rng.below(len));
                let (from, to) = (a.min(b), a.max(b));
                let slice = bytes[from..to].to_vec();
                let at = rng.below(bytes.len() + 1);
                bytes.splice(at..at, slice);
            }
            _ => {}
        }
    }
    bytes
}

fn calibration() -> RgbdCalibration {
    RgbdCalibration { intrinsics: PinholeIntrinsics { fx_px: 20.0, fy_px: 20.0, cx_px: 7.5, cy_px: 5.5, width_px: 16, height_px: 12 }, depth_units_per_metre: 1000.0 }
}

fn frame(i: u64) -> RgbdFrame {
    let k = calibration().intrinsics;
    let n = k.pixel_count();
    RgbdFrame {
        index: i,
        depth_timestamp_ns: 1_000_000_000 + i as i64 * 33_000_000,
        color_timestamp_ns: 1_000_000_100 + i as i64 * 33_000_000,
        depth: DepthImage::new(k.width_px, k.height_px, (0..n).map(|p| if p % 9 == 0 { 0 } else { (700 + p as u16 * 7) ^ i as u16 }).collect()).expect("size"),
        color: ColorImage::new(k.width_px, k.height_px, (0..3 * n).map(|b| (b * 5 + i as usize) as u8).collect()).expect("size"),
    }
}

/// Three frames and one ground-truth pose, the pose written before the frames (as `record`
/// does, right after the header) or after them, and the take's statistics in the footer.
fn recording(color_codec: ColorCodec, ground_truth_first: bool) -> Vec<u8> {
    let options = RecordingOptions { depth_codec: DepthCodec::RvlDeflate, color_codec, ..RecordingOptions::default() };
    let mut writer = RecordingWriter::new(Cursor::new(Vec::new()), calibration(), options).expect("writer");
    let pose = Se3 { rotation: DQuat::from_rotation_y(0.1), translation_m: DVec3::new(0.1, 0.2, 0.3) };
    let ground_truth = [TimedPose { timestamp_ns: 1_000_000_000, world_from_camera: pose }];
    if ground_truth_first {
        writer.set_ground_truth(&ground_truth).expect("ground truth");
    }
    for i in 0..3 {
        writer.write_frame(&frame(i)).expect("frame");
    }
    if !ground_truth_first {
        writer.set_ground_truth(&ground_truth).expect("ground truth");
    }
    writer.set_take_stats(TakeStats { duration_ns: 100_000_000, frames_dropped_by_source: 1 });
    writer.finish_into_inner().expect("finish").0.into_inner()
}

fn messages() -> Vec<Vec<u8>> {
    let f = frame(1);
    let frame_message = |color: WireColor, color_payload: Vec<u8>| FrameMessage {
        sequence: 7,
        index: 1,
        depth_timestamp_ns: f.depth_timestamp_ns,
        color_timestamp_ns: f.color_timestamp_ns,
        ground_truth: Some(Se3::IDENTITY),
        depth_codec: DepthCodec::Rvl,
        depth_payload: DepthCodec::Rvl.encode(&f.depth),
        color,
        color_payload,
    };
    vec![
        Message::Hello(Hello { source_name: "fuzz".into(), frame_count: Some(3), calibration: calibration(), has_ground_truth: true, delivery: Delivery::Lossless, depth_noise: webfusion_core::source::DepthNoise::None }).encode(),
        Message::Status(Status { state: PlaybackState::Playing, next_index: 2, rate: 1.0, looping: false, delivery: Delivery::Live, frames_sent: 5, frames_dropped: 1, frames_skipped: 1 }).encode(),
        Message::Control(Control::Seek(3)).encode(),
        Message::Control(Control::Rate(2.5)).encode(),
        Message::Frame(frame_message(WireColor::Raw, f.color.rgb8.clone())).encode(),
        Message::Frame(frame_message(WireColor::Coded(ColorCodec::Jpeg), ColorCodec::Jpeg.encode(&f.color, 80).expect("jpeg"))).encode(),
        Message::Frame(frame_message(WireColor::Coded(ColorCodec::Png), ColorCodec::Png.encode(&f.color, 0).expect("png"))).encode(),
        Message::RenderRequest(RenderRequest {
            request_id: 4,
            world_from_camera: Se3::IDENTITY,
            intrinsics: calibration().intrinsics,
            depth_units_per_metre: 5000.0,
            radial: false,
            depth_range_m: Some((0.4, 4.0)),
            noise: Some(RenderNoise { seed: 1, frame_index: 2 }),
            color: true,
            unknown: true,
            depth_encoding: WireDepth::Raw,
        })
        .encode(),
        Message::RenderReply {
            request_id: 4,
            outcome: RenderOutcome::View(RenderedView {
                width_px: f.depth.width_px,
                height_px: f.depth.height_px,
                depth_units_per_metre: 5000.0,
                radial: false,
                depth_encoding: WireDepth::Raw,
                depth_payload: WireDepth::Raw.encode(&f.depth),
                color_rgb8: Some(f.color.rgb8.clone()),
                unknown_mask: Some(vec![0; f.depth.units.len()]),
            }),
        }
        .encode(),
    ]
}

/// Runs `decode` on `cases` mutations of the seeds; returns (ok, err, panics).
fn fuzz(name: &str, cases: u64, rng: &mut Rng, seeds: &[Vec<u8>], decode: &dyn Fn(&[u8]) -> bool) -> u64 {
    let started = Instant::now();
    let (mut ok, mut err, mut panics) = (0u64, 0u64, 0u64);
    for case in 0..cases {
        let input = mutate(rng, &seeds[case as usize % seeds.len()]);
        match catch_unwind(AssertUnwindSafe(|| decode(&input))) {
            Ok(true) => ok += 1,
            Ok(false) => err += 1,
            Err(_) => {
                panics += 1;
                eprintln!("{name}: PANIC on case {case} ({} bytes): {:02x?}", input.len(), &input[..input.len().min(64)]);
            }
        }
    }
    println!("{name:<24} {cases:>9} cases  {ok:>9} ok  {err:>9} err  {panics} panics  {:.1} s", started.elapsed().as_secs_f64());
    panics
}

fn main() {
    let mut args = std::env::args().skip(1);
    let cases: u64 = args.next().map_or(1_000_000, |a| a.parse().expect("CASES_PER_TARGET: a whole number"));
    let seed: u64 = args.next().map_or(0x5eed_f00d, |a| a.parse().expect("SEED: a whole number"));
    println!("mutation fuzzing, {cases} cases per target, seed {seed}");
    // A panic is counted and reported; keep the default hook from printing each one twice.
    std::panic::set_hook(Box::new(|_| {}));
    let mut rng = Rng(seed | 1);
    let recordings = vec![recording(ColorCodec::Png, false), recording(ColorCodec::Jpeg, true)];
    let calibration = calibration();
    let read_all = |mut reader: RecordingReader| {
        for i in 0..reader.frame_count() {
            if reader.read_frame(i).is_err() {
                return false;
            }
        }
        true
    };
    let mut panics = 0;
    panics += fuzz("wfr (strict)", cases, &mut rng, &recordings, &|b| RecordingReader::from_bytes(b.to_vec()).map(read_all).unwrap_or(false));
    panics += fuzz("wfr (recovering)", cases, &mut rng, &recordings, &|b| RecordingReader::from_bytes_recovering(b.to_vec()).map(read_all).unwrap_or(false));
    panics += fuzz("protocol + frame images", cases, &mut rng, &messages(), &|b| match Message::decode(b) {
        Ok(Message::Frame(f)) => f.decode_images(&calibration).is_ok(),
        Ok(_) => true,
        Err(_) => false,
    });
    let f = frame(2);
    let n = f.depth.units.len();
    panics += fuzz("rvl", cases, &mut rng, &[rvl::rvl_encode(&f.depth.units)], &|b| rvl::rvl_decode(b, n).is_ok());
    panics += fuzz("rvl + deflate", cases, &mut rng, &[rvl::rvl_deflate_encode(&f.depth.units)], &|b| rvl::rvl_deflate_decode(b, n).is_ok());
    panics += fuzz("png depth16", cases, &mut rng, &[png::encode_depth16(&f.depth).expect("png")], &|b| png::decode_depth16(b, 16, 12).is_ok());
    if panics > 0 {
        eprintln!("{panics} panics");
        std::process::exit(1);
    }
    println!("0 panics");
}
