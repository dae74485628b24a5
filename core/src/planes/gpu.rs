// SPDX-License-Identifier: MIT
//! Plane segmentation on the GPU: [`super`]'s pipeline as one recorded chain of kernels with no
//! host round trip inside it. The per-frame plane list lives in a GPU buffer (kernel
//! `plane_list`), which also sizes the per-plane sums by indirect dispatch and feeds its planes
//! to the next labelling and its normals to the next round's peak search, so the host encodes
//! the same chain every frame and reads one result at the end.
//!
//! Per round, as [`super::reference::segment`]: `normal_histogram` over the free pixels,
//! `normal_peaks` (the planes so far cleared), `distance_histogram` at the inner level,
//! `peak_realign` to the pixels' mean normals and `distance_histogram` again, `distance_peaks`,
//! `plane_keys` → `plane_sums` → `plane_sums_reduce` → `plane_fit` for every (normal peak,
//! distance peak), `plane_list` merge; then `plane_label` at full resolution, sums and fits of
//! the labelled raw points, `plane_list` keep (size, bend, incidence), `plane_label` again, sums
//! and fits, `plane_list` keep (fittable) with `plane_relabel`. At the end `plane_list` sort,
//! `plane_relabel` and `plane_extent`. The full-resolution kernels of a round are dispatched
//! indirectly, sized by `plane_list`: a round whose merge took no newcomer ends there, with no
//! full-resolution pass, as the reference's does (most frames' second round), and a keep that
//! dropped no plane skips the second labelling, sums and fits.

use super::{MAX_DISTANCE_PEAKS, MAX_NORMAL_PEAKS, MAX_PLANES, NO_LABEL, DISTANCE_BINS, NORMAL_BINS, Plane, PlaneConfig, Segmentation};
use crate::cpu::planes::moments::PLANE_MOMENT_VEC4S;
use crate::cpu::planes::plane_extent::decode_extent;
use crate::cpu::planes::plane_fit::PLANE_FIT_VEC4S;
use crate::cpu::planes::plane_list::{DISPATCH_FIT, DISPATCH_KEYS, DISPATCH_LABEL, DISPATCH_REDUCE, DISPATCH_RELABEL, DISPATCH_SUMS, MODE_KEEP, MODE_MERGE, MODE_SORT, PLANE_LIST_DISPATCH, PLANE_LIST_STATE, PLANE_LIST_VEC4S, PLANE_RECORD_VEC4S};
use crate::cpu::planes::plane_sums::{CHUNK_MASK_WORDS, plane_sums_chunks};
use crate::kernels::{
    Kernels, KernelPipeline, distance_histogram, distance_peaks, normal_histogram, normal_peaks, peak_realign, plane_complete, plane_extent, plane_fit, plane_keys, plane_label, plane_list, plane_relabel,
    plane_sums, plane_sums_reduce, plane_window,
};
use crate::engine::ReadbackRing;
use crate::preprocess::DepthPreprocessor;
use crate::{Error, Gpu, PinholeIntrinsics, Result};

/// Candidate slots of the inner loop: a plane per (normal peak, distance peak).
const SLOTS: usize = MAX_NORMAL_PEAKS * MAX_DISTANCE_PEAKS;

/// Picks a kernel's pipeline from the registry (a step holds it, not the pipeline itself).
type KernelOf = fn(&Kernels) -> &KernelPipeline;

/// One recorded step of the chain.
enum Step {
    /// Zero a buffer.
    Clear(wgpu::Buffer),
    /// A kernel over this many invocations.
    Direct(KernelOf, wgpu::BindGroup, [u32; 3]),
    /// A kernel sized by the plane list's dispatch buffer at this byte offset.
    Indirect(KernelOf, wgpu::BindGroup, u64),
}

/// `plane_keys`' parameters for maps of intrinsics `k` in `mode` (0: the inner loop's
/// intervals; 1: labels, with the fit margin and the raw-point test of `config`).
pub fn plane_keys_params(k: &PinholeIntrinsics, mode: u32, config: &PlaneConfig) -> plane_keys::PlaneKeysParams {
    plane_keys::PlaneKeysParams {
        width_px: k.width_px,
        height_px: k.height_px,
        mode,
        margin_px: config.fit_margin_px,
        use_raw: 1,
        min_distance_m: config.label_min_distance_m,
        fx_px: k.fx_px,
        fy_px: k.fy_px,
        cx_px: k.cx_px,
        cy_px: k.cy_px,
        ..Default::default()
    }
}

