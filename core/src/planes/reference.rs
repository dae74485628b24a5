// SPDX-License-Identifier: MIT
//! CPU reference of plane segmentation ([`super`]'s pipeline), stage by stage: per-pixel
//! passes, small histograms, per-plane sums and small per-plane solves, the shape the GPU
//! kernels take. Sums and solves are in f64 here: this is the accuracy the GPU's f32 kernels
//! are held to.

#![expect(clippy::needless_range_loop, reason = "per-pixel passes index several buffers by pixel, as kernels do")]

use super::{DISTANCE_BINS, MAX_DISTANCE_PEAKS, MAX_NORMAL_PEAKS, NO_LABEL, NORMAL_BINS, Plane, PlaneConfig, Segmentation};
use crate::PinholeIntrinsics;
use crate::cpu::preprocess::chain::CpuPyramidLevel;
use crate::cpu::shared::kinect_sigma_m;
use crate::kernels::normal_histogram::NormalHistogramParams;
use crate::kernels::normal_peaks::NormalPeaksParams;
use crate::kernels::distance_histogram::DistanceHistogramParams;
use crate::kernels::distance_peaks::DistancePeaksParams;
use crate::kernels::plane_label::PlaneLabelParams;
use crate::cpu::planes::distance_histogram::NO_ASSIGNMENT;

/// Stage 1a (kernel `normal_histogram`): the histogram of the normals of the pixels no plane
/// has yet.
pub fn normal_histogram(normals: &[[f32; 4]], labels: &[u32]) -> Vec<u32> {
    let mut hist = vec![0u32; NORMAL_BINS * NORMAL_BINS];
    let params = NormalHistogramParams { pixel_count: normals.len() as u32, use_labels: 1, ..Default::default() };
    crate::cpu::normal_histogram(&params, normals, labels, &mut hist);
    hist
}

/// Stage 1b (kernel `normal_peaks`): up to [`MAX_NORMAL_PEAKS`] peaks of `hist`, highest
/// first, after clearing the bins within `clear_bins` of each of `known` normals (a later
/// round's peaks are new planes); see the kernel.
pub fn normal_peaks(hist: &[u32], min_count: u32, exclusion_bins: f32, known: &[[f32; 3]], clear_bins: f32) -> Vec<[f32; 3]> {
    let params = NormalPeaksParams { min_count, exclusion_bins, clear_bins, ..Default::default() };
    let known: Vec<[f32; 4]> = known.iter().map(|n| [n[0], n[1], n[2], 0.0]).collect();
    let (mut peaks, mut count) = (vec![[0.0f32; 4]; MAX_NORMAL_PEAKS], [0u32]);
    crate::cpu::normal_peaks(&params, hist, &known, &[known.len() as u32], &mut peaks, &mut count);
    peaks[..count[0] as usize].iter().map(|p| [p[0], p[1], p[2]]).collect()
}

/// Stage 2b (kernel `distance_peaks`): the planes of one distance histogram (of
/// [`DISTANCE_BINS`] bins), as bin intervals `[lo, hi]`, most pixels first, at most
/// [`MAX_DISTANCE_PEAKS`]: peaks of the [1 2 1]/4-smoothed histogram whose prominence is at
/// least half their height, each owning the bins up to the valleys towards its neighbours and
/// at most `reach_bins` from it, with at least `min_mass` pixels; see the kernel.
pub fn distance_peaks(hist: &[u32], min_mass: u32, reach_bins: usize) -> Vec<[usize; 2]> {
    let params = DistancePeaksParams { min_mass, reach_bins: reach_bins as u32, ..Default::default() };
    let (mut intervals, mut count) = (vec![[0u32; 4]; MAX_DISTANCE_PEAKS], [0u32]);
    crate::cpu::distance_peaks(&params, &hist[..DISTANCE_BINS], &[1], &mut intervals, &mut count);
    intervals[..count[0] as usize].iter().map(|i| [i[0] as usize, i[1] as usize]).collect()
}

/// Sums over a plane's pixels, from which it is fitted; sums of two planes add up to the sums
/// of their union (003's merge, after Biswas & Veloso).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlaneSums {
    /// Pixels.
    pub count: f64,
    /// Σ p.
    pub p: [f64; 3],
    /// Σ p pᵀ (row-major, symmetric).
    pub pp: [[f64; 3]; 3],
    /// Σ n (pixel normals).
    pub n: [f64; 3],
    /// Σ n pᵀ: entry (i, j) = Σ n_i p_j.
    pub np: [[f64; 3]; 3],
    /// Σ of the pixels' footprints on the plane, m².
    pub area_m2: f64,
    /// Σ σ(z)² r rᵀ: each raw point's noise covariance as the sensor model shapes it (axial
    /// noise along its unit ray r); zero for filtered points.
    pub noise: [[f64; 3]; 3],
}

