// SPDX-License-Identifier: MIT
//! `plane_overlay`: the world planes' textured quadtree meshes drawn into a view, GPU against
//! the CPU twin, on a room corner built from three exact views and drawn from a fourth pose
//! none of them had (where the truth is known: every drawn pixel must show the scene's wall
//! with the scene's colour), behind a nearer surface (nothing drawn) and on its own surface
//! (everything drawn), and on a real frame's planes drawn back over it.
//!
//! Tolerance: the texel a ray lands on is `floor` of an f32 dot product; a GPU that fuses a
//! multiply-add may land one texel over at a texel's edge, so at most 2 ‰ of the pixels may
//! differ (none did on lavapipe when this was written). The padding must stay untouched.

use glam::{DQuat, DVec3};
use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::fusion::predictor::camera_pose;
use webfusion_core::kernels::gpu_data::{CameraPose, PlaneOverlayParams};
use webfusion_core::planes::mesh::{blend_reach_px, complete_labels};
use webfusion_core::planes::overlay::{DEFAULT_MAX_OVERLAY_TEXELS, OverlayModel, OverlayTarget, PlaneOverlay};
use webfusion_core::planes::world::{PlaneView, PlaneWorld, WorldConfig};
use webfusion_core::planes::{PlaneConfig, reference};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::sim::plane_scenes::{NO_PLANE, PlaneScene, UNITS_PER_METRE};
use webfusion_core::{PinholeIntrinsics, RgbdCalibration, Se3};
use webfusion_tests::{SENTINEL_F32, Slot, cast, compare_u32_mostly, finish, gpu, run_kernel_slots, sample_frame};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };
/// Rows of the drawn image, padded (the padding must stay the sentinel).
const STRIDE_PX: u32 = 384;
/// Allowed GPU-twin differences, per mille (see the module doc).
const MAX_DIFFER_PER_MILLE: usize = 2;
const OCCLUSION_M: f32 = 0.015;
/// Distance from a check's edge within which a texel may take the other side's colour: a
/// texel and a half at 128 texels per metre.
const CHECK_EDGE_MARGIN_M: f64 = 0.012;
/// Cosine of the largest angle between a ray and a wall's normal at which colours are
/// compared with the scene's (60°).
const MIN_INCIDENCE_COS: f64 = 0.5;

/// A room corner's world model from three exact, noise-free views sweeping 30° and 30 cm, the
/// scene at its base pose, and the views' poses.
fn room_corner_world() -> (PlaneScene, PlaneWorld, Vec<Se3>) {
    let base = PlaneScene::room_corner();
    let (config, pre_config) = (PlaneConfig::default(), PreprocessConfig::default());
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 };
    let mut world = PlaneWorld::new(WorldConfig::default());
    let mut poses = Vec::new();
    for v in 0..3 {
        let t = f64::from(v) / 2.0 - 0.5;
        let mut scene = base.clone();
        scene.world_from_camera = Se3::new(DQuat::from_rotation_y((30.0 * t).to_radians()) * base.world_from_camera.rotation, base.world_from_camera.translation_m + DVec3::new(0.3 * t, 0.0, 0.0));
        let r = scene.render(&K, None);
        let pre = preprocess(&calibration, &pre_config, &r.frame);
        let seg = reference::segment(&pre.levels, Some(&pre.depth_unfiltered_m), &config);
        let labels = complete_labels(&seg, &pre.depth_unfiltered_m, &K, &config, blend_reach_px(&pre_config));
        let view = PlaneView { index: v as u64, world_from_camera: scene.world_from_camera, segmentation: &seg, labels: &labels, colour: &r.frame.color, intrinsics: K };
        world.add_frame(&view, &config);
        poses.push(scene.world_from_camera);
    }
    (base, world, poses)
}