/// What a segmentation read back from the GPU holds besides the planes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuSegmentationStats {
    /// Planes the list could not hold (more than [`MAX_PLANES`]).
    pub overflow: u32,
}

/// The GPU segmenter of one preprocessor's frames: buffers, parameters and the recorded chain.
pub struct GpuPlaneSegmenter {
    full: PinholeIntrinsics,
    steps: Vec<Step>,
    /// Per full-resolution pixel its plane in the last segmentation's table, or [`NO_LABEL`].
    pub labels: wgpu::Buffer,
    /// [`Self::labels`] completed for meshing and texturing (kernel `plane_complete`, the
    /// twin of [`super::mesh::complete_labels`]), by [`Self::encode_completion`].
    pub completed: wgpu::Buffer,
    /// The completion's kernels: `plane_window` along rows and along columns, `plane_complete`.
    completion: [(KernelOf, wgpu::BindGroup); 3],
    list: wgpu::Buffer,
    state: wgpu::Buffer,
    extents: wgpu::Buffer,
    dispatch: wgpu::Buffer,
    /// Plane tables (and, where asked, the labels) on their way back, tagged with the frame
    /// index; slots are sized for both, only what was copied is mapped.
    tables: ReadbackRing<u64>,
    _keep_alive: Vec<wgpu::Buffer>,
}

/// Bytes of a plane table readback: the state, the list's first MAX_PLANES records, the extents.
const TABLE_BYTES: u64 = 4 * (PLANE_LIST_STATE + 4 * MAX_PLANES * PLANE_RECORD_VEC4S + 4 * MAX_PLANES) as u64;

impl std::fmt::Debug for GpuPlaneSegmenter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuPlaneSegmenter").field("full", &self.full).field("steps", &self.steps.len()).finish()
    }
}

