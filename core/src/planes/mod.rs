// SPDX-License-Identifier: MIT
//! Plane segmentation of RGB-D frames (seed 003, §4.3 of its digest), and where it goes beyond
//! 003: planes a few centimetres apart kept apart, curved surfaces kept out.
//!
//! The pipeline, per frame, from the preprocessor's vertex and normal maps (camera frame):
//! 1. **Normal histogram** over the full-resolution normals (32 x 32 bins of
//!    [acos n_x, acos n_y] on the n_z ≥ 0 hemisphere, 003's mapping) and **peaks** by repeated
//!    arg-max with an exclusion radius.
//! 2. **Inner loop** at a coarse pyramid level (about 160 x 120): pixels within
//!    [`PlaneConfig::normal_segment_deg`] of a peak get its label and their distance along it;
//!    a **distance histogram** per peak, whose peaks are found by *prominence* (a peak counts when
//!    the valley between it and any higher peak is at most half its height), so two surfaces 2
//!    cm apart stay two peaks when the sensor can tell them apart, where 003's fixed exclusion of
//!    ±5 bins (±4.8 cm) merges them; each peak owns the bins up to the valleys on either side.
//!    Plane **statistics** (count, Σp, Σppᵀ, Σn, Σnpᵀ, area) per (normal peak, distance peak)
//!    and an eigen-fit per plane, after 003's realignment: a first pass moves each normal peak
//!    to the mean normal of its pixels (003 took its largest plane's fitted normal, which a
//!    parallel plane beside it tilts, smearing the distance peaks the second pass needs).
//! 3. **Merging** (003 after Biswas & Veloso): two planes within [`PlaneConfig::merge_angle_deg`]
//!    whose offsets differ by less than [`PlaneConfig::merge_sigmas`] times the sensor's axial
//!    noise at their depth become one (003 used a fixed 2.5 cm, which is 13 σ at 1 m and 1.8 σ
//!    at 3 m).
//! 4. **Final labelling** at full resolution: each pixel to the plane nearest along its normal,
//!    within [`PlaneConfig::label_angle_deg`] (003's 15°) and a distance of
//!    max([`PlaneConfig::label_min_distance_m`], 3 σ(z)); statistics again and a final fit.
//! 5. **Planarity**: a plane seen edge-on (past [`PlaneConfig::max_incidence_deg`]) is dropped,
//!    and so is a plane whose pixel normals turn with position (the slope of the normal's
//!    tangential component against the position along each in-plane axis, times the plane's
//!    extent) by more than [`PlaneConfig::max_bend_deg`] is a curved surface (a column, a
//!    sofa's back) cut into a strip by the angle window, and is dropped; 003 has no such test
//!    and turns a cylinder into planes.
//! 6. A second **round** (003's) on the pixels no plane took, for planes the first round's
//!    peaks hid; a round that finds no new plane ends the segmentation (labelling and fitting
//!    again would only iterate on the same planes).
//!
//! [`reference`] computes it on the CPU; every plane is reported as `n·p + d = 0` in the camera
//! frame with the unit normal facing the camera (d > 0).

pub mod export;
pub mod gpu;
pub mod mesh;
pub mod overlay;
pub mod reference;
pub mod world;

use crate::cpu::shared::kinect_sigma_m;

/// Side of the normal histogram, bins (003: 32).
pub const NORMAL_BINS: usize = 32;
/// Bins of each distance histogram.
pub const DISTANCE_BINS: usize = 1024;
/// Most normal peaks per round.
pub const MAX_NORMAL_PEAKS: usize = 8;
/// Most distance peaks (planes) per normal peak.
pub const MAX_DISTANCE_PEAKS: usize = 8;
/// Most planes the GPU's plane list holds per frame (more are counted as overflow).
pub const MAX_PLANES: usize = 64;
/// Pixel label of no plane.
pub const NO_LABEL: u32 = u32::MAX;