impl PlaneSums {
    /// Adds one pixel: point `p`, normal `n`, footprint `area_m2`.
    pub fn add(&mut self, p: [f32; 3], n: [f32; 4], area_m2: f32) {
        let (p, n) = (p.map(f64::from), [n[0], n[1], n[2]].map(f64::from));
        self.count += 1.0;
        for i in 0..3 {
            self.p[i] += p[i];
            self.n[i] += n[i];
            for j in 0..3 {
                self.pp[i][j] += p[i] * p[j];
                self.np[i][j] += n[i] * p[j];
            }
        }
        self.area_m2 += f64::from(area_m2);
    }

    /// Adds the model noise of raw point `p`: σ(z) of depth, i.e. σ |p| / z along the ray, so
    /// (σ / z)² p pᵀ.
    pub fn add_noise(&mut self, p: [f32; 3]) {
        let r = p.map(f64::from);
        let s2 = (f64::from(kinect_sigma_m(p[2])) / r[2]).powi(2);
        for i in 0..3 {
            for j in 0..3 {
                self.noise[i][j] += s2 * r[i] * r[j];
            }
        }
    }

    /// The sums of both.
    pub fn merged(&self, o: &PlaneSums) -> PlaneSums {
        let mut m = *self;
        m.count += o.count;
        m.area_m2 += o.area_m2;
        for i in 0..3 {
            m.p[i] += o.p[i];
            m.n[i] += o.n[i];
            for j in 0..3 {
                m.pp[i][j] += o.pp[i][j];
                m.np[i][j] += o.np[i][j];
                m.noise[i][j] += o.noise[i][j];
            }
        }
        m
    }
}

/// Eigen-decomposition of a symmetric 3 x 3 matrix by cyclic Jacobi rotations: eigenvalues
/// ascending, and `vectors[i]` the unit eigenvector of `values[i]`.
pub fn eigen_symmetric3(m: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut a = m;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = (0..3).map(|i| a[i][i].abs()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    for _ in 0..50 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        if off <= (1e-30 * scale) * scale {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() <= 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A ← Jᵀ A J, V ← V J with J the rotation in the (p, q) plane.
            let mut j = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
            j[p][p] = c;
            j[q][q] = c;
            j[p][q] = s;
            j[q][p] = -s;
            let mul = |x: &[[f64; 3]; 3], y: &[[f64; 3]; 3]| -> [[f64; 3]; 3] { std::array::from_fn(|r| std::array::from_fn(|k| (0..3).map(|i| x[r][i] * y[i][k]).sum())) };
            let jt: [[f64; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|k| j[k][r]));
            a = mul(&mul(&jt, &a), &j);
            v = mul(&v, &j);
        }
    }
    let mut order = [0usize, 1, 2];
    order.sort_by(|&x, &y| a[x][x].total_cmp(&a[y][y]));
    (order.map(|i| a[i][i]), order.map(|i| [v[0][i], v[1][i], v[2][i]]))
}

/// A plane fitted to its sums.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneFit {
    /// The sums it was fitted to.
    pub sums: PlaneSums,
    /// Unit normal facing the camera (n·centroid < 0).
    pub normal: [f64; 3],
    /// d of n·p + d = 0, metres.
    pub offset_m: f64,
    /// Mean point.
    pub centroid: [f64; 3],
    /// In-plane axes: the largest spread first.
    pub tangents: [[f64; 3]; 2],
    /// Variance of the points along each tangent, m².
    pub tangent_variance_m2: [f64; 2],
    /// Root-mean-square distance of the points from the plane, metres.
    pub rms_m: f64,
    /// Turn of the normal across the plane, degrees: the larger over both in-plane axes t of
    /// |cov(n·t, p·t) / var(p·t)| (the normal's rate of turn, 1/radius) times √12 · std(p·t)
    /// (the extent of a uniformly covered interval with that spread).
    pub bend_deg: f64,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Fits a plane to `sums` (at least 3 pixels): the smallest eigenvector of the points'