impl GpuPlaneSegmenter {
    /// Records the chain over `pre`'s buffers (its pyramid and its depth before filtering).
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] when the configuration asks for no round or a level the
    /// preprocessor does not have.
    pub fn new(gpu: &Gpu, pre: &DepthPreprocessor, config: &PlaneConfig) -> Result<Self> {
        let full_level = &pre.levels[0];
        let full = full_level.intrinsics;
        let inner_l = config.inner_level_for(full.width_px, pre.levels.len());
        if config.rounds == 0 || config.inner_level.is_some_and(|l| l >= pre.levels.len()) {
            return Err(Error::InvalidConfig(format!("plane segmentation needs at least one round and an inner level below {} (rounds {}, inner level {:?})", pre.levels.len(), config.rounds, config.inner_level)));
        }
        let inner_level = &pre.levels[inner_l];
        let inner = inner_level.intrinsics;
        let (n_full, n_inner) = (full.pixel_count(), inner.pixel_count());
        let (chunks_full, chunks_inner) = (plane_sums_chunks(n_full), plane_sums_chunks(n_inner));
        let raw = pre.depth_unfiltered_m.as_ref().unwrap_or(&full_level.depth_m);
        let min_full = (config.min_plane_fraction * n_full as f32).ceil();
        let min_inner = (config.min_plane_fraction * n_inner as f32).ceil();
        let min_peak = (config.min_normal_peak_fraction * n_full as f32).ceil() as u32;

        let buffer = |name: &str, bytes: usize| gpu.storage_buffer::<u8>(&format!("core.planes.{name}"), bytes);
        let labels = buffer("labels", 4 * n_full);
        let completed = buffer("completed", 4 * n_full);
        let normal_hist = buffer("normal_histogram", 4 * NORMAL_BINS * NORMAL_BINS);
        let peaks = buffer("peaks", 16 * MAX_NORMAL_PEAKS);
        let peak_count = buffer("peak_count", 4);
        let realigned = buffer("realigned", 16 * MAX_NORMAL_PEAKS);
        let assignment = buffer("assignment", 4 * n_inner);
        let distance_hist = buffer("distance_histogram", 4 * MAX_NORMAL_PEAKS * DISTANCE_BINS);
        let normal_sums = buffer("normal_sums", 16 * MAX_NORMAL_PEAKS);
        let intervals = buffer("intervals", 16 * SLOTS);
        let interval_count = buffer("interval_count", 4 * MAX_NORMAL_PEAKS);
        let keys_inner = buffer("keys_inner", 4 * n_inner);
        let keys_full = buffer("keys_full", 4 * n_full);
        let masks_inner = buffer("chunk_masks_inner", 4 * CHUNK_MASK_WORDS * chunks_inner);
        let masks_full = buffer("chunk_masks_full", 4 * CHUNK_MASK_WORDS * chunks_full);
        let partials = buffer("partials", 16 * PLANE_MOMENT_VEC4S * (SLOTS * chunks_inner).max(MAX_PLANES * chunks_full));
        let moments = buffer("moments", 16 * PLANE_MOMENT_VEC4S * SLOTS.max(MAX_PLANES));
        let fits = buffer("fits", 16 * PLANE_FIT_VEC4S * SLOTS.max(MAX_PLANES));
        let list = buffer("list", 16 * PLANE_LIST_VEC4S);
        let planes = buffer("planes", 16 * MAX_PLANES);
        let state = buffer("state", 4 * PLANE_LIST_STATE);
        let renumber = buffer("renumber", 4 * MAX_PLANES);
        let extents = buffer("extents", 16 * MAX_PLANES);
        let dispatch = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("core.planes.dispatch"),
            size: 4 * PLANE_LIST_DISPATCH as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let dummy = buffer("dummy", 16);

        let mut params_buffers: Vec<wgpu::Buffer> = Vec::new();
        let mut uniform = |name: &str, bytes: &[u8]| {
            let b = gpu.device.create_buffer(&wgpu::BufferDescriptor { label: Some(&format!("core.planes.{name}.params")), size: bytes.len() as u64, usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST, mapped_at_creation: false });
            gpu.queue.write_buffer(&b, 0, bytes);
            params_buffers.push(b.clone());
            b
        };

        // Parameters.
        let cos_segment = config.normal_segment_deg.to_radians().cos();
        let p_hist = uniform("normal_histogram", bytemuck::bytes_of(&normal_histogram::NormalHistogramParams { pixel_count: n_full as u32, use_labels: 1, ..Default::default() }));
        let p_peaks = uniform("normal_peaks", bytemuck::bytes_of(&normal_peaks::NormalPeaksParams { min_count: min_peak, exclusion_bins: config.normal_peak_exclusion_bins, clear_bins: 0.5 * config.normal_peak_exclusion_bins, ..Default::default() }));
        let p_dist = uniform(
            "distance_histogram",
            bytemuck::bytes_of(&distance_histogram::DistanceHistogramParams {
                width_px: inner.width_px,
                height_px: inner.height_px,
                full_width_px: full.width_px,
                level_shift: inner_l as u32,
                cos_segment,
                bin_m: config.distance_bin_m,
                use_labels: 1,
                ..Default::default()
            }),
        );
        let p_realign = uniform("peak_realign", bytemuck::bytes_of(&peak_realign::PeakRealignParams { peak_slots: MAX_NORMAL_PEAKS as u32, ..Default::default() }));
        let p_dpeaks = uniform("distance_peaks", bytemuck::bytes_of(&distance_peaks::DistancePeaksParams { min_mass: min_inner as u32, reach_bins: (config.distance_reach_m / config.distance_bin_m).round() as u32, ..Default::default() }));
        let p_keys_inner = uniform("plane_keys.inner", bytemuck::bytes_of(&plane_keys_params(&inner, 0, config)));
        let p_keys_full = uniform("plane_keys.full", bytemuck::bytes_of(&plane_keys_params(&full, 1, config)));
        let sums_params = |k: &PinholeIntrinsics, use_raw: u32, normal_shift: u32| plane_sums::PlaneSumsParams { width_px: k.width_px, height_px: k.height_px, use_raw, normal_shift, fx_px: k.fx_px, fy_px: k.fy_px, cx_px: k.cx_px, cy_px: k.cy_px };
        let p_sums_inner = uniform("plane_sums.inner", bytemuck::bytes_of(&sums_params(&inner, 0, MAX_DISTANCE_PEAKS.trailing_zeros())));
        let p_sums_full = uniform("plane_sums.full", bytemuck::bytes_of(&sums_params(&full, 1, 0)));
        let p_reduce_inner = uniform("plane_sums_reduce.inner", bytemuck::bytes_of(&plane_sums_reduce::PlaneSumsReduceParams { chunks: chunks_inner as u32, ..Default::default() }));
        let p_reduce_full = uniform("plane_sums_reduce.full", bytemuck::bytes_of(&plane_sums_reduce::PlaneSumsReduceParams { chunks: chunks_full as u32, ..Default::default() }));
        let p_fit = uniform("plane_fit", bytemuck::bytes_of(&plane_fit::PlaneFitParams { plane_count: SLOTS.max(MAX_PLANES) as u32, ..Default::default() }));
        let kernels = &gpu.kernels;
        let [keys_groups_x, keys_groups_y, _] = kernels.plane_keys.workgroup_count([full.width_px, full.height_px, 1]);
        let list_params = |mode: u32, min_count: f32, max_bend_deg: f32, cos_incidence: f32| plane_list::PlaneListParams {
            mode,
            slot_count: SLOTS as u32,
            min_count,
            max_bend_deg,
            cos_merge: config.merge_angle_deg.to_radians().cos(),
            merge_sigmas: config.merge_sigmas,
            cos_incidence,
            chunks: chunks_full as u32,
            label_groups: kernels.plane_label.workgroup_count([n_full as u32, 1, 1])[0],
            relabel_groups: kernels.plane_relabel.workgroup_count([n_full as u32, 1, 1])[0],
            keys_groups_x,
            keys_groups_y,
        };
        let p_merge = uniform("plane_list.merge", bytemuck::bytes_of(&list_params(MODE_MERGE, min_inner, config.max_bend_deg, -1.0)));
        let p_keep = uniform("plane_list.keep", bytemuck::bytes_of(&list_params(MODE_KEEP, min_full, config.max_bend_deg, config.max_incidence_deg.to_radians().cos())));
        let p_fittable = uniform("plane_list.fittable", bytemuck::bytes_of(&list_params(MODE_KEEP, 0.0, f32::MAX, -1.0)));
        let p_sort = uniform("plane_list.sort", bytemuck::bytes_of(&list_params(MODE_SORT, 0.0, f32::MAX, -1.0)));
        let p_label = uniform("plane_label", bytemuck::bytes_of(&plane_label::PlaneLabelParams { pixel_count: n_full as u32, cos_label: config.label_angle_deg.to_radians().cos(), min_distance_m: config.label_min_distance_m, ..Default::default() }));
        let p_relabel = uniform("plane_relabel", bytemuck::bytes_of(&plane_relabel::PlaneRelabelParams { pixel_count: n_full as u32, ..Default::default() }));
        let p_extent = uniform("plane_extent", bytemuck::bytes_of(&plane_extent::PlaneExtentParams { pixel_count: n_full as u32, ..Default::default() }));
        let reach_px = super::mesh::blend_reach_px(pre.config());
        let p_rows = uniform("plane_window.rows", bytemuck::bytes_of(&super::mesh::plane_window_params(&full, reach_px, 0)));
        let p_columns = uniform("plane_window.columns", bytemuck::bytes_of(&super::mesh::plane_window_params(&full, reach_px, 1)));
        let p_complete = uniform("plane_complete", bytemuck::bytes_of(&super::mesh::plane_complete_params(&full, config)));

        // Bind groups.
        let bg_hist = normal_histogram::Bindings { params: &p_hist, normal_in_camera: &full_level.normal_in_camera, labels: &labels, histogram: &normal_hist }.bind_group(gpu);
        let bg_peaks = normal_peaks::Bindings { params: &p_peaks, histogram: &normal_hist, known_normals: &planes, known_count: &state, peaks: &peaks, peak_count: &peak_count }.bind_group(gpu);
        let dist = |peaks: &wgpu::Buffer| {
            distance_histogram::Bindings {
                params: &p_dist,
                vertex_in_camera: &inner_level.vertex_in_camera,
                normal_in_camera: &inner_level.normal_in_camera,
                labels: &labels,
                peaks,
                peak_count: &peak_count,
                assignment: &assignment,
                histogram: &distance_hist,
                normal_sums: &normal_sums,
            }
            .bind_group(gpu)
        };
        let (bg_dist_first, bg_dist_second) = (dist(&peaks), dist(&realigned));
        let bg_realign = peak_realign::Bindings { params: &p_realign, peaks: &peaks, peak_count: &peak_count, normal_sums: &normal_sums, realigned: &realigned }.bind_group(gpu);
        let bg_dpeaks = distance_peaks::Bindings { params: &p_dpeaks, histogram: &distance_hist, peak_count: &peak_count, intervals: &intervals, interval_count: &interval_count }.bind_group(gpu);
        let bg_keys_inner = plane_keys::Bindings { params: &p_keys_inner, source: &assignment, intervals: &intervals, interval_count: &interval_count, raw_depth_m: &dummy, planes: &planes, keys: &keys_inner, chunk_masks: &masks_inner }.bind_group(gpu);
        let bg_keys_full = plane_keys::Bindings { params: &p_keys_full, source: &labels, intervals: &intervals, interval_count: &interval_count, raw_depth_m: raw, planes: &planes, keys: &keys_full, chunk_masks: &masks_full }.bind_group(gpu);
        let bg_sums_inner = plane_sums::Bindings {
            params: &p_sums_inner,
            keys: &keys_inner,
            vertex_in_camera: &inner_level.vertex_in_camera,
            normal_in_camera: &inner_level.normal_in_camera,
            raw_depth_m: &dummy,
            normals: &realigned,
            partials: &partials,
            chunk_masks: &masks_inner,
        }
        .bind_group(gpu);
        let bg_sums_full = plane_sums::Bindings { params: &p_sums_full, keys: &keys_full, vertex_in_camera: &full_level.vertex_in_camera, normal_in_camera: &full_level.normal_in_camera, raw_depth_m: raw, normals: &planes, partials: &partials, chunk_masks: &masks_full }.bind_group(gpu);
        let bg_reduce_inner = plane_sums_reduce::Bindings { params: &p_reduce_inner, partials: &partials, moments: &moments }.bind_group(gpu);
        let bg_reduce_full = plane_sums_reduce::Bindings { params: &p_reduce_full, partials: &partials, moments: &moments }.bind_group(gpu);
        let bg_fit = plane_fit::Bindings { params: &p_fit, moments: &moments, fits: &fits }.bind_group(gpu);
        let list_bg = |params: &wgpu::Buffer| plane_list::Bindings { params, fits: &fits, moments: &moments, list: &list, planes: &planes, state: &state, renumber: &renumber, dispatch: &dispatch }.bind_group(gpu);
        let (bg_merge, bg_keep, bg_fittable, bg_sort) = (list_bg(&p_merge), list_bg(&p_keep), list_bg(&p_fittable), list_bg(&p_sort));
        let bg_label = plane_label::Bindings { params: &p_label, vertex_in_camera: &full_level.vertex_in_camera, normal_in_camera: &full_level.normal_in_camera, planes: &planes, plane_count: &state, labels: &labels }.bind_group(gpu);
        let bg_relabel = plane_relabel::Bindings { params: &p_relabel, renumber: &renumber, labels: &labels }.bind_group(gpu);
        let bg_extent = plane_extent::Bindings { params: &p_extent, vertex_in_camera: &full_level.vertex_in_camera, labels: &labels, list: &list, extents: &extents }.bind_group(gpu);
        let (row_masks, window_masks) = (buffer("row_masks", 8 * n_full), buffer("window_masks", 8 * n_full));
        let completion: [(KernelOf, wgpu::BindGroup); 3] = [
            (|k| &k.plane_window, plane_window::Bindings { params: &p_rows, labels: &labels, plane_count: &state, masks_in: &dummy, masks_out: &row_masks }.bind_group(gpu)),
            (|k| &k.plane_window, plane_window::Bindings { params: &p_columns, labels: &labels, plane_count: &state, masks_in: &row_masks, masks_out: &window_masks }.bind_group(gpu)),
            (|k| &k.plane_complete, plane_complete::Bindings { params: &p_complete, depth_m: raw, labels_in: &labels, window: &window_masks, planes: &planes, labels_out: &completed }.bind_group(gpu)),
        ];

        // The chain.
        let mut steps = vec![Step::Clear(state.clone())];
        // With no planes yet, labelling marks every pixel free.
        steps.push(Step::Direct(|k| &k.plane_label, bg_label.clone(), [n_full as u32, 1, 1]));
        // Labels, keys, sums and fits at full resolution, sized by the plane list (nothing once
        // a round's merge took no newcomer, nor after a keep that dropped no plane).
        let full_sums = |steps: &mut Vec<Step>| {
            steps.push(Step::Indirect(|k| &k.plane_label, bg_label.clone(), DISPATCH_LABEL));
            steps.push(Step::Clear(masks_full.clone()));
            steps.push(Step::Indirect(|k| &k.plane_keys, bg_keys_full.clone(), DISPATCH_KEYS));
            steps.push(Step::Indirect(|k| &k.plane_sums, bg_sums_full.clone(), DISPATCH_SUMS));
            steps.push(Step::Indirect(|k| &k.plane_sums_reduce, bg_reduce_full.clone(), DISPATCH_REDUCE));
            steps.push(Step::Indirect(|k| &k.plane_fit, bg_fit.clone(), DISPATCH_FIT));
        };
        for _ in 0..config.rounds {
            steps.push(Step::Clear(normal_hist.clone()));
            steps.push(Step::Direct(|k| &k.normal_histogram, bg_hist.clone(), [n_full as u32, 1, 1]));
            steps.push(Step::Direct(|k| &k.normal_peaks, bg_peaks.clone(), [256, 1, 1]));
            for (bg, realign) in [(&bg_dist_first, true), (&bg_dist_second, false)] {
                steps.push(Step::Clear(distance_hist.clone()));
                steps.push(Step::Clear(normal_sums.clone()));
                steps.push(Step::Direct(|k| &k.distance_histogram, bg.clone(), [inner.width_px, inner.height_px, 1]));
                if realign {
                    steps.push(Step::Direct(|k| &k.peak_realign, bg_realign.clone(), [MAX_NORMAL_PEAKS as u32, 1, 1]));
                }
            }
            steps.push(Step::Direct(|k| &k.distance_peaks, bg_dpeaks.clone(), [256 * MAX_NORMAL_PEAKS as u32, 1, 1]));
            steps.push(Step::Clear(masks_inner.clone()));
            steps.push(Step::Direct(|k| &k.plane_keys, bg_keys_inner.clone(), [inner.width_px, inner.height_px, 1]));
            steps.push(Step::Direct(|k| &k.plane_sums, bg_sums_inner.clone(), [64 * chunks_inner as u32, SLOTS as u32, 1]));
            steps.push(Step::Direct(|k| &k.plane_sums_reduce, bg_reduce_inner.clone(), [64 * SLOTS as u32, 1, 1]));
            steps.push(Step::Direct(|k| &k.plane_fit, bg_fit.clone(), [SLOTS as u32, 1, 1]));
            steps.push(Step::Direct(|k| &k.plane_list, bg_merge.clone(), [1, 1, 1]));
            full_sums(&mut steps);
            steps.push(Step::Direct(|k| &k.plane_list, bg_keep.clone(), [1, 1, 1]));
            full_sums(&mut steps);
            steps.push(Step::Direct(|k| &k.plane_list, bg_fittable.clone(), [1, 1, 1]));
            steps.push(Step::Indirect(|k| &k.plane_relabel, bg_relabel.clone(), DISPATCH_RELABEL));
        }
        steps.push(Step::Direct(|k| &k.plane_list, bg_sort, [1, 1, 1]));
        steps.push(Step::Direct(|k| &k.plane_relabel, bg_relabel, [n_full as u32, 1, 1]));
        steps.push(Step::Clear(extents.clone()));
        steps.push(Step::Direct(|k| &k.plane_extent, bg_extent, [n_full as u32, 1, 1]));

        let keep_alive = [normal_hist, peaks, peak_count, realigned, assignment, distance_hist, normal_sums, intervals, interval_count, keys_inner, keys_full, masks_inner, masks_full, partials, moments, fits, planes, renumber, dummy, row_masks, window_masks];
        params_buffers.extend(keep_alive);
        let tables = ReadbackRing::new(gpu, "core.planes.table", TABLE_BYTES + 4 * full.pixel_count() as u64, 2);
        Ok(Self { full, steps, labels, completed, completion, list, state, extents, dispatch, tables, _keep_alive: params_buffers })
    }

    /// Records the whole segmentation of the preprocessor's current frame into `encoder`:
    /// each run of kernels between two clears in one compute pass.
    pub fn encode(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder) {
        self.encode_steps(gpu, encoder, &self.steps);
    }

    /// Records the completion of the last segmentation's labels for meshing (after
    /// [`Self::encode`]): [`Self::completed`] from the labels, the plane table and the raw depth.
    pub fn encode_completion(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("core.planes.complete"), timestamp_writes: None });
        for (kernel, bind_group) in &self.completion {
            kernel(&gpu.kernels).dispatch_in(&mut pass, bind_group, [self.full.width_px, self.full.height_px, 1]);
        }
    }

    /// Records `steps`: clears as they come, each run of kernels between them in one pass.
    fn encode_steps(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, steps: &[Step]) {
        let mut i = 0;
        while i < steps.len() {
            if let Step::Clear(buffer) = &steps[i] {
                encoder.clear_buffer(buffer, 0, None);
                i += 1;
                continue;
            }
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("core.planes"), timestamp_writes: None });
            while let Some(step) = steps.get(i) {
                match step {
                    Step::Clear(_) => break,
                    Step::Direct(kernel, bg, invocations) => kernel(&gpu.kernels).dispatch_in(&mut pass, bg, *invocations),
                    Step::Indirect(kernel, bg, offset) => {
                        pass.set_pipeline(&kernel(&gpu.kernels).pipeline);
                        pass.set_bind_group(0, bg, &[]);
                        pass.dispatch_workgroups_indirect(&self.dispatch, *offset);
                    }
                }
                i += 1;
            }
        }
    }

    /// Runs the chain one step per submission, waiting for each, and returns the GPU time spent
    /// in each kernel (summed over its dispatches, clears under "clear"), in the order first
    /// run: per-stage times for benchmarks, at the cost of a host wait per step. The result is
    /// the same as [`Self::encode`]'s.
    ///
    /// # Errors
    /// A failed wait.
    #[cfg(not(target_arch = "wasm32"))]
    pub async fn run_profiled(&self, gpu: &Gpu) -> Result<Vec<(&'static str, f64)>> {
        let mut times: Vec<(&'static str, f64)> = Vec::new();
        for step in &self.steps {
            let started = std::time::Instant::now();
            let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.planes.profiled") });
            self.encode_steps(gpu, &mut encoder, std::slice::from_ref(step));
            gpu.submit_and_wait(encoder).await?;
            let ms = started.elapsed().as_secs_f64() * 1e3;
            let name = match step {
                Step::Clear(_) => "clear",
                Step::Direct(kernel, ..) | Step::Indirect(kernel, ..) => kernel(&gpu.kernels).kernel.name,
            };
            match times.iter_mut().find(|(n, _)| *n == name) {
                Some((_, t)) => *t += ms,
                None => times.push((name, ms)),
            }
        }
        Ok(times)
    }

    /// Reads the last segmentation back: the labels, the plane table (largest first) and the
    /// list's overflow count.
    ///
    /// # Errors
    /// A failed readback.
    pub async fn read(&self, gpu: &Gpu) -> Result<(Segmentation, GpuSegmentationStats)> {
        self.read_parts(gpu, true).await
    }

    /// [`Self::read`] without the labels (which stay on the GPU, in [`Self::labels`], for a
    /// view): the plane table, the curved rejections and the overflow, a few kilobytes.
    ///
    /// # Errors
    /// A failed readback.
    pub async fn read_table(&self, gpu: &Gpu) -> Result<(Segmentation, GpuSegmentationStats)> {
        self.read_parts(gpu, false).await
    }

    /// [`Self::read`] and the labels completed for meshing: completes them first (one
    /// submission), then reads the table and both label images; the completed labels come back
    /// beside the segmentation, clamped to its table as its own labels are.
    ///
    /// # Errors
    /// A failed readback.
    pub async fn read_with_completed(&self, gpu: &Gpu) -> Result<(Segmentation, Vec<u32>, GpuSegmentationStats)> {
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.planes.complete") });
        self.encode_completion(gpu, &mut encoder);
        gpu.submit(Some(encoder.finish()));
        let n = self.full.pixel_count();
        let parts: Vec<(&wgpu::Buffer, usize)> = self.table_parts().into_iter().chain([(&self.labels, n), (&self.completed, n)]).collect();
        let words: Vec<u32> = gpu.read_buffers(&parts).await?;
        let (table, completed) = words.split_at(words.len() - n);
        let (seg, stats) = parse_table(table);
        let completed = completed.iter().map(|&l| clamp_label(l, seg.planes.len())).collect();
        Ok((seg, completed, stats))
    }

    /// The plane table's buffers and their words, in the order [`parse_table`] reads them: the
    /// state, the list's first MAX_PLANES records, the extents.
    fn table_parts(&self) -> [(&wgpu::Buffer, usize); 3] {
        [(&self.state, PLANE_LIST_STATE), (&self.list, 4 * MAX_PLANES * PLANE_RECORD_VEC4S), (&self.extents, 4 * MAX_PLANES)]
    }

    async fn read_parts(&self, gpu: &Gpu, with_labels: bool) -> Result<(Segmentation, GpuSegmentationStats)> {
        let mut parts = self.table_parts().to_vec();
        if with_labels {
            parts.push((&self.labels, self.full.pixel_count()));
        }
        let words: Vec<u32> = gpu.read_buffers(&parts).await?;
        Ok(parse_table(&words))
    }

    /// Records a copy of the plane table into a free readback slot (after [`Self::encode`], in
    /// the same encoder), and when `with_labels` the labels completed for meshing after it
    /// ([`Self::encode_completion`], recorded here; 4 bytes a pixel, for a frame the world
    /// model takes: the table it brings back carries those as its labels); `None` when both
    /// slots are still in flight (this frame is then not read).
    pub fn encode_table_copy(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, with_labels: bool) -> Option<usize> {
        let (slot, buffer) = self.tables.free_slot()?;
        let mut offset = 0;
        if with_labels {
            self.encode_completion(gpu, encoder);
        }
        let labels = if with_labels { Some((&self.completed, self.full.pixel_count())) } else { None };
        for (source, words) in self.table_parts().into_iter().chain(labels) {
            let bytes = 4 * words as u64;
            encoder.copy_buffer_to_buffer(source, 0, buffer, offset, bytes);
            offset += bytes;
        }
        Some(slot)
    }

    /// Maps the slot [`Self::encode_table_copy`] filled (`with_labels` as it was told) once
    /// `submission` is done; the table comes back through [`Self::collect_tables`] tagged with
    /// `frame`.
    pub fn start_table_read(&mut self, gpu: &Gpu, slot: usize, submission: wgpu::SubmissionIndex, frame: u64, with_labels: bool) {
        let bytes = TABLE_BYTES + if with_labels { 4 * self.full.pixel_count() as u64 } else { 0 };
        self.tables.start_bytes(gpu, slot, submission, frame, bytes);
    }

    /// The plane tables whose readback completed (oldest first, without waiting): frame, the
    /// planes (with the completed labels where they were copied, else none) and the stats.
    ///
    /// # Errors
    /// A failed mapping or a lost device.
    pub fn collect_tables(&mut self, gpu: &Gpu) -> Result<Vec<(u64, Segmentation, GpuSegmentationStats)>> {
        Ok(self
            .tables
            .collect(gpu)?
            .into_iter()
            .map(|done| {
                // The table, then the labels where they were copied (and mapped).
                let words: Vec<u32> = bytemuck::pod_collect_to_vec(&done.bytes);
                let (seg, stats) = parse_table(&words);
                (done.tag, seg, stats)
            })
            .collect())
    }

    /// Whether a table can be copied now ([`Self::encode_table_copy`] would not return `None`).
    pub fn table_slot_free(&self) -> bool {
        self.tables.free_slot().is_some()
    }

    /// Plane tables still on their way back.
    pub fn tables_in_flight(&self) -> usize {
        self.tables.in_flight()
    }
}

