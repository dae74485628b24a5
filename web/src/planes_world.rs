// SPDX-License-Identifier: MIT
//! Seed 003's world model in the page, as `webfusion planes` builds it natively: planes that
//! persist across frames, with one texture each, and the scene as one `.glb` (the textured
//! planar quadtree meshes plus the fused mesh less what they cover).
//!
//! At most once every [`WORLD_INTERVAL_MS`], a frame that is segmented anyway has its labels,
//! completed for meshing on the GPU (`plane_window`, `plane_complete`), read back with its
//! plane table (4 bytes a pixel, once a second instead of every frame); when they and the
//! frame's tracked pose (its report) have both arrived, its planes join the world on the CPU
//! (`PlaneWorld::add_frame`: association, texel accumulation, merging). A frame whose tracking
//! was lost is left out. Poses are the pipeline's own (the fused mesh's frame); a rebuilt
//! pipeline starts a new world.

use std::collections::VecDeque;

use web_time::Instant;
use webfusion_core::mesh::Mesh;
use webfusion_core::planes::export::{mesh_remainder, write_scene_glb};
use webfusion_core::planes::mesh::PlaneMesh;
use webfusion_core::planes::overlay::{DEFAULT_MAX_OVERLAY_TEXELS, OverlayModel};
use webfusion_core::planes::world::{PlaneView, PlaneWorld, WorldConfig};
use webfusion_core::planes::{PlaneConfig, Segmentation};
use webfusion_core::{ColorImage, RgbdCalibration, Se3};

use crate::status::Window;

/// Least time between two frames the world model takes, milliseconds.
pub(crate) const WORLD_INTERVAL_MS: f64 = 1000.0;

/// A frame whose labels were asked for, until its labels and its pose are both here.
struct Waiting {
    index: u64,
    colour: ColorImage,
    calibration: RgbdCalibration,
    segmentation: Option<Segmentation>,
    /// `Some(None)`: its tracking was lost (it is left out).
    pose: Option<Option<Se3>>,
}

/// The world model and the frames on their way into it.
pub(crate) struct PlaneWorldModel {
    world: PlaneWorld,
    plane_config: PlaneConfig,
    waiting: VecDeque<Waiting>,
    last_asked: Option<Instant>,
    frames: usize,
    merged: usize,
    clipped_texels: u64,
    add_ms: Window,
    /// Bumped whenever the world changes (a frame added, a reset).
    version: u64,
    /// What the free view draws of it, as [`PlaneWorldModel::set_drawn`] last said.
    drawn: Drawn,
}

/// What the free view drew of the world at its last draw.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub(crate) struct Drawn {
    /// World planes drawn as textured quadtree meshes.
    pub(crate) planes: u32,
    /// Their texels (the overlay's memory is 4 bytes each).
    pub(crate) texels: usize,
    /// World planes left out (beyond the overlay's texel budget).
    pub(crate) left_out: usize,
}

/// The world model's part of the status.
#[derive(Clone, Debug, serde::Serialize)]
pub(crate) struct WorldStatus {
    /// Frames whose planes joined the world.
    pub(crate) frames: usize,
    /// World planes (merged ones not counted).
    pub(crate) planes: usize,
    /// World planes merged into another so far.
    pub(crate) merged: usize,
    /// Texels beyond a plane's largest grid, not stored.
    pub(crate) clipped_texels: u64,
    /// Frames waiting for their labels or pose.
    pub(crate) waiting: usize,
    /// Median milliseconds of adding a frame to the world (association, texels, merging).
    pub(crate) median_ms: f64,
    /// What the free view's last draw showed of the world's textured planes.
    pub(crate) drawn: Drawn,
}

impl PlaneWorldModel {
    pub(crate) fn new(plane_config: PlaneConfig) -> Self {
        Self { world: PlaneWorld::new(WorldConfig::default()), plane_config, waiting: VecDeque::new(), last_asked: None, frames: 0, merged: 0, clipped_texels: 0, add_ms: Window::default(), version: 0, drawn: Drawn::default() }
    }

    /// Whether the next segmented frame should bring its labels back: none is waiting and the
    /// last was asked for at least [`WORLD_INTERVAL_MS`] ago.
    pub(crate) fn wants_frame(&self) -> bool {
        self.waiting.is_empty() && self.last_asked.is_none_or(|t| t.elapsed().as_secs_f64() * 1e3 >= WORLD_INTERVAL_MS)
    }