fn params(plane_count: usize) -> PlaneOverlayParams {
    PlaneOverlayParams { intrinsics: K.into(), row_stride_px: STRIDE_PX, plane_count: plane_count as u32, near_m: 0.1, far_m: 10.0, occlusion_m: OCCLUSION_M, ..Default::default() }
}

/// The overlay drawn over a sentinel image by the GPU and by the twin.
fn draw(p: &PlaneOverlayParams, pose: &CameraPose, model: &OverlayModel, depth_m: &[f32]) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let image = vec![SENTINEL_F32.to_bits(); (STRIDE_PX * K.height_px) as usize];
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.plane_overlay,
        p,
        &[Slot::In(bytemuck::bytes_of(pose)), Slot::In(bytemuck::cast_slice(&model.planes)), Slot::In(bytemuck::cast_slice(&model.texels)), Slot::In(bytemuck::cast_slice(depth_m)), Slot::InOut(bytemuck::cast_slice(&image))],
        [K.width_px, K.height_px, 1],
    );
    finish(&gpu);
    let mut c = image;
    cpu::plane_overlay(p, pose, &model.planes, &model.texels, depth_m, &mut c);
    (cast(&out[0]), c)
}

/// GPU against twin, with the negative controls: a moved colour, an erased pixel and a
/// written padding pixel, each in 1 % of the pixels, must fail the comparison.
fn compare(what: &str, g: &[u32], c: &[u32]) -> usize {
    let differ = compare_u32_mostly(what, g, c, MAX_DIFFER_PER_MILLE).unwrap();
    let drawn: Vec<usize> = (0..c.len()).filter(|&i| c[i] != SENTINEL_F32.to_bits()).collect();
    let padding: Vec<usize> = (0..c.len()).filter(|&i| i % STRIDE_PX as usize >= K.width_px as usize).collect();
    let many = c.len() / 100;
    assert!(drawn.len() > many, "{what}: too few drawn pixels ({}) for the controls", drawn.len());
    for (case, at, value) in [("a moved colour", &drawn, None), ("an erased pixel", &drawn, Some(SENTINEL_F32.to_bits())), ("a written padding pixel", &padding, Some(0xff00_0000))] {
        let mut bad = g.to_vec();
        for &i in at.iter().take(many) {
            bad[i] = value.unwrap_or(bad[i] ^ 0x10);
        }
        assert!(compare_u32_mostly(what, &bad, c, MAX_DIFFER_PER_MILLE).is_err(), "{what}: the comparison accepted {case}");
    }
    assert!(padding.iter().all(|&i| g[i] == SENTINEL_F32.to_bits()), "{what}: padding written");
    differ
}