/// covariance less their noise covariance. Depth noise moves points along their rays and
/// inflates the scatter along them, which tilts a narrow plane seen obliquely towards the rays
/// (errors in variables: E[Σ (n·p + d)²] gains Σ σ² (n·r)², smallest for n across the rays);
/// subtracting it removes that bias (a 30 cm tread at 2.5 m with 1 cm depth noise tilts by 1°
/// without). The model gives the noise's shape (its direction and growth with depth); its
/// level is measured on the plane itself: the variance of the points along the normal, where
/// a plane has no extent, over the model's prediction of it (at most 1), so noise-free data
/// gets no correction and a quieter sensor a smaller one. Two rounds, each with the last
/// normal.
pub fn fit(sums: &PlaneSums) -> Option<PlaneFit> {
    if sums.count < 3.0 {
        return None;
    }
    let k = 1.0 / sums.count;
    let c = sums.p.map(|v| v * k);
    let nbar = sums.n.map(|v| v * k);
    let raw_cov: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| sums.pp[i][j] * k - c[i] * c[j]));
    let quad = |m: &[[f64; 3]; 3], v: [f64; 3]| (0..3).map(|i| (0..3).map(|j| v[i] * m[i][j] * v[j]).sum::<f64>()).sum::<f64>();
    let (mut values, mut vectors) = eigen_symmetric3(raw_cov);
    for _ in 0..2 {
        let predicted = quad(&sums.noise, vectors[0]) * k;
        if predicted <= 0.0 {
            break;
        }
        let level = (quad(&raw_cov, vectors[0]) / predicted).clamp(0.0, 1.0);
        let cov: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| raw_cov[i][j] - level * sums.noise[i][j] * k));
        (values, vectors) = eigen_symmetric3(cov);
    }
    let mut normal = vectors[0];
    if dot(normal, c) > 0.0 {
        normal = normal.map(|v| -v);
    }
    // cov(n, p)(i, j) = E[n_i p_j] − E[n_i] E[p_j].
    let cov_np: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| sums.np[i][j] * k - nbar[i] * c[j]));
    let tangents = [vectors[2], vectors[1]];
    let variance = [values[2].max(0.0), values[1].max(0.0)];
    let mut bend = 0.0f64;
    for (t, var) in tangents.iter().zip(variance) {
        if var <= 0.0 {
            continue;
        }
        // tᵀ cov(n, p) t = cov(n·t, p·t).
        let rate = (0..3).map(|i| (0..3).map(|j| t[i] * cov_np[i][j] * t[j]).sum::<f64>()).sum::<f64>() / var;
        bend = bend.max(rate.abs() * (12.0 * var).sqrt());
    }
    Some(PlaneFit {
        sums: *sums,
        normal,
        offset_m: -dot(normal, c),
        centroid: c,
        tangents,
        tangent_variance_m2: variance,
        rms_m: quad(&raw_cov, normal).max(0.0).sqrt(),
        bend_deg: bend.to_degrees(),
    })
}

/// Footprint on a plane of normal `n` of the pixel whose point is `p`, m²: the pixel's solid
/// angle cos³θ / (f_x f_y) times r² over the cosine of incidence |n·p| / r, = z³ / (f_x f_y |n·p|).
fn footprint_m2(k: &PinholeIntrinsics, p: [f32; 3], n: [f64; 3]) -> f32 {
    let np = (n[0] * f64::from(p[0]) + n[1] * f64::from(p[1]) + n[2] * f64::from(p[2])).abs().max(1e-6);
    (f64::from(p[2]).powi(3) / (f64::from(k.fx_px) * f64::from(k.fy_px) * np)) as f32
}

fn point(v: [f32; 4]) -> Option<[f32; 3]> {
    (v[2].is_finite() && v[2] > 0.0).then_some([v[0], v[1], v[2]])
}

/// Stage 2a's output: per pixel its (normal peak, distance bin), per peak its distance
/// histogram and the mean normal of its pixels.
struct Assigned {
    assigned: Vec<Option<(usize, usize)>>,
    hist: Vec<u32>,
    /// Oriented like the peak: a direction the offsets of parallel planes do not bias, unlike a
    /// fit to their union (003's realignment target).
    mean_normals: Vec<[f32; 3]>,
}