/// Parameters of plane segmentation. The defaults are 003's where it gave one and it holds up,
/// and derived from the sensor's noise where 003's fixed distances do not.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneConfig {
    /// A normal-histogram peak needs this fraction of the image's pixels in its bin (003: 800
    /// of 640 x 480, 0.26 %).
    pub min_normal_peak_fraction: f32,
    /// Bins cleared around a normal peak before the next is sought (003: 8).
    pub normal_peak_exclusion_bins: f32,
    /// Largest angle between a pixel's normal and a peak in the inner loop, degrees (003: 5).
    pub normal_segment_deg: f32,
    /// Width of a distance-histogram bin, metres (003: 9.6 mm; finer here, so planes 2 cm apart
    /// are two peaks).
    pub distance_bin_m: f32,
    /// A distance peak claims bins up to this far from it (or the valley, if nearer), metres.
    pub distance_reach_m: f32,
    /// Smallest plane, as a fraction of the image's pixels (at the inner loop's level and at full
    /// resolution).
    pub min_plane_fraction: f32,
    /// Two planes merge when their normals are within this angle, degrees (003: 5)...
    pub merge_angle_deg: f32,
    /// ...and their offsets differ by less than this many σ(z) of the sensor's axial noise at
    /// their depth.
    pub merge_sigmas: f32,
    /// Largest angle between a pixel's normal and its plane in the final labelling, degrees
    /// (003: 15).
    pub label_angle_deg: f32,
    /// The final labelling takes pixels up to max(this, 3 σ(z)) from a plane, metres (003: 15
    /// mm).
    pub label_min_distance_m: f32,
    /// Largest turn of the normal across a plane, degrees, before it counts as curved.
    pub max_bend_deg: f32,
    /// Largest angle between a plane's normal and the ray to its centroid, degrees: beyond it
    /// the camera sees the plane edge-on (the sensor drops such surfaces; what remains there
    /// is the silhouette rim of a curved object, whose points and normals do lie on one plane
    /// through the camera).
    pub max_incidence_deg: f32,
    /// Plane fits skip pixels this close (pixels, full resolution) to another label: the
    /// filters blend depth and normals across the border (see [`reference::label`]).
    pub fit_margin_px: u32,
    /// Segmentation rounds (003: 2).
    pub rounds: usize,
    /// Pyramid level of the inner loop; `None` picks the one nearest 160 px wide (003's).
    pub inner_level: Option<usize>,
}

impl Default for PlaneConfig {
    fn default() -> Self {
        Self {
            min_normal_peak_fraction: 800.0 / (640.0 * 480.0),
            normal_peak_exclusion_bins: 8.0,
            normal_segment_deg: 5.0,
            distance_bin_m: 0.005,
            distance_reach_m: 0.03,
            min_plane_fraction: 0.01,
            merge_angle_deg: 5.0,
            merge_sigmas: 2.5,
            label_angle_deg: 15.0,
            label_min_distance_m: 0.015,
            max_bend_deg: 10.0,
            max_incidence_deg: 85.0,
            fit_margin_px: 2,
            rounds: 2,
            inner_level: None,
        }
    }
}

impl PlaneConfig {
    /// The final labelling's distance tolerance at depth `z_m`.
    pub fn label_distance_m(&self, z_m: f32) -> f32 {
        self.label_min_distance_m.max(3.0 * kinect_sigma_m(z_m))
    }

    /// The inner loop's pyramid level for a full-resolution width, among `levels`.
    pub fn inner_level_for(&self, width_px: u32, levels: usize) -> usize {
        self.inner_level.unwrap_or_else(|| {
            let mut l = 0;
            while l + 1 < levels && (width_px >> (l + 1)) >= 160 {
                l += 1;
            }
            l
        })
        .min(levels.saturating_sub(1))
    }
}

/// One plane found in a frame, in the camera frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// Unit normal, facing the camera.
    pub normal: [f32; 3],
    /// Offset d of `normal·p + d = 0`, metres (positive).
    pub offset_m: f32,
    /// Mean of its points, metres.
    pub centroid_m: [f32; 3],
    /// Full-resolution pixels labelled with it.
    pub pixels: u32,
    /// Surface area its pixels cover, m² (each pixel's footprint on the plane).
    pub area_m2: f32,
    /// First in-plane axis (the points' largest spread), unit.
    pub tangent: [f32; 3],
    /// Extent along `tangent` and along `normal × tangent`: (min, max) of the points relative
    /// to the centroid, metres.
    pub extent_m: [[f32; 2]; 2],
    /// Root-mean-square distance of its points from it, metres.
    pub rms_m: f32,
    /// Turn of the normal across it, degrees (the planarity test's measure).
    pub bend_deg: f32,
}

/// A frame's segmentation.
#[derive(Clone, Debug, PartialEq)]
pub struct Segmentation {
    /// Per full-resolution pixel, the index of its plane in `planes`, or [`NO_LABEL`].
    pub labels: Vec<u32>,
    /// The planes, largest first.
    pub planes: Vec<Plane>,
    /// Candidates dropped as curved (the planarity test).
    pub curved_rejected: u32,
}