#[test]
fn a_room_corner_drawn_from_a_new_pose_matches_the_twin_and_the_scene() {
    let (base, world, views) = room_corner_world();
    let model = OverlayModel::from_world(&world, DEFAULT_MAX_OVERLAY_TEXELS);
    assert_eq!((model.planes.len(), model.left_out), (world.live().count(), 0));
    // A pose none of the views had: 10° about y the other way round from the middle one and
    // 12 cm up, 15 cm nearer.
    let mut scene = base.clone();
    scene.world_from_camera = Se3::new(DQuat::from_rotation_y(8f64.to_radians()) * DQuat::from_rotation_x(-5f64.to_radians()) * base.world_from_camera.rotation, base.world_from_camera.translation_m + DVec3::new(0.05, -0.12, 0.15));
    let truth = scene.render(&K, None);
    let pose = camera_pose(Some(&scene.world_from_camera));
    let none = vec![f32::NAN; K.pixel_count()];
    let (g, c) = draw(&params(model.planes.len()), &pose, &model, &none);
    let differ = compare("room corner, no surface", &g, &c);
    // Against the scene: a drawn pixel shows a wall, in the wall's colour (10 cm checks on a
    // shade per wall) wherever it is not near a check's edge.
    let walls: Vec<_> = scene.planes_in_camera().iter().map(|p| p.map(|p| p.in_frame(&scene.world_from_camera.inverse()))).collect();
    let (mut drawn, mut on_wall, mut away_from_edges, mut same_colour, mut wall_px) = (0, 0, 0, 0, 0);
    for y in 0..K.height_px as usize {
        for x in 0..K.width_px as usize {
            let (i, o) = (y * K.width_px as usize + x, y * STRIDE_PX as usize + x);
            wall_px += usize::from(truth.plane_of_pixel[i] != NO_PLANE);
            if c[o] == SENTINEL_F32.to_bits() {
                continue;
            }
            drawn += 1;
            on_wall += usize::from(truth.plane_of_pixel[i] != NO_PLANE);
            // The scene's point at this pixel, and its distance to the nearest check edge
            // (the planes x, y, z = 10 cm multiples across the wall).
            let z_m = f64::from(truth.frame.depth.units[i]) / UNITS_PER_METRE;
            let p = scene.world_from_camera.transform_point(DVec3::new((x as f64 - f64::from(K.cx_px)) * z_m / f64::from(K.fx_px), (y as f64 - f64::from(K.cy_px)) * z_m / f64::from(K.fy_px), z_m));
            let normal = walls[truth.plane_of_pixel[i] as usize].expect("a wall").normal;
            let across = normal.abs().max_position();
            let edge_m = (0..3).filter(|&a| a != across).map(|a| (p[a] / 0.1 - (p[a] / 0.1).round()).abs() * 0.1).fold(f64::INFINITY, f64::min);
            // A texel took the colour of the pixel its centre fell in, in each view that saw
            // it: within a pixel's footprint on the wall of an edge it may have the other
            // side's colour. Only where every view and this one see the wall within 60° of
            // its normal: at grazing angles a millimetre of error in a plane's fit moves the
            // point a ray meets it along the wall by centimetres.
            let seen_from = |eye: DVec3| ((p - eye).normalize().dot(normal)).abs();
            if views.iter().chain([&scene.world_from_camera]).any(|v| seen_from(v.translation_m) < MIN_INCIDENCE_COS) {
                continue;
            }
            let footprint_m = views.iter().map(|v| {
                let ray = p - v.translation_m;
                let z = (v.rotation.inverse() * ray).z;
                let cos = (ray.normalize().dot(normal)).abs().max(0.05);
                z / (f64::from(K.fx_px) * cos)
            }).fold(0.0, f64::max);
            if edge_m < CHECK_EDGE_MARGIN_M + footprint_m {
                continue;
            }
            away_from_edges += 1;
            let rgb = &truth.frame.color.rgb8[3 * i..3 * i + 3];
            let px = c[o].to_le_bytes();
            same_colour += usize::from((0..3).all(|a| px[a].abs_diff(rgb[a]) <= 8));
        }
    }
    let f = |n: usize, of: usize| n as f64 / of.max(1) as f64;
    eprintln!("{} planes; {drawn} of {wall_px} wall pixels drawn, {:.2} % on a wall, {:.2} % of {away_from_edges} away from check edges in its colour; {differ} differ from the twin", model.planes.len(), 100.0 * f(on_wall, drawn), 100.0 * f(same_colour, away_from_edges));
    assert!(f(on_wall, drawn) >= 0.995, "drawn off the walls");
    // 95.9 % when this was written: a texel's colour is the mean over the views that saw it,
    // each sampling it with the plane as it was fitted then, so on walls seen obliquely the
    // views disagree a few centimetres from an edge. The mapping itself is exact (the test
    // below).
    assert!(f(same_colour, away_from_edges) >= 0.93, "drawn in the wrong colours");
    assert!(f(drawn, wall_px) >= 0.9, "the walls the views saw are drawn");

    // Behind a surface 30 % nearer than the walls along every ray, nothing shows; on the walls'
    // own surface, everything does.
    let z: Vec<f32> = truth.frame.depth.units.iter().map(|&u| if u == 0 { f32::NAN } else { f32::from(u) / UNITS_PER_METRE as f32 }).collect();
    let nearer: Vec<f32> = z.iter().map(|z| 0.7 * z).collect();
    let (g_near, c_near) = draw(&params(model.planes.len()), &pose, &model, &nearer);
    compare_u32_mostly("room corner, nearer surface", &g_near, &c_near, MAX_DIFFER_PER_MILLE).unwrap();
    let hidden_drawn = c_near.iter().filter(|&&p| p != SENTINEL_F32.to_bits()).count();
    assert!(hidden_drawn * 1000 <= drawn, "{hidden_drawn} pixels drawn behind a nearer surface");
    let (g_own, c_own) = draw(&params(model.planes.len()), &pose, &model, &z);
    compare("room corner, its own surface", &g_own, &c_own);
    let own_drawn = c_own.iter().filter(|&&p| p != SENTINEL_F32.to_bits()).count();
    assert!(own_drawn * 1000 >= 998 * drawn, "on their own surface {own_drawn} of {drawn} drawn");

    // The host's path (upload and draw) draws what the kernel did.
    let gpu = gpu();
    let mut overlay = PlaneOverlay::new(&gpu, "test.plane_overlay");
    overlay.upload(&gpu, &model).unwrap();
    let depth = gpu.storage_buffer::<f32>("test.depth", K.pixel_count());
    gpu.write_buffer(&depth, &none);
    let image = gpu.storage_buffer::<u32>("test.image", (STRIDE_PX * K.height_px) as usize);
    gpu.fill_buffer(&image, SENTINEL_F32.to_bits());
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test.plane_overlay") });
    overlay.draw(&gpu, &mut encoder, &OverlayTarget { intrinsics: K, depth_m: &depth, rgba8: &image, row_stride_px: STRIDE_PX }, &scene.world_from_camera, (0.1, 10.0), OCCLUSION_M);
    gpu.submit([encoder.finish()]);
    let host: Vec<u32> = pollster::block_on(gpu.read_buffer::<u32>(&image, (STRIDE_PX * K.height_px) as usize)).expect("readback");
    assert_eq!(host, g, "PlaneOverlay::draw draws what the kernel drew");
}