/// Stage 2a (kernel `distance_histogram`): free pixels (`free`: the full-resolution labels,
/// their width and this level's log2 scale; a pixel is free when the full-resolution pixel at
/// its corner is unlabelled) with a normal within the segmentation angle of a peak (the
/// nearest) get its label and their distance bin along it.
fn assign(level: &CpuPyramidLevel, peaks: &[[f32; 3]], free: (&[u32], u32, u32), config: &PlaneConfig) -> Assigned {
    let n_px = level.vertex_in_camera.len();
    let (labels, full_width_px, level_shift) = free;
    let params = DistanceHistogramParams {
        width_px: level.intrinsics.width_px,
        height_px: level.intrinsics.height_px,
        full_width_px,
        level_shift,
        cos_segment: config.normal_segment_deg.to_radians().cos(),
        bin_m: config.distance_bin_m,
        use_labels: 1,
        ..Default::default()
    };
    let peaks4: Vec<[f32; 4]> = peaks.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
    let mut assignment = vec![NO_ASSIGNMENT; n_px];
    let mut hist = vec![0u32; peaks.len() * DISTANCE_BINS];
    let mut normal_sums = vec![0i32; 4 * peaks.len()];
    crate::cpu::distance_histogram(&params, &level.vertex_in_camera, &level.normal_in_camera, labels, &peaks4, &[peaks.len() as u32], &mut assignment, &mut hist, &mut normal_sums);
    let assigned = assignment.iter().map(|&a| (a != NO_ASSIGNMENT).then_some(((a >> 16) as usize, (a & 0xffff) as usize))).collect();
    let mean_normals = peaks
        .iter()
        .zip(normal_sums.chunks(4))
        .map(|(pk, s)| {
            let s = [s[0], s[1], s[2]].map(f64::from);
            let len = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
            if len > 0.0 { s.map(|v| (v / len) as f32) } else { *pk }
        })
        .collect();
    Assigned { assigned, hist, mean_normals }
}

/// Stage 2 (the inner loop at one level): the planes of each normal peak. Pixels are assigned
/// ([`assign`]); each distance peak's pixels are summed and fitted; fits smaller than
/// `min_pixels` or bent past the limit are dropped (the count of bent ones is added to
/// `curved`).
fn inner_pass(level: &CpuPyramidLevel, peaks: &[[f32; 3]], free: (&[u32], u32, u32), config: &PlaneConfig, min_pixels: u32, curved: &mut u32) -> Vec<PlaneFit> {
    let n_px = level.vertex_in_camera.len();
    let Assigned { assigned, hist, .. } = assign(level, peaks, free, config);
    // 2b: the distance peaks of each normal peak.
    let reach = (config.distance_reach_m / config.distance_bin_m).round() as usize;
    let intervals: Vec<Vec<[usize; 2]>> = (0..peaks.len()).map(|k| distance_peaks(&hist[k * DISTANCE_BINS..(k + 1) * DISTANCE_BINS], min_pixels, reach)).collect();
    // 2c: the sums of each (normal peak, distance peak).
    let mut sums = vec![PlaneSums::default(); peaks.len() * MAX_DISTANCE_PEAKS];
    let k_img = &level.intrinsics;
    for ix in 0..n_px {
        let Some((k, bin)) = assigned[ix] else { continue };
        let Some(j) = intervals[k].iter().position(|[lo, hi]| (*lo..=*hi).contains(&bin)) else { continue };
        let p = point(level.vertex_in_camera[ix]).expect("assigned pixels have points");
        let pk = peaks[k].map(f64::from);
        sums[k * MAX_DISTANCE_PEAKS + j].add(p, level.normal_in_camera[ix], footprint_m2(k_img, p, pk));
    }
    // 2d: fits.
    let mut fits: Vec<PlaneFit> = Vec::new();
    for k in 0..peaks.len() {
        for j in 0..intervals[k].len() {
            let s = &sums[k * MAX_DISTANCE_PEAKS + j];
            if s.count < f64::from(min_pixels.max(3)) {
                continue;
            }
            let Some(f) = fit(s) else { continue };
            if f.bend_deg > f64::from(config.max_bend_deg) {
                *curved += 1;
                continue;
            }
            fits.push(f);
        }
    }
    fits
}

/// Stage 3: merges planes within the merge angle whose offsets, each measured at the other's
/// centroid, differ by less than `merge_sigmas` σ(z) at their mean depth; largest first.
pub fn merge(mut planes: Vec<PlaneFit>, config: &PlaneConfig) -> Vec<PlaneFit> {
    planes.sort_by(|a, b| b.sums.count.total_cmp(&a.sums.count));
    let cos_merge = f64::from(config.merge_angle_deg).to_radians().cos();
    let mut out: Vec<PlaneFit> = Vec::new();
    for p in planes {
        let close = out.iter().position(|q| {
            let apart = (dot(p.normal, q.centroid) + p.offset_m).abs().min((dot(q.normal, p.centroid) + q.offset_m).abs());
            let z = 0.5 * (p.centroid[2] + q.centroid[2]);
            dot(p.normal, q.normal) >= cos_merge && apart < f64::from(config.merge_sigmas) * f64::from(kinect_sigma_m(z as f32))
        });
        match close.and_then(|i| fit(&out[i].sums.merged(&p.sums)).map(|f| (i, f))) {
            Some((i, f)) => out[i] = f,
            None => out.push(p),
        }
    }
    out
}

