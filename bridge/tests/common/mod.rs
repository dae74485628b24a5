// SPDX-License-Identifier: MIT
//! What the seed-000 tests of the binary share: running `webfusion`, and a synthetic room
//! (exact depth and poses) fused at its known poses and saved as a map.
#![allow(dead_code, reason = "each test crate uses the helpers it needs")]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use webfusion_core::io::trajectory::{TimedPose, format_tum_trajectory};
use webfusion_core::recording::RecordingReader;
use webfusion_core::source::FrameSource as _;

pub(crate) fn webfusion(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_webfusion")).args(args).env("XDG_RUNTIME_DIR", std::env::temp_dir()).output().expect("run webfusion")
}

/// Runs `webfusion args`, which must succeed; its stdout.
pub(crate) fn ok(args: &[&str]) -> String {
    let o = webfusion(args);
    assert!(o.status.success(), "webfusion {args:?} failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs `webfusion args`, which must fail cleanly (no panic) with `needle` in its error.
pub(crate) fn fails(args: &[&str], needle: &str) {
    let o = webfusion(args);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "webfusion {args:?} should fail");
    assert!(stderr.contains(needle), "webfusion {args:?}: the error should say {needle:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "no panic: {stderr}");
}

/// A fresh directory for one test.
pub(crate) fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("webfusion-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

pub(crate) fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// A 4 x 2.5 x 4 m synthetic room rendered at 160x120 along its loop, fused at its exact poses.
pub(crate) struct FusedRoom {
    /// The room's recording (`synth-room`).
    pub(crate) room: PathBuf,
    /// Its exact poses.
    pub(crate) gt: Vec<TimedPose>,
    /// The same as a TUM trajectory file.
    pub(crate) poses: PathBuf,
    /// The saved map (`reconstruct --poses --save-map`), in the room's frame.
    pub(crate) map: PathBuf,
    /// The fusing run's output directory (`trajectory.txt`: the pose each frame was fused at).
    pub(crate) fused: PathBuf,
}

/// The room of `frames` frames fused with `voxel` (metres, as typed) voxels, in `dir`.
pub(crate) fn fused_room(dir: &Path, frames: usize, voxel: &str) -> FusedRoom {
    let room = dir.join("room.wfr");
    ok(&["synth-room", "--out", s(&room), "--size", "4,2.5,4", "--frames", &frames.to_string(), "--width", "160", "--height", "120"]);
    let reader = RecordingReader::open(&room).expect("the room");
    // The room's header says its depth is exact, so it is fused with the band μ alone.
    assert_eq!(reader.depth_noise(), webfusion_core::source::DepthNoise::None, "synth-room's depth is exact");
    let gt = reader.ground_truth().expect("exact poses").to_vec();
    let poses = dir.join("gt.txt");
    std::fs::write(&poses, format_tum_trajectory(&gt)).expect("poses");
    let map = dir.join("room.wfm");
    let fused = dir.join("fused");
    ok(&["reconstruct", s(&room), "--poses", s(&poses), "--voxel-size", voxel, "--save-map", s(&map), "--no-mesh", "--out", s(&fused)]);
    // The recording's ground truth comes out beside the trajectory, as it was recorded.
    let written = std::fs::read_to_string(fused.join("groundtruth.txt")).expect("groundtruth.txt");
    assert_eq!(written, format_tum_trajectory(&gt), "reconstruct writes the source's ground truth");
    let stats: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(fused.join("stats.json")).expect("stats.json")).expect("json");
    assert_eq!(stats["volume"]["noise_band_sigmas"], serde_json::json!(0.0), "exact depth fuses with the band μ");
    FusedRoom { room, gt, poses, map, fused }
}