#[test]
fn a_real_frames_planes_drawn_back_over_it_match_the_twin_and_its_labels() {
    let (calibration, frame) = sample_frame(0);
    let (config, pre_config) = (PlaneConfig::default(), PreprocessConfig::default());
    let k = calibration.intrinsics;
    let pre = preprocess(&calibration, &pre_config, &frame);
    let seg = reference::segment(&pre.levels, Some(&pre.depth_unfiltered_m), &config);
    let labels = complete_labels(&seg, &pre.depth_unfiltered_m, &k, &config, blend_reach_px(&pre_config));
    let mut world = PlaneWorld::new(WorldConfig::default());
    let view = PlaneView { index: 0, world_from_camera: Se3::IDENTITY, segmentation: &seg, labels: &labels, colour: &frame.color, intrinsics: k };
    world.add_frame(&view, &config);
    let model = OverlayModel::from_world(&world, DEFAULT_MAX_OVERLAY_TEXELS);
    assert!(model.planes.len() >= 2, "the desk and the partition");
    let stride = k.width_px.next_multiple_of(64);
    let p = PlaneOverlayParams { intrinsics: k.into(), row_stride_px: stride, plane_count: model.planes.len() as u32, near_m: 0.1, far_m: 10.0, occlusion_m: OCCLUSION_M, ..Default::default() };
    let gpu = gpu();
    let image = vec![SENTINEL_F32.to_bits(); (stride * k.height_px) as usize];
    let pose = camera_pose(Some(&Se3::IDENTITY));
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.plane_overlay,
        &p,
        &[Slot::In(bytemuck::bytes_of(&pose)), Slot::In(bytemuck::cast_slice(&model.planes)), Slot::In(bytemuck::cast_slice(&model.texels)), Slot::In(bytemuck::cast_slice(&pre.depth_unfiltered_m)), Slot::InOut(bytemuck::cast_slice(&image))],
        [k.width_px, k.height_px, 1],
    );
    finish(&gpu);
    let g: Vec<u32> = cast(&out[0]);
    let mut c = image;
    cpu::plane_overlay(&p, &pose, &model.planes, &model.texels, &pre.depth_unfiltered_m, &mut c);
    let differ = compare_u32_mostly("real frame", &g, &c, MAX_DIFFER_PER_MILLE).unwrap();
    let mut moved = g.clone();
    let drawn: Vec<usize> = (0..c.len()).filter(|&i| c[i] != SENTINEL_F32.to_bits()).collect();
    drawn.iter().take(c.len() / 100).for_each(|&i| moved[i] ^= 0x10);
    assert!(compare_u32_mostly("real frame", &moved, &c, MAX_DIFFER_PER_MILLE).is_err(), "the comparison accepted moved colours");
    // At the frame's own pose the planes cover the pixels labelled with them, and little else
    // (a quad's outline follows the labels to a 2 x 2-texel cell).
    let w = k.width_px as usize;
    let labelled = labels.iter().filter(|&&l| l != webfusion_core::planes::NO_LABEL).count();
    let on_label = drawn.iter().filter(|&&o| labels[(o / stride as usize) * w + o % stride as usize] != webfusion_core::planes::NO_LABEL).count();
    eprintln!("{} planes; {} drawn, {labelled} labelled, {on_label} drawn on a label; {differ} differ from the twin", model.planes.len(), drawn.len());
    assert!(on_label as f64 >= 0.9 * labelled as f64, "the labelled pixels are drawn");
    assert!(drawn.len() - on_label <= drawn.len() / 20, "little is drawn off the labels");
}

