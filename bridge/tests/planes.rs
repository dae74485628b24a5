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
    let o = webfusion(&["planes", recording.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8"), "--labels", "--no-world"]);
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
    assert!(!out.join("scene.glb").exists() && !out.join("planes.json").exists(), "--no-world writes no world model");
    assert_eq!(json["implementation"], "gpu");
    // The CPU reference finds the same planes (the GPU holds to it within 0.05° and 0.5 mm on
    // these scenes: tests/kernels/planes/pipeline.rs).
    let reference_out = dir.join("reference");
    let o = webfusion(&["planes", recording.to_str().expect("utf-8"), "--out", reference_out.to_str().expect("utf-8"), "--no-world", "--cpu-reference"]);
    assert!(o.status.success(), "planes --cpu-reference failed: {}", String::from_utf8_lossy(&o.stderr));
    let reference = frames_json(&reference_out);
    assert_eq!(reference["implementation"], "cpu-reference");
    for (g, c) in frames.iter().zip(reference["frames"].as_array().expect("frames")) {
        let (g, c) = (g["planes"].as_array().expect("planes"), c["planes"].as_array().expect("planes"));
        assert_eq!(g.len(), c.len());
        for (gp, cp) in g.iter().zip(c) {
            let (gn, cn) = (vec3(&gp["normal"]), vec3(&cp["normal"]));
            assert!(gn[0] * cn[0] + gn[1] * cn[1] + gn[2] * cn[2] > 0.05f64.to_radians().cos() && (gp["offset_m"].as_f64().unwrap() - cp["offset_m"].as_f64().unwrap()).abs() < 5e-4, "{gp} vs {cp}");
        }
    }
}

/// The parts of a `.glb` the checks need: its JSON and BIN chunks, each checked for length.
fn read_glb(path: &Path) -> (serde_json::Value, Vec<u8>) {
    let bytes = std::fs::read(path).expect("scene.glb");
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes")) as usize;
    assert_eq!(&bytes[0..4], b"glTF", "glTF magic");
    assert_eq!((u32_at(4), u32_at(8)), (2, bytes.len()), "version 2, total length");
    let json_len = u32_at(12);
    assert_eq!(&bytes[16..20], b"JSON", "the first chunk is JSON");
    let json: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).expect("JSON chunk");
    let bin_at = 20 + json_len;
    assert_eq!(&bytes[bin_at + 4..bin_at + 8], b"BIN\0", "the second chunk is BIN");
    let bin = bytes[bin_at + 8..bin_at + 8 + u32_at(bin_at)].to_vec();
    (json, bin)
}

/// A room corner seen from six poses, with the poses given: `planes.json` holds its three
/// planes in the poses' frame; `scene.glb` is valid glTF with a textured mesh per plane whose
/// vertices lie on it, and the OBJ scene references textures that exist.
/// One world plane (`planes.json`) per true plane, each within 1° and 1 cm of the true plane
/// its normal is nearest.
fn assert_world_planes_are_true(what: &str, planes: &[serde_json::Value], truth: &[webfusion_core::sim::plane_scenes::ScenePlane]) {
    assert_eq!(planes.len(), truth.len(), "{what}: {planes:?}");
    for p in planes {
        let n = vec3(&p["normal"]);
        let cos_to = |t: &webfusion_core::sim::plane_scenes::ScenePlane| t.normal.x * n[0] + t.normal.y * n[1] + t.normal.z * n[2];
        let t = truth.iter().max_by(|a, b| cos_to(a).total_cmp(&cos_to(b))).expect("truth");
        assert!(cos_to(t) > 1f64.to_radians().cos() && (p["offset_m"].as_f64().expect("offset") - t.offset_m).abs() < 0.01, "{what}: {p} is not {t:?}");
    }
}

