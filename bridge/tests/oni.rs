// SPDX-License-Identifier: MIT
//! OpenNI2 `.oni` recordings end to end (feature `openni2`): a Dummy-device recording made by
//! `webfusion oni-dummy` converts to `.wfr` with every frame intact and streams over the bridge.
#![cfg(feature = "openni2")]

use std::path::PathBuf;
use std::process::Command;

use webfusion_core::recording::RecordingReader;
use webfusion_core::source::FrameSource as _;

/// `record`'s calibration flags for the Dummy device (it reports no field of view).
const CALIBRATION: [&str; 4] = ["--intrinsics", "285,285,159.5,119.5,320,240", "--depth-scale", "1000"];

fn webfusion(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_webfusion")).args(args).env("XDG_RUNTIME_DIR", std::env::temp_dir()).output().expect("run webfusion")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("webfusion-oni-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

#[test]
fn a_dummy_oni_converts_to_a_recording_frame_for_frame() {
    let dir = scratch("record");
    let (oni, wfr) = (dir.join("dummy.oni"), dir.join("dummy.wfr"));
    let o = webfusion(&["oni-dummy", "--out", oni.to_str().expect("utf-8"), "--frames", "15"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The recorder runs on its own thread and may miss a frame at either end on a busy machine.
    let stdout = String::from_utf8_lossy(&o.stdout);
    let recorded: usize = stdout.split('(').nth(1).and_then(|s| s.split(' ').next()).and_then(|n| n.parse().ok()).unwrap_or_else(|| panic!("no frame count in {stdout:?}"));
    assert!((8..=15).contains(&recorded), "recorded {recorded} of 15 frames");
    // Without calibration the command asks for it instead of guessing.
    let o = webfusion(&["record", "--source", oni.to_str().expect("utf-8"), "--out", wfr.to_str().expect("utf-8")]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("--intrinsics") && !stderr.contains("panicked"), "{stderr}");
    let mut args = vec!["record", "--source", oni.to_str().expect("utf-8"), "--out", wfr.to_str().expect("utf-8"), "--depth-codec", "rvl"];
    args.extend(CALIBRATION);
    let o = webfusion(&args);
    assert!(o.status.success(), "{}; stdout {}; stderr {}", o.status, String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    let mut recording = RecordingReader::open(&wfr).expect("opening the converted recording");
    assert_eq!(recording.frame_count(), recorded, "every recorded frame converted");
    let cal = recording.calibration();
    assert_eq!((cal.intrinsics.width_px, cal.intrinsics.height_px, cal.depth_units_per_metre), (320, 240, 1000.0), "calibration");
    let frames: Vec<_> = (0..recorded).map(|i| recording.read_frame(i).expect("reading")).collect();
    assert!(frames.windows(2).all(|w| w[1].depth_timestamp_ns - w[0].depth_timestamp_ns == 33_000_000), "30 fps timestamps");
}

#[test]
fn devices_lists_what_openni2_sees_or_says_how_to_get_a_driver() {
    let o = webfusion(&["devices"]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // CI has no camera: then the output says so and names the drivers; with one, each line has a URI and USB id.
    let listed = !stdout.trim().is_empty() && stdout.lines().all(|l| l.contains("(USB "));
    assert!((stdout.contains("no OpenNI2 devices found") && stdout.contains("libfreenect")) || listed, "{stdout}");
}

#[test]
fn a_live_camera_records_the_frames_asked_for() {
    let dir = scratch("live");
    let wfr = dir.join("live.wfr");
    let o = webfusion(&["record", "--source", "openni2:Dummy", "--out", wfr.to_str().expect("utf-8")]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("--frames ..N"), "a camera has no end: {stderr}");
    let mut args = vec!["record", "--source", "openni2:Dummy", "--out", wfr.to_str().expect("utf-8"), "--frames", "..9"];
    args.extend(CALIBRATION);
    let o = webfusion(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("frames/s written") && stdout.contains("frames dropped by the source"), "the take's rate and drops: {stdout}");
    let mut recording = RecordingReader::open(&wfr).expect("opening the live recording");
    assert_eq!(recording.frame_count(), 9, "the frames asked for");
    let take = recording.take_stats().expect("the footer holds the take's statistics");
    assert!(take.frames_per_second(9).is_some_and(|fps| fps > 0.0), "{take:?}");
    let stamps: Vec<i64> = (0..9).map(|i| recording.read_frame(i).expect("reading").depth_timestamp_ns).collect();
    assert!(stamps.windows(2).all(|w| w[1] > w[0]), "one frame each, in order: {stamps:?}");
}