/// Stage 4: labels every pixel with the plane nearest along the plane's normal, among those
/// within the labelling angle and distance; returns the labels and each plane's new sums.
///
/// The sums take only pixels whose neighbours within [`PlaneConfig::fit_margin_px`] all carry
/// the same label, and, with `raw_depth_m` (the depth before the edge-preserving filter, same
/// size), each such pixel's raw point when it too lies within the distance. Where surfaces meet,
/// the filters round the corner and blend the normals, so the pixels along a plane's border
/// (those of the next surface within the distance and angle, and its own rounded edge) pull a
/// narrow plane's fit: a 30 cm stair tread seven pixels deep at 2.5 m tilts by 0.6°, moving its
/// offset by 2.5 cm. Raw points are noisier but unbiased.
pub fn label(level: &CpuPyramidLevel, planes: &[PlaneFit], config: &PlaneConfig, raw_depth_m: Option<&[f32]>) -> (Vec<u32>, Vec<PlaneSums>) {
    let k_img = level.intrinsics;
    // Kernel `plane_label`.
    let params = PlaneLabelParams { pixel_count: level.vertex_in_camera.len() as u32, cos_label: config.label_angle_deg.to_radians().cos(), min_distance_m: config.label_min_distance_m, ..Default::default() };
    let planes4: Vec<[f32; 4]> = planes.iter().map(|p| [p.normal[0] as f32, p.normal[1] as f32, p.normal[2] as f32, p.offset_m as f32]).collect();
    let mut labels = vec![NO_LABEL; level.vertex_in_camera.len()];
    crate::cpu::plane_label(&params, &level.vertex_in_camera, &level.normal_in_camera, &planes4, &[planes.len() as u32], &mut labels);
    let mut sums = vec![PlaneSums::default(); planes.len()];
    let (w, h) = (k_img.width_px as i64, k_img.height_px as i64);
    let m = i64::from(config.fit_margin_px);
    for (ix, &l) in labels.iter().enumerate() {
        if l == NO_LABEL {
            continue;
        }
        let (x, y) = (ix as i64 % w, ix as i64 / w);
        let interior = (-m..=m).all(|dy| (-m..=m).all(|dx| {
            let (u, v) = (x + dx, y + dy);
            u >= 0 && v >= 0 && u < w && v < h && labels[(v * w + u) as usize] == l
        }));
        if !interior {
            continue;
        }
        let plane = &planes[l as usize];
        let p = point(level.vertex_in_camera[ix]).expect("labelled pixels have points");
        let p = match raw_depth_m {
            None => p,
            Some(raw) => {
                let z = raw[ix];
                if !(z.is_finite() && z > 0.0) {
                    continue;
                }
                let q = [(x as f32 - k_img.cx_px) / k_img.fx_px * z, (y as f32 - k_img.cy_px) / k_img.fy_px * z, z];
                if (dot(plane.normal, q.map(f64::from)) + plane.offset_m).abs() >= f64::from(config.label_distance_m(z)) {
                    continue;
                }
                q
            }
        };
        sums[l as usize].add(p, level.normal_in_camera[ix], footprint_m2(&k_img, p, plane.normal));
        if raw_depth_m.is_some() {
            sums[l as usize].add_noise(p);
        }
    }
    (labels, sums)
}

/// Whether `new`, the refit of `old` from its labelled pixels, moved the plane by at most σ(z)
/// at its centroid over its points: `old`'s distance at `new`'s centroid plus the tilt between
/// them times the points' RMS radius from the centroid (the GPU's `plane_list` tests the same).
fn refit_settled(old: &PlaneFit, new: &PlaneFit) -> bool {
    let shift = (dot(old.normal, new.centroid) + old.offset_m).abs();
    let (a, b) = (old.normal, new.normal);
    let cross = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let radius = (new.tangent_variance_m2[0] + new.tangent_variance_m2[1]).sqrt();
    shift + dot(cross, cross).sqrt() * radius <= f64::from(kinect_sigma_m(new.centroid[2] as f32))
}

