// SPDX-License-Identifier: MIT
//! `webfusion record` loses nothing it reported as synced: killed with SIGKILL after a reported
//! sync (from a recording, a TUM directory and an OpenNI2 `.oni` of the Dummy device), every
//! synced frame is recovered bit-identical, and the source's ground truth with them (it is
//! written before the first frame); SIGTERM ends the take with a finished file that holds the
//! take's statistics; a file-size limit (`ulimit -f`) ends it with a finished file of what fit
//! and an error.
//! Event-driven: the kills follow the recorder's own "synced N frames" lines, no timing.

use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use webfusion_core::recording::{EncodedFrame, RecordingReader};
use webfusion_core::source::{FrameSource as _, TimedPose};

const SAMPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/sample/fr1_rpy.wfr");

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("webfusion-record-crash-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn record(out: &Path, extra: &[&str]) -> Child {
    record_from(SAMPLE, out, extra)
}

fn record_from(source: &str, out: &Path, extra: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_webfusion"))
        .args(["record", "--source", source, "--out", out.to_str().expect("utf-8")])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start webfusion record")
}

/// Reads the recorder's stderr until its `nth` "synced N frames" line; returns N.
fn wait_for_sync(child: &mut Child, nth: usize) -> usize {
    let stderr = child.stderr.take().expect("piped stderr");
    let mut lines = BufReader::new(stderr).lines();
    let mut seen = 0;
    for line in lines.by_ref() {
        let line = line.expect("stderr line");
        if let Some(rest) = line.strip_prefix("synced ") {
            seen += 1;
            if seen == nth {
                // Keep draining stderr so the recorder never blocks on a full pipe.
                std::thread::spawn(move || lines.for_each(drop));
                return rest.split_whitespace().next().and_then(|n| n.parse().ok()).expect("a frame count");
            }
        }
    }
    panic!("the recorder ended after {seen} syncs, before sync {nth}");
}

/// What a finished recording of the same source holds (the encoders are deterministic): its
/// frames and its ground truth.
struct Reference {
    frames: Vec<EncodedFrame>,
    ground_truth: Option<Vec<TimedPose>>,
}

fn reference(dir: &Path) -> Reference {
    reference_from(SAMPLE, dir, &[])
}

fn reference_from(source: &str, dir: &Path, extra: &[&str]) -> Reference {
    let out = dir.join("reference.wfr");
    let status = record_from(source, &out, extra).wait_with_output().expect("reference run");
    assert!(status.status.success(), "reference recording ended with {}: {}", status.status, String::from_utf8_lossy(&status.stderr));
    let stdout = String::from_utf8_lossy(&status.stdout);
    assert!(stdout.contains("frames/s written") && stdout.contains("frames dropped by the source"), "the summary gives the take's rate: {stdout}");
    let mut reader = RecordingReader::open(&out).expect("the reference is finished");
    let take = reader.take_stats().expect("a recorded take has its statistics in the footer");
    assert!(take.duration_ns > 0 && take.frames_dropped_by_source == 0, "{take:?}");
    let frames = (0..reader.frame_count()).map(|i| reader.read_encoded_frame(i).expect("frame")).collect();
    Reference { frames, ground_truth: reader.ground_truth().map(<[_]>::to_vec) }
}

/// Kills the recorder of `source` after its `nth_sync`-th reported sync, in each trial, and
/// checks that every synced frame is recovered bit-identical to `want`, and its ground truth.
fn kill_trials(dir: &Path, source: &str, extra: &[&str], want: &Reference, syncs: &[usize]) {
    for (trial, &nth_sync) in syncs.iter().enumerate() {
        let out = dir.join(format!("take{trial}.wfr"));
        let mut args = vec!["--sync-interval-ms", "0"];
        args.extend_from_slice(extra);
        let mut child = record_from(source, &out, &args);
        let synced = wait_for_sync(&mut child, nth_sync);
        child.kill().expect("SIGKILL");
        child.wait().expect("reap");
        let partial = dir.join(format!("take{trial}.wfr.partial"));
        let mut reader = RecordingReader::open_recovering(&partial).expect("the killed take opens");
        let kept = reader.frame_count();
        assert!(kept >= synced, "trial {trial}: {synced} frames reported synced, {kept} recovered ({:?})", reader.recovery());
        for (i, want) in want.frames.iter().enumerate().take(kept) {
            assert_eq!(&reader.read_encoded_frame(i).expect("recovered frame"), want, "trial {trial}: frame {i} bit-identical");
        }
        assert_eq!(reader.ground_truth(), want.ground_truth.as_deref(), "trial {trial}: the ground truth survives the kill");
    }
}