/// Every vertex of every world plane's mesh lands, through the overlay's texel mapping, on
/// the lattice point of the texel grid it was built at (its texture coordinate times the
/// padded grid): the overlay reads the texel the mesh would show there.
#[test]
fn the_overlays_texel_mapping_puts_every_mesh_vertex_on_its_lattice_point() {
    let (_, world, _) = room_corner_world();
    let model = OverlayModel::from_world(&world, DEFAULT_MAX_OVERLAY_TEXELS);
    let mut meshes: Vec<_> = world.live().filter_map(|j| world.mesh(j)).collect();
    meshes.sort_by(|a, b| b.area_m2.total_cmp(&a.area_m2));
    assert_eq!(meshes.len(), model.planes.len());
    for (mesh, q) in meshes.iter().zip(&model.planes) {
        let g = &mesh.grid;
        assert_eq!((q.width, q.height), (g.width, g.height));
        let (pw, ph) = (g.width.next_power_of_two() as f32, g.height.next_power_of_two() as f32);
        let at = |row: [f32; 4], p: &[f32; 3]| row[0] * p[0] + row[1] * p[1] + row[2] * p[2] + row[3];
        let worst = mesh.positions_m.iter().zip(&mesh.uv).map(|(p, uv)| (at(q.to_texel_x, p) - uv[0] * pw).abs().max((at(q.to_texel_y, p) - uv[1] * ph).abs())).fold(0.0f32, f32::max);
        eprintln!("grid {}x{}: {} vertices, worst {worst} texel off", g.width, g.height, mesh.positions_m.len());
        assert!(worst < 1e-3, "a vertex {worst} texels off its lattice point");
        // A texel a quad covers carries the mesh texture's colour; one no quad covers, none.
        let covered = mesh.cells.iter().filter(|&&c| c).count();
        let opaque = model.texels[q.first_texel as usize..(q.first_texel + g.width * g.height) as usize].iter().filter(|&&w| w >> 24 == 0xff).count();
        assert_eq!(covered, opaque);
    }
}