/// Segments one preprocessed frame (its pyramid, level 0 at full resolution; `raw_depth_m` the
/// full-resolution depth before filtering, for the final fits, see [`label`]).
///
/// # Panics
/// If `levels` is empty.
pub fn segment(levels: &[CpuPyramidLevel], raw_depth_m: Option<&[f32]>, config: &PlaneConfig) -> Segmentation {
    let full = &levels[0];
    let inner_l = config.inner_level_for(full.intrinsics.width_px, levels.len());
    let inner = &levels[inner_l];
    let n_full = full.vertex_in_camera.len();
    let min_full = (config.min_plane_fraction * n_full as f32).ceil() as u32;
    let min_inner = (config.min_plane_fraction * inner.vertex_in_camera.len() as f32).ceil() as u32;
    let min_peak = (config.min_normal_peak_fraction * n_full as f32).ceil() as u32;
    let mut planes: Vec<PlaneFit> = Vec::new();
    let mut labels = vec![NO_LABEL; n_full];
    let mut curved = 0u32;
    for round in 0..config.rounds {
        let hist = normal_histogram(&full.normal_in_camera, &labels);
        let known: Vec<[f32; 3]> = if round == 0 { Vec::new() } else { planes.iter().map(|p| p.normal.map(|v| v as f32)).collect() };
        let peaks = normal_peaks(&hist, min_peak, config.normal_peak_exclusion_bins, &known, 0.5 * config.normal_peak_exclusion_bins);
        if peaks.is_empty() {
            break;
        }
        // An inner-level pixel is free when the full-resolution pixel at its corner is.
        let free_inner = (labels.as_slice(), full.intrinsics.width_px, inner_l as u32);
        // 003's realignment, with the mean normal of each peak's pixels (003 took its largest
        // plane's fitted normal, which a parallel plane a few cm away tilts); then again.
        let realigned = assign(inner, &peaks, free_inner, config).mean_normals;
        let newcomers = inner_pass(inner, &realigned, free_inner, config, min_inner, &mut curved);
        if newcomers.is_empty() {
            // Nothing new: labelling and fitting again would only iterate on the same planes.
            break;
        }
        planes.extend(newcomers);
        planes = merge(planes, config);
        // Final labelling with every plane so far; drop the small and the bent, then relabel.
        let (l1, sums) = label(full, &planes, config, raw_depth_m);
        let refit: Vec<Option<PlaneFit>> = sums.iter().map(fit).collect();
        let keep: Vec<bool> = refit
            .iter()
            .map(|f| match f {
                Some(f) if f.sums.count >= f64::from(min_full) && f.bend_deg <= f64::from(config.max_bend_deg) && f.offset_m >= dot(f.centroid, f.centroid).sqrt() * f64::from(config.max_incidence_deg).to_radians().cos() => true,
                Some(f) => {
                    curved += u32::from(f.bend_deg > f64::from(config.max_bend_deg));
                    false
                }
                None => false,
            })
            .collect();
        if keep.iter().all(|&k| k) && planes.iter().zip(&refit).all(|(old, new)| new.as_ref().is_some_and(|new| refit_settled(old, new))) {
            // Nothing dropped, nothing moved beyond the noise: labelling again with the refits
            // would only iterate on the same planes.
            planes = refit.into_iter().flatten().collect();
            labels = l1;
            continue;
        }
        planes = refit.into_iter().zip(&keep).filter_map(|(f, &k)| f.filter(|_| k)).collect();
        let (l2, sums2) = label(full, &planes, config, raw_depth_m);
        labels = l2;
        // A plane whose raw points all fell outside its distance is gone.
        let kept: Vec<Option<PlaneFit>> = sums2.iter().map(fit).collect();
        if kept.iter().any(Option::is_none) {
            let renumber: Vec<u32> = kept.iter().scan(0u32, |next, f| Some(if f.is_some() { *next += 1; *next - 1 } else { NO_LABEL })).collect();
            for l in &mut labels {
                if *l != NO_LABEL {
                    *l = renumber[*l as usize];
                }
            }
        }
        planes = kept.into_iter().flatten().collect();
    }
    finish(full, planes, labels, curved)
}