#[test]
fn a_killed_recorder_loses_no_synced_frame() {
    let dir = scratch("kill");
    let want = reference(&dir);
    assert!(want.ground_truth.as_ref().is_some_and(|gt| !gt.is_empty()), "the sample has ground truth to lose");
    kill_trials(&dir, SAMPLE, &[], &want, &[1, 9, 37]);
}

#[test]
fn a_killed_recorder_of_a_tum_directory_loses_no_synced_frame() {
    let dir = scratch("kill-tum");
    let tum = dir.join("rgbd_dataset_freiburg1_rpy");
    let mut sample = RecordingReader::open(SAMPLE).expect("the sample");
    webfusion_core::io::tum::write_tum_dataset(&tum, &mut sample, 0..30).expect("the sample as a TUM directory");
    let tum = tum.to_str().expect("utf-8").to_owned();
    kill_trials(&dir, &tum, &[], &reference_from(&tum, &dir, &[]), &[2, 13]);
}

/// OpenNI2's Dummy device (no hardware), recorded to `.oni` and re-recorded to `.wfr`.
#[cfg(feature = "openni2")]
#[test]
fn a_killed_recorder_of_an_openni2_recording_loses_no_synced_frame() {
    const CALIBRATION: [&str; 4] = ["--intrinsics", "285,285,159.5,119.5,320,240", "--depth-scale", "1000"];
    let dir = scratch("kill-oni");
    let oni = dir.join("dummy.oni");
    let o = Command::new(env!("CARGO_BIN_EXE_webfusion")).args(["oni-dummy", "--out", oni.to_str().expect("utf-8"), "--frames", "40"]).output().expect("oni-dummy");
    assert!(o.status.success(), "oni-dummy: {}", String::from_utf8_lossy(&o.stderr));
    let oni = oni.to_str().expect("utf-8").to_owned();
    kill_trials(&dir, &oni, &CALIBRATION, &reference_from(&oni, &dir, &CALIBRATION), &[3, 21]);
}

#[test]
fn sigterm_ends_the_take_with_a_finished_file() {
    let dir = scratch("term");
    let out = dir.join("take.wfr");
    let mut child = record(&out, &["--sync-interval-ms", "0"]);
    let synced = wait_for_sync(&mut child, 5);
    let pid = child.id().to_string();
    assert!(Command::new("kill").args(["-TERM", &pid]).status().expect("kill -TERM").success(), "SIGTERM sent");
    let output = child.wait_with_output().expect("the recorder exits");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success() && stdout.contains("stopped by a signal"), "a signalled take ends cleanly: {stdout}");
    let reader = RecordingReader::open(&out).expect("a finished file");
    // 95 frames, each synced to disk, remained when the signal came.
    assert!(reader.frame_count() >= synced && reader.frame_count() < 100, "{} frames, {synced} synced", reader.frame_count());
    let take = reader.take_stats().expect("the footer holds the take's statistics");
    assert!(take.frames_per_second(reader.frame_count()).is_some_and(|fps| fps > 0.0) && take.frames_dropped_by_source == 0, "{take:?}");
}

#[test]
fn a_file_size_limit_ends_the_take_with_what_fit() {
    let dir = scratch("ulimit");
    let out = dir.join("take.wfr");
    // 3000 KiB of the sample's ~12 MB: the limit hits a third of the way in.
    let script = format!("ulimit -f 3000; exec {} record --source {SAMPLE} --out {}", env!("CARGO_BIN_EXE_webfusion"), out.display());
    let output = Command::new("bash").args(["-c", &script]).output().expect("bash");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "the take could not finish: it must say so");
    assert!(stderr.contains("the take ended early") && !stderr.contains("panicked"), "{stderr}");
    let reader = RecordingReader::open(&out).expect("what fit is a finished file");
    let len = std::fs::metadata(&out).expect("size").len();
    assert!(reader.frame_count() > 5 && len <= 3000 * 1024, "{} frames in {len} bytes", reader.frame_count());
    assert!(reader.ground_truth().is_some() && reader.take_stats().is_some(), "ground truth and take statistics kept");
}