    /// Frame `index`'s labels were asked for: keeps what the world needs of it.
    pub(crate) fn asked(&mut self, index: u64, colour: &ColorImage, calibration: RgbdCalibration) {
        self.last_asked = Some(Instant::now());
        self.waiting.push_back(Waiting { index, colour: colour.clone(), calibration, segmentation: None, pose: None });
    }

    /// A segmentation came back for frame `index`, its labels completed for meshing.
    pub(crate) fn labels_arrived(&mut self, index: u64, segmentation: Segmentation) {
        if let Some(w) = self.waiting.iter_mut().find(|w| w.index == index) {
            w.segmentation = Some(segmentation);
        }
        self.advance();
    }

    /// Frame `index` was tracked (`Some(pose)`, in the pipeline's world) or lost (`None`).
    pub(crate) fn pose_reported(&mut self, index: u64, world_from_camera: Option<Se3>) {
        if let Some(w) = self.waiting.iter_mut().find(|w| w.index == index) {
            w.pose = Some(world_from_camera);
        }
        self.advance();
    }

    /// Adds the waiting frames that have everything, oldest first; drops lost ones and any
    /// older frame that can no longer complete (its labels or report were skipped).
    fn advance(&mut self) {
        while let Some(front) = self.waiting.front() {
            let complete = front.segmentation.is_some() && front.pose.is_some();
            let overtaken = self.waiting.iter().skip(1).any(|w| w.segmentation.is_some() && w.pose.is_some());
            if !complete && !overtaken {
                break;
            }
            let w = self.waiting.pop_front().expect("front exists");
            if let (Some(seg), Some(Some(pose))) = (w.segmentation, w.pose) {
                self.add(w.index, &seg, &w.colour, w.calibration, pose);
            }
        }
    }

    fn add(&mut self, index: u64, seg: &Segmentation, colour: &ColorImage, calibration: RgbdCalibration, world_from_camera: Se3) {
        let started = Instant::now();
        let view = PlaneView { index, world_from_camera, segmentation: seg, labels: &seg.labels, colour, intrinsics: calibration.intrinsics };
        let association = self.world.add_frame(&view, &self.plane_config);
        self.frames += 1;
        self.merged += association.merged;
        self.clipped_texels += association.clipped_texels;
        self.version += 1;
        self.add_ms.push(started.elapsed().as_secs_f64() * 1e3);
    }

    /// Forgets the world and the frames on their way (a new run).
    pub(crate) fn reset(&mut self) {
        let version = self.version + 1;
        *self = Self::new(self.plane_config);
        self.version = version;
    }

    /// Changes whenever the world does.
    pub(crate) fn version(&self) -> u64 {
        self.version
    }

    /// The live planes' textured meshes as the free view's overlay draws them.
    pub(crate) fn overlay_model(&self) -> OverlayModel {
        OverlayModel::from_world(&self.world, DEFAULT_MAX_OVERLAY_TEXELS)
    }

    /// The free view drew this much of the world.
    pub(crate) fn set_drawn(&mut self, drawn: Drawn) {
        self.drawn = drawn;
    }

    pub(crate) fn status(&self) -> WorldStatus {
        WorldStatus {
            frames: self.frames,
            planes: self.world.live().count(),
            merged: self.merged,
            clipped_texels: self.clipped_texels,
            waiting: self.waiting.len(),
            median_ms: self.add_ms.median().unwrap_or(0.0),
            drawn: self.drawn,
        }
    }

    /// The live planes' textured meshes.
    pub(crate) fn meshes(&self) -> Vec<PlaneMesh> {
        self.world.live().filter_map(|j| self.world.mesh(j)).collect()
    }