/// Orders the planes by size, renumbers the labels and measures each plane's extent.
fn finish(full: &CpuPyramidLevel, planes: Vec<PlaneFit>, labels: Vec<u32>, curved: u32) -> Segmentation {
    let mut order: Vec<usize> = (0..planes.len()).collect();
    order.sort_by(|&a, &b| planes[b].sums.count.total_cmp(&planes[a].sums.count));
    let mut rank = vec![NO_LABEL; planes.len()];
    for (r, &i) in order.iter().enumerate() {
        rank[i] = r as u32;
    }
    let labels: Vec<u32> = labels.iter().map(|&l| if l == NO_LABEL { NO_LABEL } else { rank[l as usize] }).collect();
    let mut extent = vec![[[f64::INFINITY, f64::NEG_INFINITY]; 2]; planes.len()];
    for (ix, &l) in labels.iter().enumerate() {
        if l == NO_LABEL {
            continue;
        }
        let f = &planes[order[l as usize]];
        let p = point(full.vertex_in_camera[ix]).expect("labelled pixels have points").map(f64::from);
        let rel = [p[0] - f.centroid[0], p[1] - f.centroid[1], p[2] - f.centroid[2]];
        for a in 0..2 {
            let u = dot(rel, f.tangents[a]);
            extent[l as usize][a] = [extent[l as usize][a][0].min(u), extent[l as usize][a][1].max(u)];
        }
    }
    let to32 = |v: [f64; 3]| v.map(|x| x as f32);
    let planes = order
        .iter()
        .enumerate()
        .map(|(r, &i)| {
            let f = &planes[i];
            Plane {
                normal: to32(f.normal),
                offset_m: f.offset_m as f32,
                centroid_m: to32(f.centroid),
                pixels: f.sums.count as u32,
                area_m2: f.sums.area_m2 as f32,
                tangent: to32(f.tangents[0]),
                extent_m: extent[r].map(|e| e.map(|x| x as f32)),
                rms_m: f.rms_m as f32,
                bend_deg: f.bend_deg as f32,
            }
        })
        .collect();
    Segmentation { labels, planes, curved_rejected: curved }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RgbdCalibration;
    use crate::cpu::preprocess::chain::preprocess;
    use crate::preprocess::PreprocessConfig;
    use crate::sim::plane_scenes::{NO_PLANE, PlaneScene, UNITS_PER_METRE};

    const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };

    #[test]
    fn normal_bins_map_back_to_their_normals() {
        for n in [[0.0f32, 0.0, -1.0], [0.6, 0.0, -0.8], [0.0, -0.8, -0.6], [-0.48, 0.6, -0.64]] {
            let (bx, by) = crate::cpu::planes::normal_histogram::normal_bin([n[0], n[1], n[2], 0.0]);
            let back = crate::cpu::planes::normal_peaks::bin_normal(bx as f32 + 0.5, by as f32 + 0.5);
            let cos = (back[0] * -n[0] + back[1] * -n[1] + back[2] * -n[2]).abs();
            assert!(cos > 8f32.to_radians().cos(), "{n:?} -> bin ({bx}, {by}) -> {back:?}");
        }
        assert_eq!(normal_histogram(&[[f32::NAN, 0.0, 0.0, 0.0]], &[NO_LABEL]).iter().sum::<u32>(), 0, "an invalid normal has no bin");
    }

    #[test]
    fn jacobi_diagonalises_a_known_matrix() {
        // R diag(1, 2, 5) Rᵀ for a rotation about (1, 1, 1).
        let r = glam::DMat3::from_axis_angle(glam::DVec3::ONE.normalize(), 0.7);
        let m = r * glam::DMat3::from_diagonal(glam::DVec3::new(5.0, 1.0, 2.0)) * r.transpose();
        let a: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| m.col(j)[i]));
        let (values, vectors) = eigen_symmetric3(a);
        for (v, e) in values.iter().zip([1.0, 2.0, 5.0]) {
            assert!((v - e).abs() < 1e-12, "{values:?}");
        }
        // The smallest eigenvector is R's second column (the 1.0 entry).
        let c = r.col(1);
        assert!((dot(vectors[0], [c.x, c.y, c.z]).abs() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn prominence_keeps_two_close_modes_apart_and_one_noisy_mode_whole() {
        // Two Gaussian bumps 4 bins apart (2 cm at 5 mm bins, σ 0.8 bin): two planes.
        let bump = |c: f32, s: f32, m: f32| (0..DISTANCE_BINS).map(move |i| (m * (-0.5 * ((i as f32 - c) / s).powi(2)).exp()) as u32);
        let two: Vec<u32> = bump(20.0, 0.8, 400.0).zip(bump(24.0, 0.8, 300.0)).map(|(a, b)| a + b).collect();
        let peaks = distance_peaks(&two, 50, 6);
        assert_eq!(peaks.len(), 2, "{peaks:?}");
        assert!(peaks[0][0] <= 20 && 20 <= peaks[0][1] && peaks[1][0] <= 24 && 24 <= peaks[1][1] && peaks[0][1] < peaks[1][0], "{peaks:?}");
        // One wide noisy bump (σ 3 bins) with counting noise: one plane.
        let mut state = 5u32;
        let one: Vec<u32> = bump(30.0, 3.0, 200.0).map(|v| (v as f32 * (0.8 + 0.4 * crate::cpu::shared::random_uniform(&mut state))) as u32).collect();
        assert_eq!(distance_peaks(&one, 50, 6).len(), 1);
        // Below the smallest mass: none.
        assert!(distance_peaks(&one, 100_000, 6).is_empty());
    }

    /// Per scene: matches each found plane to the true plane most of its pixels show, and
    /// returns (precision, recall over true planes > 2 % of the image, worst normal error in
    /// degrees, worst offset error in metres) of the matched ones.
    fn score(scene: &PlaneScene, noise: Option<u32>, config: &PlaneConfig) -> (f64, f64, f64, f64, Segmentation) {
        let r = scene.render(&K, noise);
        let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 };
        let pre = preprocess(&calibration, &PreprocessConfig::default(), &r.frame);
        let seg = segment(&pre.levels, Some(&pre.depth_unfiltered_m), config);
        let truth = scene.planes_in_camera();
        let n = K.pixel_count();
        let true_pixels: Vec<usize> = (0..truth.len()).map(|s| r.plane_of_pixel.iter().filter(|&&l| l == s as u32).count()).collect();
        let mut found = vec![false; truth.len()];
        let (mut tp, mut worst_deg, mut worst_m) = (0usize, 0.0f64, 0.0f64);
        for (k, plane) in seg.planes.iter().enumerate() {
            let mut votes = vec![0usize; truth.len()];
            for (ix, &l) in seg.labels.iter().enumerate() {
                if l == k as u32 && r.plane_of_pixel[ix] != NO_PLANE {
                    votes[r.plane_of_pixel[ix] as usize] += 1;
                }
            }
            let (s, &v) = votes.iter().enumerate().max_by_key(|(_, v)| **v).unwrap();
            let Some(t) = truth[s].filter(|_| v * 2 > plane.pixels as usize) else {
                eprintln!("  {}: plane {k} ({} px, n {:?}, d {:.3}) matches no true plane", scene.name, plane.pixels, plane.normal, plane.offset_m);
                continue;
            };
            let n_err = (plane.normal.map(f64::from)[0] * t.normal.x + plane.normal.map(f64::from)[1] * t.normal.y + plane.normal.map(f64::from)[2] * t.normal.z).clamp(-1.0, 1.0).acos().to_degrees();
            let d_err = (f64::from(plane.offset_m) - t.offset_m).abs();
            eprintln!("  {}: plane {k} = surface {s}: {} px ({} true), normal off {n_err:.3}°, offset off {:.1} mm, bend {:.1}°", scene.name, plane.pixels, true_pixels[s], d_err * 1e3, plane.bend_deg);
            if found[s] {
                eprintln!("  {}: surface {s} found twice", scene.name);
                continue;
            }
            found[s] = true;
            tp += 1;
            worst_deg = worst_deg.max(n_err);
            worst_m = worst_m.max(d_err);
        }
        let big: Vec<usize> = (0..truth.len()).filter(|&s| truth[s].is_some() && true_pixels[s] * 50 > n).collect();
        let recall = big.iter().filter(|&&s| found[s]).count() as f64 / big.len() as f64;
        let precision = if seg.planes.is_empty() { 1.0 } else { tp as f64 / seg.planes.len() as f64 };
        for &s in &big {
            if !found[s] {
                eprintln!("  {}: surface {s} ({} px) missed", scene.name, true_pixels[s]);
            }
        }
        (precision, recall, worst_deg, worst_m, seg)
    }

    #[test]
    fn synthetic_scenes_exact_and_noisy() {
        let config = PlaneConfig::default();
        let mut failures = Vec::new();
        for scene in PlaneScene::all() {
            for noise in [None, Some(3)] {
                let (precision, recall, deg, m, seg) = score(&scene, noise, &config);
                eprintln!("{} ({}): {} planes, precision {precision:.2}, recall {recall:.2}, normal error ≤ {deg:.3}°, offset error ≤ {:.1} mm, {} curved rejected", scene.name, if noise.is_some() { "noisy" } else { "exact" }, seg.planes.len(), m * 1e3, seg.curved_rejected);
                if precision < 1.0 || recall < 1.0 || deg >= 1.0 || m >= 0.01 {
                    failures.push(format!("{} {:?}", scene.name, noise));
                }
            }
        }
        assert!(failures.is_empty(), "failed: {failures:?}");
    }
}