#[test]
fn a_posed_room_corner_becomes_three_textured_world_planes() {
    use glam::{DQuat, DVec3};
    use webfusion_core::Se3;
    use webfusion_core::io::trajectory::{TimedPose, write_tum_trajectory};
    let dir = scratch("world");
    let base = PlaneScene::room_corner();
    let recording = dir.join("corner.wfr");
    let mut writer = RecordingWriter::create(&recording, RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 }, RecordingOptions::default()).expect("recording");
    let mut poses = Vec::new();
    for i in 0..6 {
        let t = f64::from(i) / 5.0 - 0.5;
        let mut scene = base.clone();
        scene.world_from_camera = Se3::new(DQuat::from_rotation_y((30.0 * t).to_radians()) * base.world_from_camera.rotation, DVec3::new(0.5 * t, 0.05 * t, 0.1 * t));
        let mut frame = scene.render(&K, Some(i + 1)).frame;
        frame.index = u64::from(i);
        let t_ns = i64::from(i) * 33_333_333;
        (frame.depth_timestamp_ns, frame.color_timestamp_ns) = (t_ns, t_ns);
        writer.write_frame(&frame).expect("frame");
        poses.push(TimedPose { timestamp_ns: t_ns, world_from_camera: scene.world_from_camera });
    }
    writer.finish().expect("finish");
    let pose_file = dir.join("poses.txt");
    write_tum_trajectory(&pose_file, &poses).expect("poses");
    let out = dir.join("out");
    let o = webfusion(&["planes", recording.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8"), "--poses", pose_file.to_str().expect("utf-8")]);
    assert!(o.status.success(), "planes failed: {}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("planes.json")).expect("planes.json")).expect("json");
    assert_eq!(json["poses"], "given");
    let planes = json["planes"].as_array().expect("planes");
    // In the world frame: the scene's planes as the first camera sees them, moved back.
    let truth: Vec<_> = base.planes_in_camera().into_iter().flatten().map(|p| p.in_frame(&base.world_from_camera.inverse())).collect();
    assert_world_planes_are_true("frames", planes, &truth);
    for p in planes {
        assert!(p["triangles"].as_u64().expect("triangles") > 0 && p["area_m2"].as_f64().expect("area") > 0.5, "{p}");
    }
    // The poses used, one per frame, as given.
    let used = webfusion_core::io::trajectory::read_tum_trajectory(&out.join("trajectory.txt")).expect("trajectory.txt");
    assert_eq!(used.len(), poses.len());
    for (u, p) in used.iter().zip(&poses) {
        assert_eq!(u.timestamp_ns, p.timestamp_ns);
        assert!((u.world_from_camera.translation_m - p.world_from_camera.translation_m).length() < 1e-4);
    }
    // Every frame's planes name the world plane they joined.
    for frame in frames_json(&out)["frames"].as_array().expect("frames") {
        for p in frame["planes"].as_array().expect("planes") {
            assert!(planes.iter().any(|w| w["id"] == p["world_plane"]), "{p} names no plane of planes.json");
        }
    }
    let c = &json["compactness"];
    assert!(c["planar_triangles"].as_u64().expect("count") * 10 < c["marching_cubes_triangles_replaced"].as_u64().expect("count"), "the quadtree is not compact: {c}");
    // The glTF scene: a mesh per plane and the remainder, every accessor inside the BIN
    // chunk, textures that decode, vertices on their planes.
    let (gltf, bin) = read_glb(&out.join("scene.glb"));
    let meshes = gltf["meshes"].as_array().expect("meshes");
    assert_eq!(meshes.iter().filter(|m| m["name"].as_str().is_some_and(|n| n.starts_with("plane_"))).count(), planes.len());
    let views = gltf["bufferViews"].as_array().expect("views");
    for v in views {
        assert!(v["byteOffset"].as_u64().expect("offset") + v["byteLength"].as_u64().expect("length") <= bin.len() as u64);
    }
    let view_bytes = |i: u64| {
        let v = &views[i as usize];
        let o = v["byteOffset"].as_u64().expect("offset") as usize;
        &bin[o..o + v["byteLength"].as_u64().expect("length") as usize]
    };
    for image in gltf["images"].as_array().expect("images") {
        let png = view_bytes(image["bufferView"].as_u64().expect("view"));
        assert_eq!(&png[1..4], b"PNG");
    }
    let accessors = gltf["accessors"].as_array().expect("accessors");
    for m in meshes.iter().filter(|m| m["name"].as_str().is_some_and(|n| n.starts_with("plane_"))) {
        let prim = &m["primitives"][0];
        let positions = &accessors[prim["attributes"]["POSITION"].as_u64().expect("POSITION") as usize];
        let floats: Vec<f32> = view_bytes(positions["bufferView"].as_u64().expect("view")).chunks(4).map(|b| f32::from_le_bytes(b.try_into().expect("4"))).collect();
        assert_eq!(floats.len() as u64, 3 * positions["count"].as_u64().expect("count"));
        let worst = floats.chunks(3).map(|p| truth.iter().map(|t| (t.normal.x * f64::from(p[0]) + t.normal.y * f64::from(p[1]) + t.normal.z * f64::from(p[2]) + t.offset_m).abs()).fold(f64::INFINITY, f64::min)).fold(0.0, f64::max);
        assert!(worst < 0.01, "{}: a vertex {worst} m off every true plane", m["name"]);
        assert!(prim["material"].is_u64() && prim["attributes"]["TEXCOORD_0"].is_u64());
    }
    let obj = std::fs::read_to_string(out.join("scene.obj")).expect("scene.obj");
    assert_eq!(obj.lines().filter(|l| l.starts_with("o plane_")).count(), planes.len());
    let mtl = std::fs::read_to_string(out.join("scene.mtl")).expect("scene.mtl");
    for line in mtl.lines().filter_map(|l| l.strip_prefix("map_Kd ")) {
        assert!(out.join(line).is_file(), "{line} missing");
    }
    // The fused map segmented instead of the frames (--from-model): each frame's depth is the
    // map's at its pose, where six noisy views were averaged, so the same three world planes
    // come back and each frame's planes fit their points more tightly than the raw frame's.
    let model_out = dir.join("model");
    let o = webfusion(&["planes", recording.to_str().expect("utf-8"), "--out", model_out.to_str().expect("utf-8"), "--poses", pose_file.to_str().expect("utf-8"), "--from-model"]);
    assert!(o.status.success(), "planes --from-model failed: {}", String::from_utf8_lossy(&o.stderr));
    let model_json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(model_out.join("planes.json")).expect("planes.json")).expect("json");
    assert_eq!((&model_json["depth"], &json["depth"]), (&serde_json::json!("model"), &serde_json::json!("sensor")));
    let model_planes = model_json["planes"].as_array().expect("planes");
    assert_world_planes_are_true("model", model_planes, &truth);
    let model_frames = frames_json(&model_out);
    assert_eq!((&model_frames["depth"], &model_frames["frames_without_pose"]), (&serde_json::json!("model"), &serde_json::json!(0)));
    let median_rms = |frames: &serde_json::Value| {
        let mut rms: Vec<f64> = frames["frames"].as_array().expect("frames").iter().flat_map(|f| f["planes"].as_array().expect("planes").iter().map(|p| p["rms_m"].as_f64().expect("rms"))).collect();
        rms.sort_by(f64::total_cmp);
        rms[rms.len() / 2]
    };
    let (rms_model, rms_sensor) = (median_rms(&model_frames), median_rms(&frames_json(&out)));
    eprintln!("median plane rms: model {:.2} mm, frames {:.2} mm", rms_model * 1e3, rms_sensor * 1e3);
    assert!(rms_model < rms_sensor, "the model's planes fit no more tightly ({rms_model} m) than the frames' ({rms_sensor} m)");

    // The same poses as seed 000's robot poses (x y z in cm, α β γ with R = Rz(α) Ry(β) Rx(γ) ·
    // (Eq. 5.3's axis change)⁻¹), one per frame in frame order: the same world planes.
    let camera_from_sensor = glam::DMat3::from_cols(DVec3::X, -DVec3::Z, DVec3::Y).transpose();
    let robot: String = poses
        .iter()
        .map(|p| {
            let sensor = glam::DMat3::from_quat(p.world_from_camera.rotation) * camera_from_sensor;
            let (a, b, g) = DQuat::from_mat3(&sensor).to_euler(glam::EulerRot::ZYX);
            let t = p.world_from_camera.translation_m * 100.0;
            format!("{} {} {} {a} {b} {g}\n", t.x, t.y, t.z)
        })
        .collect();
    let robot_file = dir.join("robot.txt");
    std::fs::write(&robot_file, robot).expect("robot poses");
    let robot_out = dir.join("robot-out");
    let o = webfusion(&["planes", recording.to_str().expect("utf-8"), "--out", robot_out.to_str().expect("utf-8"), "--robot-poses", robot_file.to_str().expect("utf-8")]);
    assert!(o.status.success(), "planes --robot-poses failed: {}", String::from_utf8_lossy(&o.stderr));
    let robot_json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(robot_out.join("planes.json")).expect("planes.json")).expect("json");
    assert_eq!(robot_json["poses"], "given");
    let robot_planes = robot_json["planes"].as_array().expect("planes");
    assert_eq!(robot_planes.len(), planes.len());
    for (r, p) in robot_planes.iter().zip(planes) {
        let (rn, pn) = (vec3(&r["normal"]), vec3(&p["normal"]));
        let cos = rn[0] * pn[0] + rn[1] * pn[1] + rn[2] * pn[2];
        assert!(cos > 0.01f64.to_radians().cos() && (r["offset_m"].as_f64().expect("offset") - p["offset_m"].as_f64().expect("offset")).abs() < 1e-3, "{r} vs {p}");
    }
    // Fewer robot poses than frames: the frames past the list are left out of the world.
    let short: String = std::fs::read_to_string(&robot_file).expect("read").lines().take(4).map(|l| format!("{l}\n")).collect();
    std::fs::write(&robot_file, short).expect("write");
    let o = webfusion(&["planes", recording.to_str().expect("utf-8"), "--out", dir.join("robot-short").to_str().expect("utf-8"), "--robot-poses", robot_file.to_str().expect("utf-8")]);
    assert!(o.status.success(), "planes --robot-poses (short) failed: {}", String::from_utf8_lossy(&o.stderr));
    let short_json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("robot-short/planes.json")).expect("planes.json")).expect("json");
    assert_eq!(short_json["frames_with_pose"], 4);
    assert_eq!(short_json["frames_left_out"], serde_json::json!([4, 5]));
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
    // The world model, tracked: the desk and the partition at least, in a scene that parses.
    let world: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("planes.json")).expect("planes.json")).expect("json");
    assert_eq!(world["poses"], "tracked");
    assert_eq!(world["frames_with_pose"], 3);
    assert!(world["planes"].as_array().expect("planes").len() >= 2, "{world}");
    let (gltf, _) = read_glb(&out.join("scene.glb"));
    assert!(gltf["meshes"].as_array().expect("meshes").iter().any(|m| m["name"] == "remainder"));
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