    /// The scene as glTF binary: the planes' textured meshes and `fused` (the map's mesh, in
    /// the same frame) less the triangles they cover (within two voxels of `voxel_m`).
    pub(crate) fn scene_glb(&self, fused: &Mesh, voxel_m: f32) -> std::io::Result<Vec<u8>> {
        let planes = self.meshes();
        let rest = mesh_remainder(fused, &planes, voxel_m);
        let mut bytes = Vec::new();
        write_scene_glb(&planes, Some(&rest), &mut bytes)?;
        Ok(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wasm_bindgen_test::wasm_bindgen_test;
    use webfusion_core::planes::mesh::{blend_reach_px, complete_labels};
    use webfusion_core::planes::reference;
    use webfusion_core::preprocess::PreprocessConfig;
    use webfusion_core::sim::plane_scenes::{PlaneScene, UNITS_PER_METRE};
    use webfusion_core::PinholeIntrinsics;

    const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 131.25, fy_px: 131.25, cx_px: 79.5, cy_px: 59.5, width_px: 160, height_px: 120 };

    /// A synthetic scene's frame, segmented by the CPU reference with its labels completed
    /// (the GPU's `plane_complete` twin), as the page would have it.
    fn frame(scene: &PlaneScene) -> (Segmentation, ColorImage, RgbdCalibration) {
        let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 };
        let r = scene.render(&K, None);
        let preprocess = PreprocessConfig::default();
        let pre = webfusion_core::cpu::preprocess::chain::preprocess(&calibration, &preprocess, &r.frame);
        let mut seg = reference::segment(&pre.levels, Some(&pre.depth_unfiltered_m), &PlaneConfig::default());
        seg.labels = complete_labels(&seg, &pre.depth_unfiltered_m, &K, &PlaneConfig::default(), blend_reach_px(&preprocess));
        (seg, r.frame.color.clone(), calibration)
    }

    #[wasm_bindgen_test]
    fn frames_join_the_world_once_labels_and_pose_are_both_here() {
        let scene = &PlaneScene::all()[0];
        let (seg, colour, calibration) = frame(scene);
        assert!(seg.planes.len() >= 2, "{}: planes to add", scene.name);
        let mut model = PlaneWorldModel::new(PlaneConfig::default());
        assert!(model.wants_frame(), "the first frame is wanted");
        model.asked(3, &colour, calibration);
        assert!(!model.wants_frame(), "one frame at a time");
        // Labels first, pose later (or the other way round): added only with both.
        model.labels_arrived(3, seg.clone());
        assert_eq!(model.status().frames, 0, "no pose yet");
        model.pose_reported(3, Some(Se3::IDENTITY));
        let s = model.status();
        assert_eq!((s.frames, s.waiting), (1, 0));
        assert_eq!(s.planes, seg.planes.len(), "each frame plane starts a world plane");
        // The same view again from the same pose: the planes are associated, not duplicated.
        model.last_asked = None;
        model.asked(4, &colour, calibration);
        model.pose_reported(4, Some(Se3::IDENTITY));
        model.labels_arrived(4, seg.clone());
        assert_eq!((model.status().frames, model.status().planes), (2, seg.planes.len()), "associated with the world's planes");
        // A lost frame is left out; a frame overtaken by a complete later one is dropped.
        model.last_asked = None;
        model.asked(5, &colour, calibration);
        model.asked(6, &colour, calibration);
        model.pose_reported(5, None);
        model.labels_arrived(5, seg.clone());
        model.labels_arrived(6, seg.clone());
        model.pose_reported(6, Some(Se3::IDENTITY));
        let s = model.status();
        assert_eq!((s.frames, s.waiting), (3, 0), "frame 5 (lost) left out, 6 added");
        // The scene: one textured mesh per plane and the remainder, as glTF binary.
        // The overlay's model: a plane per world plane, each with covered texels.
        let overlay = model.overlay_model();
        assert_eq!((overlay.planes.len(), overlay.left_out), (seg.planes.len(), 0));
        assert!(overlay.texels.iter().any(|&w| w >> 24 == 0xff), "covered texels");
        let glb = model.scene_glb(&Mesh::default(), 0.01).expect("glb");
        assert_eq!(&glb[..4], b"glTF", "glTF magic");
        assert_eq!(model.meshes().len(), seg.planes.len(), "a mesh per world plane");
        assert!(model.meshes().iter().all(|m| !m.triangles.is_empty() && m.texture.width_px > 0), "textured meshes");
        let before = model.version();
        model.reset();
        assert_eq!((model.status().frames, model.status().planes), (0, 0), "a new run starts a new world");
        assert_ne!(model.version(), before, "a reset changes the version (the overlay is rebuilt)");
        // Negative control: frames never reported stay waiting and add nothing.
        model.asked(7, &colour, calibration);
        model.labels_arrived(7, seg);
        assert_eq!((model.status().frames, model.status().waiting), (0, 1));
    }
}
