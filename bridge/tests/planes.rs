// SPDX-License-Identifier: MIT
//! `webfusion planes` through the binary: synthetic scenes with exact planes written as a
//! recording come back in `frames.json` as those planes (camera frame, n·p + d = 0, normal
//! facing the camera), real frames of the bundled sample give planes, and bad input gives
//! clean errors.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use webfusion_core::recording::{RecordingOptions, RecordingWriter};
use webfusion_core::sim::plane_scenes::{PlaneScene, UNITS_PER_METRE};
use webfusion_core::{PinholeIntrinsics, RgbdCalibration};

const SAMPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/sample/fr1_rpy.wfr");
const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };

fn webfusion(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_webfusion")).args(args).env("XDG_RUNTIME_DIR", std::env::temp_dir()).output().expect("run webfusion")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("webfusion-planes-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn frames_json(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("frames.json")).expect("frames.json")).expect("json")
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    std::array::from_fn(|i| v[i].as_f64().expect("a number"))
}

#[test]
fn synthetic_planes_come_back_exactly() {
    let dir = scratch("synthetic");
    let scenes = [PlaneScene::whiteboard(), PlaneScene::box_on_floor()];
    let recording = dir.join("scenes.wfr");
    let mut writer = RecordingWriter::create(&recording, RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 }, RecordingOptions::default()).expect("recording");
    for (i, scene) in scenes.iter().enumerate() {
        let mut frame = scene.render(&K, Some(1)).frame;
        frame.index = i as u64;
        (frame.depth_timestamp_ns, frame.color_timestamp_ns) = (i as i64 * 33_333_333, i as i64 * 33_333_333);
        writer.write_frame(&frame).expect("frame");
    }
    writer.finish().expect("finish");
    let out = dir.join("out");
    let o = webfusion(&["planes", recording.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8"), "--labels"]);
    assert!(o.status.success(), "planes failed: {}", String::from_utf8_lossy(&o.stderr));
    let json = frames_json(&out);
    let frames = json["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), 2);
    for (i, (frame, scene)) in frames.iter().zip(&scenes).enumerate() {
        assert_eq!(frame["index"], i);
        assert!((frame["timestamp"].as_f64().expect("timestamp") - i as f64 / 30.0).abs() < 1e-6);
        assert!(frame["stages_ms"]["segment"].as_f64().expect("stage time") > 0.0);
        let found = frame["planes"].as_array().expect("planes");
        // Every true plane over 2 % of the image is found within 1° and 1 cm, and nothing else.
        let big: Vec<_> = {
            let r = scene.render(&K, None);
            let truth = scene.planes_in_camera();
            (0..truth.len()).filter(|&s| r.plane_of_pixel.iter().filter(|&&l| l == s as u32).count() * 50 > K.pixel_count()).filter_map(|s| truth[s]).collect()
        };
        let matches = |p: &serde_json::Value, t: &webfusion_core::sim::plane_scenes::ScenePlane| {
            let n = vec3(&p["normal"]);
            let cos = n[0] * t.normal.x + n[1] * t.normal.y + n[2] * t.normal.z;
            cos > 1f64.to_radians().cos() && (p["offset_m"].as_f64().expect("offset") - t.offset_m).abs() < 0.01
        };
        for t in &big {
            assert!(found.iter().any(|p| matches(p, t)), "{}: the plane {t:?} was not found in {found:?}", scene.name);
        }
        let truth: Vec<_> = scene.planes_in_camera().into_iter().flatten().collect();
        for p in found {
            assert!(truth.iter().any(|t| matches(p, t)), "{}: {p} is no true plane", scene.name);
        }
        let label_image = out.join(format!("labels/{}.png", webfusion_core::io::format_timestamp_s(i as i64 * 33_333_333)));
        assert!(label_image.is_file(), "{} written", label_image.display());
    }
}

#[test]
fn real_frames_give_planes_facing_the_camera() {
    let dir = scratch("sample");
    let out = dir.join("out");
    let o = webfusion(&["planes", SAMPLE, "--out", out.to_str().expect("utf-8"), "--frames", "0..3"]);
    assert!(o.status.success(), "planes failed: {}", String::from_utf8_lossy(&o.stderr));
    let json = frames_json(&out);
    let frames = json["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), 3);
    for frame in frames {
        let planes = frame["planes"].as_array().expect("planes");
        // The desk and the partition at least.
        assert!(planes.len() >= 2, "frame {}: {} planes", frame["index"], planes.len());
        for p in planes {
            let n = vec3(&p["normal"]);
            let c = vec3(&p["centroid_m"]);
            let d = p["offset_m"].as_f64().expect("offset");
            assert!(((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() - 1.0).abs() < 1e-4, "unit normal {n:?}");
            assert!(d > 0.0 && n[0] * c[0] + n[1] * c[1] + n[2] * c[2] < 0.0, "facing the camera: {p}");
            assert!((n[0] * c[0] + n[1] * c[1] + n[2] * c[2] + d).abs() < 1e-3, "the centroid lies on the plane: {p}");
            assert!(p["pixels"].as_u64().expect("pixels") > 3000 && p["area_m2"].as_f64().expect("area") > 0.0);
        }
    }
}

#[test]
fn bad_input_is_a_clean_error() {
    let dir = scratch("bad");
    let out = dir.join("out");
    std::fs::create_dir_all(&out).expect("out");
    std::fs::write(out.join("frames.json"), "{}").expect("an earlier result");
    let o = webfusion(&["planes", SAMPLE, "--out", out.to_str().expect("utf-8"), "--frames", "0..1"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("exists already"), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read_to_string(out.join("frames.json")).expect("kept"), "{}", "the earlier result is untouched");
    let o = webfusion(&["planes", SAMPLE, "--out", dir.join("o2").to_str().expect("utf-8"), "--frames", "5..2"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--frames"), "{}", String::from_utf8_lossy(&o.stderr));
    let o = webfusion(&["planes", dir.join("missing.wfr").to_str().expect("utf-8"), "--out", dir.join("o3").to_str().expect("utf-8")]);
    assert!(!o.status.success() && !String::from_utf8_lossy(&o.stderr).contains("panicked"), "{}", String::from_utf8_lossy(&o.stderr));
}