/// Labels past the table cannot occur (the last relabelling maps every dropped plane to
/// none); clamped so a reader can index the table of `count` planes with any label.
fn clamp_label(l: u32, count: usize) -> u32 {
    if l == NO_LABEL || (l as usize) < count { l } else { NO_LABEL }
}

/// A segmentation from the words of the state, the list's first MAX_PLANES records, the
/// extents and (possibly none of) the labels, in that order.
fn parse_table(words: &[u32]) -> (Segmentation, GpuSegmentationStats) {
    let (state, rest) = words.split_at(PLANE_LIST_STATE);
    let (list, rest) = rest.split_at(4 * MAX_PLANES * PLANE_RECORD_VEC4S);
    let (extents, labels) = rest.split_at(4 * MAX_PLANES);
    let count = (state[0] as usize).min(MAX_PLANES);
    let f = |w: u32| f32::from_bits(w);
    let planes = (0..count)
        .map(|k| {
            let record = &list[4 * k * PLANE_RECORD_VEC4S..4 * (k + 1) * PLANE_RECORD_VEC4S];
            let v = |i: usize| -> [f32; 4] { std::array::from_fn(|c| f(record[4 * (PLANE_MOMENT_VEC4S + i) + c])) };
            let (nd, c, t0, stats) = (v(0), v(1), v(2), v(4));
            Plane {
                normal: [nd[0], nd[1], nd[2]],
                offset_m: nd[3],
                centroid_m: [c[0], c[1], c[2]],
                pixels: c[3] as u32,
                area_m2: stats[2],
                tangent: [t0[0], t0[1], t0[2]],
                extent_m: decode_extent(&extents[4 * k..4 * k + 4]),
                rms_m: stats[0],
                bend_deg: stats[1],
            }
        })
        .collect();
    let labels = labels.iter().map(|&l| clamp_label(l, count)).collect();
    (Segmentation { labels, planes, curved_rejected: state[1] }, GpuSegmentationStats { overflow: state[2] })
}
