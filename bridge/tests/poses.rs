// SPDX-License-Identifier: MIT
//! `reconstruct --poses`: mapping from known poses (seed 000's robot workflow). The bundled
//! sample, written out as a TUM directory with its motion-capture ground truth, is fused at
//! those poses: `trajectory.txt` holds exactly the pose each frame got (the ground truth
//! interpolated at its depth timestamp), frames whose nearest pose is more than 20 ms away are
//! skipped and listed, `--refine` reports how far tracking moved every given pose, and a
//! malformed pose file is a clean error naming its line.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use webfusion_core::map::file::read_map_file;
use webfusion_core::io::trajectory::{MAX_POSE_GAP_NS, PoseTimeline, TimedPose, format_tum_trajectory, read_tum_trajectory};
use webfusion_core::recording::RecordingReader;
use webfusion_core::source::FrameSource as _;

const SAMPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/sample/fr1_rpy.wfr");
const FRAMES: usize = 12;

fn webfusion(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_webfusion")).args(args).env("XDG_RUNTIME_DIR", std::env::temp_dir()).output().expect("run webfusion")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("webfusion-poses-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// The sample's first frames as a TUM directory; (directory, ground truth, depth timestamps).
fn tum_sample(dir: &Path) -> (PathBuf, Vec<TimedPose>, Vec<i64>) {
    let tum = dir.join("rgbd_dataset_freiburg1_rpy");
    let mut sample = RecordingReader::open(SAMPLE).expect("the sample");
    webfusion_core::io::tum::write_tum_dataset(&tum, &mut sample, 0..FRAMES).expect("the sample as a TUM directory");
    let gt = sample.ground_truth().expect("the sample has ground truth").to_vec();
    let stamps = (0..FRAMES).map(|i| sample.read_frame(i).expect("frame").depth_timestamp_ns).collect();
    (tum, gt, stamps)
}

fn run(args: &[&str]) -> (Output, serde_json::Value) {
    let o = webfusion(args);
    assert!(o.status.success(), "reconstruct failed: {}", String::from_utf8_lossy(&o.stderr));
    let out = Path::new(args[args.iter().position(|a| *a == "--out").expect("--out") + 1]);
    let stats = serde_json::from_str(&std::fs::read_to_string(out.join("stats.json")).expect("stats.json")).expect("json");
    (o, stats)
}

#[test]
fn frames_are_fused_at_the_given_poses_and_frames_without_one_are_skipped() {
    let dir = scratch("given");
    let (tum, gt, stamps) = tum_sample(&dir);
    // The poses with a hole: none between the 4th and the 8th frame's timestamps.
    let holed: Vec<TimedPose> = gt.iter().copied().filter(|p| !(stamps[4] - 5_000_000..stamps[8] + 5_000_000).contains(&p.timestamp_ns)).collect();
    let poses = dir.join("poses.txt");
    std::fs::write(&poses, format_tum_trajectory(&holed)).expect("poses file");
    let out = dir.join("out");
    let (o, stats) = run(&["reconstruct", tum.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8"), "--poses", poses.to_str().expect("utf-8"), "--voxel-size", "0.04", "--no-mesh"]);
    // What each frame must get: the timeline's pose at its depth timestamp, or nothing.
    let timeline = PoseTimeline::new(holed).expect("timeline");
    let expected: Vec<(i64, Option<webfusion_core::Se3>)> = stamps.iter().map(|&t| (t, timeline.pose_at(t, MAX_POSE_GAP_NS))).collect();
    let skipped: Vec<usize> = expected.iter().enumerate().filter(|(_, (_, p))| p.is_none()).map(|(i, _)| i).collect();
    assert!(!skipped.is_empty() && skipped.len() < FRAMES / 2, "the hole leaves some frames without a pose ({skipped:?})");
    assert_eq!(stats["given_poses"]["frames_without_pose"], serde_json::json!(skipped), "the frames without a pose are listed");
    assert_eq!(stats["fused_frames"], serde_json::json!(FRAMES - skipped.len()));
    let used = read_tum_trajectory(&out.join("trajectory.txt")).expect("trajectory.txt");
    let want: Vec<(i64, webfusion_core::Se3)> = expected.into_iter().filter_map(|(t, p)| p.map(|p| (t, p))).collect();
    assert_eq!(used.len(), want.len(), "one pose per fused frame");
    for (u, (t, p)) in used.iter().zip(&want) {
        let d = p.inverse() * u.world_from_camera;
        assert!(u.timestamp_ns == *t && d.translation_m.length() < 1e-9 && d.rotation_angle_rad() < 1e-9, "frame at {t}: {u:?} is not the given pose {p:?}");
    }
    assert!(String::from_utf8_lossy(&o.stdout).contains(&format!("{} frames had no given pose", skipped.len())), "the skipped frames are counted on stdout");
    assert!(stats["volume"]["sparse"]["blocks_used"].as_u64().unwrap_or(0) > 100, "the map holds the frames: {}", stats["volume"]);
}

#[test]
fn refine_tracks_from_the_given_poses_and_reports_how_far_it_moved_them() {
    let dir = scratch("refine");
    let (tum, _, _) = tum_sample(&dir);
    let out = dir.join("out");
    let gt = tum.join("groundtruth.txt");
    let (_, stats) = run(&["reconstruct", tum.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8"), "--poses", gt.to_str().expect("utf-8"), "--refine", "--voxel-size", "0.04", "--no-mesh"]);
    let refine = &stats["given_poses"]["refine"];
    assert_eq!(refine["frames"], serde_json::json!(FRAMES), "every frame's move is reported: {refine}");
    let max_m = refine["max_moved_m"].as_f64().expect("a number");
    assert!(max_m.is_finite() && max_m < 0.2, "tracking stays near the motion-capture poses ({max_m} m)");
    let lines = std::fs::read_to_string(out.join("refine.txt")).expect("refine.txt").lines().filter(|l| !l.starts_with('#')).count();
    assert_eq!(lines, FRAMES, "refine.txt has a line per frame");
}

#[test]
fn a_malformed_pose_file_is_a_clean_error_naming_its_line() {
    let dir = scratch("malformed");
    let (tum, _, _) = tum_sample(&dir);
    let poses = dir.join("poses.txt");
    std::fs::write(&poses, "# t tx ty tz qx qy qz qw\n1305031229.0 1 2 3 0 0 0 1\n1305031229.1 1 2 3 0 0 1\n").expect("poses file");
    let o = webfusion(&["reconstruct", tum.to_str().expect("utf-8"), "--out", dir.join("out").to_str().expect("utf-8"), "--poses", poses.to_str().expect("utf-8")]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && !err.contains("panicked"), "a clean failure: {err}");
    assert!(err.contains("poses.txt:3:") && err.contains("8 fields"), "the error names the file and line: {err}");
    // Poses that cover none of the frames: an error saying so, not an empty map.
    std::fs::write(&poses, "1.0 0 0 0 0 0 0 1\n").expect("poses file");
    let o = webfusion(&["reconstruct", tum.to_str().expect("utf-8"), "--out", dir.join("out2").to_str().expect("utf-8"), "--poses", poses.to_str().expect("utf-8")]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("no frame") && !err.contains("panicked"), "{err}");
}

/// The blocks of a map file (everything after the header and creation parameters), and its
/// header without the creation-parameters length and CRC.
fn map_body(path: &Path) -> (Vec<u8>, Vec<u8>) {
    let b = std::fs::read(path).expect("map file");
    let meta = u32::from_le_bytes(b[68..72].try_into().expect("4 bytes")) as usize;
    (b[96 + meta + 4..].to_vec(), b[..64].to_vec())
}

#[test]
fn a_saved_map_continued_at_later_poses_equals_one_run_for_both_kinds() {
    let dir = scratch("save-load");
    let (tum, _, _) = tum_sample(&dir);
    let gt = tum.join("groundtruth.txt");
    let (tum, gt) = (tum.to_str().expect("utf-8"), gt.to_str().expect("utf-8"));
    for kind in ["sparse", "dense"] {
        let path = |name: &str| dir.join(format!("{kind}-{name}")).to_str().expect("utf-8").to_owned();
        let (a, a_map, b, b_map, c, c_map) = (path("a"), path("a.wfm"), path("b"), path("b.wfm"), path("c"), path("c.wfm"));
        let settings = ["--map-kind", kind, "--voxel-size", "0.04", "--volume", "96", "--no-mesh", "--poses", gt];
        let (first_range, second_range) = (format!("0..{}", FRAMES / 2), format!("{}..{FRAMES}", FRAMES / 2));
        let mut first = vec!["reconstruct", tum, "--out", a.as_str(), "--frames", first_range.as_str(), "--save-map", a_map.as_str()];
        first.extend(settings);
        run(&first);
        let (o, _) = run(&["reconstruct", tum, "--out", b.as_str(), "--frames", second_range.as_str(), "--load-map", a_map.as_str(), "--save-map", b_map.as_str(), "--no-mesh", "--poses", gt]);
        assert!(String::from_utf8_lossy(&o.stdout).contains("loaded map"), "the map was loaded");
        let mut whole = vec!["reconstruct", tum, "--out", c.as_str(), "--save-map", c_map.as_str()];
        whole.extend(settings);
        run(&whole);
        let (continued, h1) = map_body(Path::new(&path("b.wfm")));
        let (one_run, h2) = map_body(Path::new(&path("c.wfm")));
        assert_eq!(h1, h2, "{kind}: the same map settings and placement");
        assert!(continued.len() > 10_000, "{kind}: the map holds blocks");
        assert!(continued == one_run, "{kind}: the continued map equals the one-run map block for block");
        // The up direction (the mean of the fused cameras' up axes): the continued map's, its
        // loaded half counted as the frames it was made from, is the one run's (to within the
        // loaded half's up being a unit vector where its cameras' mean was a little shorter).
        let up = |name: &str| read_map_file(Path::new(&path(name))).expect("map").header.up_in_map.expect("an up direction");
        let (up_b, up_c) = (glam::Vec3::from(up("b.wfm")), glam::Vec3::from(up("c.wfm")));
        assert!((up_b - up_c).length() < 1e-2 && (up_c.length() - 1.0).abs() < 1e-5, "{kind}: up {up_b} vs {up_c}");
        // Negative control: the first half alone differs.
        assert!(map_body(Path::new(&path("a.wfm"))).0 != one_run, "{kind}: half the frames make another map");
    }
    // A damaged map file: loading it is an error naming the damage; --skip-corrupt loads what
    // is intact, with a warning.
    let damaged = dir.join("damaged.wfm");
    let mut bytes = std::fs::read(dir.join("sparse-a.wfm")).expect("map");
    let at = bytes.len() - 5000;
    bytes[at] ^= 0x40;
    std::fs::write(&damaged, &bytes).expect("write");
    let d_out = dir.join("d");
    let args = ["reconstruct", tum, "--out", d_out.to_str().expect("utf-8"), "--frames", "0..2", "--no-mesh", "--poses", gt, "--load-map", damaged.to_str().expect("utf-8")];
    let o = webfusion(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("damaged.wfm") && err.contains("damaged block") && !err.contains("panicked"), "{err}");
    let mut skipping = args.to_vec();
    skipping.push("--skip-corrupt");
    let o = webfusion(&skipping);
    assert!(o.status.success() && String::from_utf8_lossy(&o.stderr).contains("1 damaged block record"), "{}", String::from_utf8_lossy(&o.stderr));
    // Not a map at all.
    let o = webfusion(&["reconstruct", tum, "--out", dir.join("e").to_str().expect("utf-8"), "--poses", gt, "--load-map", gt]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("not a webfusion map file") && !err.contains("panicked"), "{err}");
}

#[test]
fn robot_poses_in_the_thesis_convention_give_the_same_camera_poses() {
    // The ground truth re-expressed as seed 000's robot poses, one per frame in frame order:
    // x y z in cm, and α β γ with R = Rz(α) Ry(β) Rx(γ) · (Eq. 5.3's axis change)⁻¹.
    use glam::{DMat3, DVec3, EulerRot};
    let dir = scratch("robot");
    let (tum, gt, stamps) = tum_sample(&dir);
    let timeline = PoseTimeline::new(gt).expect("timeline");
    let poses: Vec<webfusion_core::Se3> = stamps.iter().map(|&t| timeline.pose_at(t, MAX_POSE_GAP_NS).expect("each sample frame has ground truth")).collect();
    let camera_from_sensor = DMat3::from_cols(DVec3::X, -DVec3::Z, DVec3::Y).transpose();
    let mut text = String::from("# x y z (cm) alpha beta gamma (rad)\n");
    for p in &poses {
        let sensor = DMat3::from_quat(p.rotation) * camera_from_sensor;
        let (a, b, g) = glam::DQuat::from_mat3(&sensor).to_euler(EulerRot::ZYX);
        let t = p.translation_m * 100.0;
        text += &format!("{} {} {} {a} {b} {g}\n", t.x, t.y, t.z);
    }
    let file = dir.join("robot.txt");
    std::fs::write(&file, text).expect("robot poses");
    let out = dir.join("out");
    let (_, stats) = run(&["reconstruct", tum.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8"), "--robot-poses", file.to_str().expect("utf-8"), "--voxel-size", "0.04", "--no-mesh"]);
    assert_eq!(stats["fused_frames"], serde_json::json!(FRAMES));
    let used = read_tum_trajectory(&out.join("trajectory.txt")).expect("trajectory.txt");
    for (u, p) in used.iter().zip(&poses) {
        let d = p.inverse() * u.world_from_camera;
        assert!(d.translation_m.length() < 1e-9 && d.rotation_angle_rad() < 1e-9, "{u:?} vs {p:?}");
    }
    // Fewer poses than frames: the frames past the list are skipped and listed.
    let short: String = std::fs::read_to_string(&file).expect("read").lines().take(5).map(|l| format!("{l}\n")).collect();
    std::fs::write(&file, short).expect("write");
    let (_, stats) = run(&["reconstruct", tum.to_str().expect("utf-8"), "--out", dir.join("out2").to_str().expect("utf-8"), "--robot-poses", file.to_str().expect("utf-8"), "--voxel-size", "0.04", "--no-mesh"]);
    assert_eq!(stats["given_poses"]["frames_without_pose"], serde_json::json!((4..FRAMES).collect::<Vec<_>>()), "frames past the list");
}
