// SPDX-License-Identifier: MIT
//! The `webfusion` binary on bad input: a clear error naming the problem, a non-zero exit,
//! never a panic; and `eval` on exact trajectories.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn webfusion(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_webfusion")).args(args).env("XDG_RUNTIME_DIR", std::env::temp_dir()).output().expect("run webfusion")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("webfusion-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn assert_clean_failure(o: &Output, needle: &str) {
    let err = stderr(o);
    assert!(!o.status.success(), "expected failure, got success; stderr: {err}");
    assert!(!err.contains("panicked"), "panicked: {err}");
    assert!(err.contains(needle), "stderr should mention {needle:?}: {err}");
}

#[test]
fn reconstruct_names_a_missing_source() {
    let out = scratch("missing");
    let o = webfusion(&["reconstruct", "/nonexistent/fr1_dir", "--out", out.to_str().expect("utf-8")]);
    assert_clean_failure(&o, "/nonexistent/fr1_dir");
}

#[test]
fn reconstruct_names_an_unreadable_depth_png() {
    // A TUM directory whose first depth image is not a PNG.
    let dir = scratch("corrupt").join("rgbd_dataset_freiburg1_test");
    for sub in ["rgb", "depth"] {
        std::fs::create_dir_all(dir.join(sub)).expect("mkdir");
    }
    std::fs::write(dir.join("rgb.txt"), "# rgb\n1.000000 rgb/1.000000.png\n").expect("rgb.txt");
    std::fs::write(dir.join("depth.txt"), "# depth\n1.001000 depth/1.001000.png\n").expect("depth.txt");
    std::fs::write(dir.join("rgb/1.000000.png"), b"not a png").expect("rgb");
    std::fs::write(dir.join("depth/1.001000.png"), b"not a png either").expect("depth");
    let out = scratch("corrupt-out");
    let o = webfusion(&["reconstruct", dir.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8"), "--no-mesh"]);
    assert_clean_failure(&o, "1.001000.png");
}

#[test]
fn reconstruct_asks_for_intrinsics_when_the_camera_is_unknown() {
    let dir = scratch("unknown-camera").join("my_scan");
    std::fs::create_dir_all(&dir).expect("mkdir");
    std::fs::write(dir.join("rgb.txt"), "1.0 rgb/a.png\n").expect("rgb.txt");
    std::fs::write(dir.join("depth.txt"), "1.0 depth/a.png\n").expect("depth.txt");
    let out = scratch("unknown-camera-out");
    let o = webfusion(&["reconstruct", dir.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8")]);
    assert_clean_failure(&o, "--intrinsics");
}

#[test]
fn reconstruct_rejects_bad_settings() {
    let out = scratch("settings");
    let o = webfusion(&["reconstruct", "--out", out.to_str().expect("utf-8"), "--voxel-size=-0.01"]);
    assert_clean_failure(&o, "voxel size");
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/sample/fr1_rpy.wfr");
    let o = webfusion(&["reconstruct", sample.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8"), "--frames", "5..2"]);
    assert_clean_failure(&o, "--frames");
}

fn write_trajectory(path: &Path, offset_m: f64) {
    let mut text = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for i in 0..10 {
        let t = 100.0 + f64::from(i) * 0.033;
        text += &format!("{t:.6} {:.6} {:.6} {:.6} 0 0 0 1\n", 0.1 * f64::from(i) + offset_m, (0.2 * f64::from(i)).sin(), 0.05 * f64::from(i * i));
    }
    std::fs::write(path, text).expect("write trajectory");
}

#[test]
fn eval_scores_exact_and_offset_trajectories() {
    let dir = scratch("eval");
    let (gt, est) = (dir.join("gt.txt"), dir.join("est.txt"));
    write_trajectory(&gt, 0.0);
    write_trajectory(&est, 0.25);
    // Aligned: a pure offset vanishes. Unaligned: every pair is 25 cm off.
    let o = webfusion(&["eval", "--gt", gt.to_str().expect("utf-8"), "--est", est.to_str().expect("utf-8"), "--json", dir.join("a.json").to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = webfusion(&["eval", "--gt", gt.to_str().expect("utf-8"), "--est", est.to_str().expect("utf-8"), "--no-align", "--json", dir.join("b.json").to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let aligned = std::fs::read_to_string(dir.join("a.json")).expect("a.json");
    let unaligned = std::fs::read_to_string(dir.join("b.json")).expect("b.json");
    let rmse = |json: &str| -> f64 {
        let v: serde_json::Value = serde_json::from_str(json).expect("eval JSON");
        v["ate"]["stats"]["rmse_m"].as_f64().expect("ate.stats.rmse_m")
    };
    assert!(rmse(&aligned) < 1e-9, "aligned ATE {}", rmse(&aligned));
    assert!((rmse(&unaligned) - 0.25).abs() < 1e-9, "unaligned ATE {}", rmse(&unaligned));
    let o = webfusion(&["eval", "--gt", dir.join("nope.txt").to_str().expect("utf-8"), "--est", est.to_str().expect("utf-8")]);
    assert_clean_failure(&o, "nope.txt");
}

#[test]
fn eval_into_a_closed_pipe_ends_quietly_and_still_writes_json() {
    let dir = scratch("eval-pipe");
    let (gt, est, json) = (dir.join("gt.txt"), dir.join("est.txt"), dir.join("r.json"));
    write_trajectory(&gt, 0.0);
    write_trajectory(&est, 0.1);
    // Like `webfusion eval ... | head -0`: the reader is gone before the report is written.
    let mut child = Command::new(env!("CARGO_BIN_EXE_webfusion"))
        .args(["eval", "--gt", gt.to_str().expect("utf-8"), "--est", est.to_str().expect("utf-8"), "--json", json.to_str().expect("utf-8")])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run webfusion");
    drop(child.stdout.take());
    let o = child.wait_with_output().expect("waiting");
    assert!(o.status.success() && !stderr(&o).contains("panicked"), "{}", stderr(&o));
    assert!(json.is_file(), "the JSON report was lost");
}

/// The first `frames` frames of the sample recorded into `dir/take.wfr` by `webfusion record`.
fn record_sample_take(dir: &Path, frames: usize) -> PathBuf {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/sample/fr1_rpy.wfr");
    let take = dir.join("take.wfr");
    let o = webfusion(&["record", "--source", sample.to_str().expect("utf-8"), "--out", take.to_str().expect("utf-8"), "--frames", &format!("..{frames}")]);
    assert!(o.status.success(), "record: {}", stderr(&o));
    take
}

/// Where a record's payload starts in a recording's bytes (found by its first 64 bytes).
fn payload_offset(bytes: &[u8], payload: &[u8]) -> usize {
    let probe = &payload[..payload.len().min(64)];
    bytes.windows(probe.len()).position(|w| w == probe).expect("the record's payload is in the file")
}

/// A take whose recorder died mid-frame (the file cut inside frame 12, no index or footer):
/// every command reads the complete frames with a warning, and `repair` writes a finished
/// copy holding exactly them, bytes unchanged.
#[test]
fn an_unfinished_take_is_read_with_a_warning_and_repaired() {
    use webfusion_core::recording::RecordingReader;
    use webfusion_core::source::FrameSource as _;
    let dir = scratch("repair");
    let take = record_sample_take(&dir, 20);
    // Cut inside frame 12: the writer was killed there.
    let mut finished = RecordingReader::open(&take).expect("the take is finished");
    let originals: Vec<_> = (0..12).map(|i| finished.read_encoded_frame(i).expect("frame")).collect();
    let bytes = std::fs::read(&take).expect("read the take");
    let cut_at = {
        let f12 = finished.read_encoded_frame(12).expect("frame 12");
        payload_offset(&bytes, &f12.depth_payload) + 100
    };
    let partial = dir.join("take.wfr.partial");
    std::fs::write(&partial, &bytes[..cut_at]).expect("write the cut take");
    assert!(RecordingReader::open(&partial).is_err(), "the strict reader refuses it");

    let o = webfusion(&["preprocess", "--source", partial.to_str().expect("utf-8"), "--frames", "..2"]);
    assert!(o.status.success(), "preprocess reads the complete frames: {}", stderr(&o));
    assert!(stderr(&o).contains("recovered 12 frames by scanning"), "a warning says what was kept: {}", stderr(&o));

    let repaired = dir.join("repaired.wfr");
    let o = webfusion(&["repair", partial.to_str().expect("utf-8"), "--out", repaired.to_str().expect("utf-8")]);
    assert!(o.status.success(), "repair: {}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("12 frames") && out.contains("0 damaged records dropped"), "repair's counts: {out}");
    let mut reader = RecordingReader::open(&repaired).expect("the repaired copy opens strictly");
    assert_eq!(reader.frame_count(), 12, "frames");
    for (i, want) in originals.iter().enumerate() {
        assert_eq!(&reader.read_encoded_frame(i).expect("frame"), want, "frame {i} bit-identical");
    }
    let o = webfusion(&["repair", repaired.to_str().expect("utf-8"), "--out", repaired.to_str().expect("utf-8")]);
    assert_clean_failure(&o, "is the input");
}

/// Two damaged frames in the middle of a recording: every reading command stops at the first
/// with the frame named; `--skip-corrupt` skips both, counts them exactly and goes on.
#[test]
fn damaged_frames_stop_a_command_or_are_skipped_and_counted() {
    use webfusion_core::recording::RecordingReader;
    use webfusion_core::source::FrameSource as _;
    let dir = scratch("damaged-frames");
    let take = record_sample_take(&dir, 12);
    let mut bytes = std::fs::read(&take).expect("read the take");
    let mut reader = RecordingReader::open(&take).expect("finished");
    for damaged in [4usize, 9] {
        let payload = reader.read_encoded_frame(damaged).expect("frame").depth_payload;
        let at = payload_offset(&bytes, &payload);
        bytes[at + 10] ^= 0x5a;
    }
    let bad = dir.join("bad.wfr");
    std::fs::write(&bad, &bytes).expect("write the damaged copy");
    let bad_s = bad.to_str().expect("utf-8");

    let o = webfusion(&["preprocess", "--source", bad_s]);
    assert_clean_failure(&o, "frame 4: CRC mismatch");
    assert!(stderr(&o).contains("--skip-corrupt"), "the error says how to go on: {}", stderr(&o));
    let o = webfusion(&["preprocess", "--source", bad_s, "--skip-corrupt"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("2 damaged frames skipped (4, 9)"), "{}", String::from_utf8_lossy(&o.stdout));

    let fixed = dir.join("fixed.wfr");
    let o = webfusion(&["record", "--source", bad_s, "--out", fixed.to_str().expect("utf-8"), "--skip-corrupt"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(RecordingReader::open(&fixed).expect("finished").frame_count(), 10, "the ten intact frames");

    let out = dir.join("reconstruct");
    let o = webfusion(&["reconstruct", bad_s, "--out", out.to_str().expect("utf-8"), "--volume", "64", "--voxel-size", "0.08", "--centred", "--no-mesh", "--skip-corrupt"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stats: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("stats.json")).expect("stats.json")).expect("JSON");
    assert_eq!(stats["skipped_corrupt_frames"], serde_json::json!([4, 9]), "stats list the skipped frames");
}
