// SPDX-License-Identifier: MIT
//! The virtual sensor (seed 000) in the page: a Kinect placed at any pose in the map being
//! fused, or in a saved map opened from a local file or from the bridge (`serve --map` offers
//! its map at `/map.wfm`) and explored without a camera.
//!
//! It renders with `core::sim::sensor::VirtualSensor`, the kernels `webfusion simulate` and
//! `serve`'s render requests run: depth at the TUM scale, exact or with the seeded Kinect noise
//! model (the noise stream of frame `i` is the real frame's index, so a render here equals
//! `simulate --noise kinect --seed S` at that frame). When the pose is a real frame's (its
//! tracked pose while fusing, or its ground truth in a map fused at ground-truth poses), the
//! real depth is drawn beside the simulated one with seed 000's metrics (`core::sim::compare`,
//! those of `webfusion compare`) and their difference image. Renders come back a frame later,
//! like the pipeline's reports: nothing waits.
//!
//! In a map opened from the bridge, each render is also asked of the bridge for its unknown
//! mask (a `RenderRequest` with `unknown`; `serve --map M --occupancy G.json` answers it from the
//! map's occupancy grid, as `simulate --occupancy` marks its frames): the pixels whose ray
//! crossed never-observed space before its return are tinted over the simulated depth. One
//! request is in flight at a time and the newest render waiting is asked next; a mask that
//! comes back after a newer render is not drawn (counted). A bridge without a grid says so once
//! and is not asked again until another map is opened.

use std::collections::VecDeque;
use std::rc::Rc;

use glam::{DQuat, DVec3};
use web_time::Instant;
use webfusion_core::camera::TUM_DEPTH_UNITS_PER_METRE;
use webfusion_core::cpu::map::block_swap_out::block_centre;
use webfusion_core::map::file::{MapFileHeader, MapFrame, parse_map_bytes};
use webfusion_core::map::saved_map_config;
use webfusion_core::map::window::{NearestWindow, ViewCone, ViewedMap};
use webfusion_core::protocol::{RenderFailure, RenderOutcome, RenderRequest, WireDepth};
use webfusion_core::sim::compare::{DepthComparison, compare_depth, difference_image};
use webfusion_core::sim::sensor::{KinectModel, SensorOptions, VirtualSensor};
use webfusion_core::tsdf::TsdfStore;
use webfusion_core::view::{DEFAULT_DEPTH_VIEW_MAX_M, DepthView};
use webfusion_core::{Gpu, PinholeIntrinsics, Se3};

use crate::canvas::GpuCanvas;
use crate::status::Window;
use crate::ui;
use crate::view;

/// |sim − real| drawn at the top of the difference image's colour map, mm.
const DIFFERENCE_MAX_MM: f32 = 50.0;
/// The panel's canvases and inputs.
const SIM_CANVAS: &str = "view-sim";
const REAL_CANVAS: &str = "view-sim-real";
const DIFFERENCE_CANVAS: &str = "view-sim-diff";
const POSE_INPUT: &str = "sim-pose";
const UNKNOWN_CANVAS: &str = "view-sim-unknown";
/// The tint of a pixel that looked through never-observed space (RGBA, over the depth).
const UNKNOWN_TINT: [u8; 4] = [255, 0, 255, 150];

/// A real depth frame and where it was taken, in the map's frame.
#[derive(Clone, Debug)]
pub(crate) struct RealFrame {
    pub(crate) index: u64,
    pub(crate) depth_units: Rc<Vec<u16>>,
    pub(crate) units_per_metre: f32,
    pub(crate) intrinsics: PinholeIntrinsics,
    pub(crate) map_from_camera: Se3,
}

/// A saved map opened in the page.
pub(crate) struct OpenedMap {
    pub(crate) name: String,
    pub(crate) header: MapFileHeader,
    pub(crate) blocks: usize,
    /// What a damaged file lost (its intact blocks were kept).
    pub(crate) damage: Option<String>,
    /// On the GPU whole, or through a window when it has more blocks than the device's largest
    /// pool (`map::window`): each render prepares it for its view first.
    pub(crate) map: ViewedMap,
    /// What the free view's last window left out (it takes the nearest of its blocks when they
    /// do not all fit; the sensor's renders never do).
    pub(crate) free_view_window: Option<NearestWindow>,
    /// Opened from the bridge (`serve --map`), which may mark unknown pixels.
    pub(crate) from_bridge: bool,
    /// Mean of its blocks' centres and their RMS distance from it, metres (the free view's
    /// first look).
    pub(crate) centre_m: DVec3,
    pub(crate) spread_m: f64,
}

impl OpenedMap {
    /// Parses a map file's bytes (keeping the intact blocks of a damaged one) and loads it onto
    /// the GPU: whole when it fits a pool of `max_pool_blocks` (the page's map memory; at most
    /// the largest pool the device binds, 65,536 blocks on a 128 MiB binding), else through a
    /// window that follows the free view and the sensor.
    pub(crate) fn load(gpu: &Gpu, bytes: &[u8], name: &str, from_bridge: bool, max_pool_blocks: u32) -> Result<Self, String> {
        let mut file = parse_map_bytes(bytes, name).map_err(|e| e.to_string())?;
        if file.blocks.is_empty() {
            return Err(format!("{name}: the map has no intact blocks"));
        }
        let blocks = file.blocks.len();
        let desc = saved_map_config(&file.header, 1).desc(file.header.origin_in_world);
        let centres: Vec<DVec3> = file.blocks.iter().map(|b| DVec3::from(block_centre(&desc, b.coords).0.map(f64::from))).collect();
        // The mean and RMS spread of the blocks: a few stray far blocks do not push the view out.
        let centre_m = centres.iter().sum::<DVec3>() / centres.len() as f64;
        let spread_m = (centres.iter().map(|c| c.distance_squared(centre_m)).sum::<f64>() / centres.len() as f64).sqrt();
        let map = ViewedMap::load(gpu, &file.header, std::mem::take(&mut file.blocks), Some(max_pool_blocks)).map_err(|e| format!("{name}: {e}"))?;
        Ok(Self { name: name.to_owned(), blocks, damage: file.damage.map(|d| d.to_string()), header: file.header, map, free_view_window: None, from_bridge, centre_m, spread_m })
    }

    pub(crate) fn status(&self) -> OpenedMapStatus {
        OpenedMapStatus {
            name: self.name.clone(),
            kind: self.header.kind.name(),
            blocks: self.blocks,
            voxel_size_m: self.header.voxel_size_m,
            frame: match self.header.frame {
                MapFrame::FirstCamera => "first camera",
                MapFrame::GivenPoses => "given poses",
            },
            memory_bytes: self.map.map().memory_bytes(),
            damage: self.damage.clone(),
            centre_m: self.centre_m.to_array(),
            spread_m: self.spread_m,
            up_in_map: self.header.up_in_map,
            pool_blocks: self.map.window().map(|w| w.capacity()),
            windows: self.map.window().map_or(0, |w| w.uploads()),
            free_view_left_out: self.free_view_window.map_or(0, |w| w.left_out),
            free_view_complete_within_m: self.free_view_window.map(|w| w.complete_within_m).filter(|m| m.is_finite()),
        }
    }
}

/// What the sensor is built for: it is rebuilt when this changes.
#[derive(Clone, Copy, Debug, PartialEq)]
struct SensorKey {
    intrinsics: PinholeIntrinsics,
    units_per_metre: f32,
    noise_seed: Option<u32>,
}

/// The sensor, bound to one map, and its views.
struct Bound {
    key: SensorKey,
    sensor: VirtualSensor,
    sim_view: DepthView,
    sim_canvas: GpuCanvas,
    /// The real frame's depth (two u16 per word), uploaded for its view.
    real_raw: wgpu::Buffer,
    real_view: DepthView,
    real_canvas: GpuCanvas,
}

/// A render on its way back.
struct Pending {
    tag: u64,
    map_from_camera: Se3,
    key: SensorKey,
    real: Option<RealFrame>,
    sent: Instant,
}

/// The last render that came back.
struct Rendered {
    map_from_camera: Se3,
    key: SensorKey,
    real_index: Option<u64>,
    depth_units: Vec<u16>,
    metrics: Option<DepthComparison>,
}

/// The bridge's unknown masks of the renders (see the module docs).
#[derive(Default)]
struct UnknownMarks {
    /// The request on its way: its id and the render it marks.
    asked: Option<(u32, u64)>,
    /// The newest render of a bridge's map: its tag and the request that asks for its mask.
    newest: Option<(u64, RenderRequest)>,
    /// Request ids, counting.
    next_id: u32,
    /// Why the bridge cannot mark pixels, once it said so (no more requests).
    unavailable: Option<String>,
    /// The last mask drawn: its render's tag, the marked pixels and all pixels.
    drawn: Option<(u64, usize, usize)>,
    /// Masks that came back after a newer render, not drawn.
    stale: u64,
}

/// The virtual sensor panel.
#[derive(Default)]
pub(crate) struct SensorPanel {
    bound: Option<Bound>,
    pending: VecDeque<Pending>,
    next_tag: u64,
    /// The last real frame with a pose in the map ("at the last frame" renders there).
    real: Option<RealFrame>,
    /// Render at every real frame's pose as it arrives.
    follow: bool,
    noise_seed: Option<u32>,
    last: Option<Rendered>,
    rendered: u64,
    /// Follow renders skipped because two were still in flight.
    skipped: u64,
    /// Submission to readback, milliseconds.
    render_ms: Window,
    unknown: UnknownMarks,
}

impl SensorPanel {
    /// The map it renders changed (a new pipeline, a map opened or closed): the sensor is
    /// rebuilt on the next render, renders in flight are forgotten.
    pub(crate) fn unbind(&mut self) {
        self.bound = None;
        self.pending.clear();
        self.real = None;
        self.unknown.newest = None;
        self.unknown.drawn = None;
        // Another map (perhaps another bridge's) may have a grid: ask again.
        self.unknown.unavailable = None;
        if let Some(b) = &self.last {
            clear_canvas(UNKNOWN_CANVAS, b.key.intrinsics);
        }
    }

    /// The request to send the bridge now, if one is due (none in flight, a render not yet
    /// asked for): it counts as in flight from here.
    pub(crate) fn bridge_request(&mut self) -> Option<RenderRequest> {
        let u = &mut self.unknown;
        if u.asked.is_some() || u.unavailable.is_some() {
            return None;
        }
        let (tag, request) = u.newest.take()?;
        u.asked = Some((request.request_id, tag));
        Some(request)
    }

    /// The link to the bridge closed: the reply to the request in flight will not come.
    pub(crate) fn bridge_lost(&mut self) {
        self.unknown.asked = None;
    }

    /// The bridge's answer to request `request_id`: the mask is drawn over its render if that
    /// is still the newest. Errors: a reply to no request in flight, or a mask of another size.
    pub(crate) fn on_bridge_reply(&mut self, request_id: u32, outcome: RenderOutcome) -> Result<(), String> {
        let u = &mut self.unknown;
        let Some((asked_id, tag)) = u.asked.filter(|(id, _)| *id == request_id) else {
            return Err(format!("the bridge answered render request {request_id}, which this page has not in flight"));
        };
        u.asked = None;
        let view = match outcome {
            RenderOutcome::View(view) => view,
            RenderOutcome::Failed { code: RenderFailure::RenderFailed, message } => return Err(format!("the bridge's unknown mask for request {asked_id}: {message}")),
            RenderOutcome::Failed { message, .. } => {
                u.unavailable = Some(message);
                return Ok(());
            }
        };
        let Some(mask) = view.unknown_mask else { return Err(format!("the bridge's reply to request {asked_id} has no unknown mask")) };
        let pixels = (view.width_px * view.height_px) as usize;
        if mask.len() != pixels {
            return Err(format!("the bridge's unknown mask has {} bytes for {}x{} pixels", mask.len(), view.width_px, view.height_px));
        }
        // A newer render is on show (or on its way): this mask is not its.
        if self.next_tag != tag + 1 {
            u.stale += 1;
            return Ok(());
        }
        let marked = mask.iter().filter(|&&m| m != 0).count();
        let rgba: Vec<u8> = mask.iter().flat_map(|&m| if m != 0 { UNKNOWN_TINT } else { [0; 4] }).collect();
        if let Ok(canvas) = ui::element::<web_sys::HtmlCanvasElement>(UNKNOWN_CANVAS) {
            view::draw_rgba(&canvas, view.width_px, view.height_px, &rgba).map_err(|e| format!("the unknown mask: {}", crate::link::js_text(&e)))?;
        }
        u.drawn = Some((tag, marked, pixels));
        Ok(())
    }

    pub(crate) fn set_follow(&mut self, on: bool) {
        self.follow = on;
    }

    pub(crate) fn set_noise(&mut self, seed: Option<u32>) {
        self.noise_seed = seed;
    }

    /// The last real frame with a pose in the map.
    pub(crate) fn real(&self) -> Option<&RealFrame> {
        self.real.as_ref()
    }

    /// The pose of the last render, if any.
    pub(crate) fn last_pose(&self) -> Option<Se3> {
        self.last.as_ref().map(|r| r.map_from_camera).or_else(|| self.pending.back().map(|p| p.map_from_camera))
    }

    /// A real frame arrived with a pose in the map; true when the panel follows frames (the
    /// caller renders at it).
    pub(crate) fn observe(&mut self, real: RealFrame) -> bool {
        self.real = Some(real);
        self.follow
    }

    /// Whether a render is on its way back.
    pub(crate) fn awaiting_gpu(&self) -> bool {
        !self.pending.is_empty()
    }

    /// Renders `store` at `map_from_camera`, beside `real` when the pose is that frame's (with
    /// its camera; else with `camera`, the map's own, or the nominal Kinect); the result comes
    /// back through [`Self::poll`]. With two renders in flight the request is skipped (counted)
    /// rather than waited for.
    /// With `ask_bridge` (a map opened from the bridge) the bridge is asked for the render's
    /// unknown mask ([`Self::bridge_request`]).
    pub(crate) fn render(&mut self, gpu: &Gpu, store: &dyn TsdfStore, map_from_camera: Se3, real: Option<RealFrame>, camera: Option<PinholeIntrinsics>, ask_bridge: bool) -> Result<(), String> {
        let key = SensorKey {
            intrinsics: sensor_intrinsics(real.as_ref(), camera),
            units_per_metre: real.as_ref().map_or(TUM_DEPTH_UNITS_PER_METRE, |r| r.units_per_metre),
            noise_seed: self.noise_seed,
        };
        if self.bound.as_ref().is_none_or(|b| b.key != key) {
            self.pending.clear();
            self.bound = None;
            self.bound = Some(bind(gpu, store, key)?);
        }
        let Some(b) = self.bound.as_mut() else { return Ok(()) };
        if !b.sensor.can_submit() {
            self.skipped += 1;
            return Ok(());
        }
        let tag = self.next_tag;
        self.next_tag += 1;
        let frame_index = real.as_ref().map_or(0, |r| r.index as u32);
        b.sensor.submit(gpu, store, &map_from_camera, frame_index, tag).map_err(|e| format!("virtual sensor: {e}"))?;
        // The views, queued after the render they show.
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("web.sim.views") });
        if let Some(r) = &real {
            let mut words: Vec<u32> = r.depth_units.chunks(2).map(|p| u32::from(p[0]) | (u32::from(*p.get(1).unwrap_or(&0)) << 16)).collect();
            words.resize((b.real_raw.size() / 4) as usize, 0);
            gpu.write_buffer(&b.real_raw, &words);
        }
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("web.sim.views"), timestamp_writes: None });
            b.sim_view.dispatch_in(gpu, &mut pass);
            if real.is_some() {
                b.real_view.dispatch_in(gpu, &mut pass);
            }
        }
        let mut textures = vec![b.sim_canvas.draw(&mut encoder, &b.sim_view.image)?];
        if real.is_some() {
            textures.push(b.real_canvas.draw(&mut encoder, &b.real_view.image)?);
        }
        gpu.submit([encoder.finish()]);
        GpuCanvas::present(gpu, textures);
        ui::set_value(POSE_INPUT, &format_pose(&map_from_camera));
        // The last mask belongs to an older render.
        clear_canvas(UNKNOWN_CANVAS, key.intrinsics);
        self.unknown.drawn = None;
        if ask_bridge {
            let request_id = self.unknown.next_id;
            self.unknown.next_id = self.unknown.next_id.wrapping_add(1);
            let request = RenderRequest {
                request_id,
                world_from_camera: map_from_camera,
                intrinsics: key.intrinsics,
                depth_units_per_metre: key.units_per_metre,
                radial: false,
                depth_range_m: None,
                // The mask depends on where each ray returns; the exact render's returns.
                noise: None,
                color: false,
                unknown: true,
                depth_encoding: WireDepth::Raw,
            };
            self.unknown.newest = Some((tag, request));
        }
        self.pending.push_back(Pending { tag, map_from_camera, key, real, sent: Instant::now() });
        Ok(())
    }

    /// Takes the renders that came back (never waits): their metrics against the real frame
    /// and the difference image. True if one did.
    pub(crate) fn poll(&mut self, gpu: &Gpu) -> Result<bool, String> {
        let Some(b) = self.bound.as_mut() else { return Ok(false) };
        let frames = b.sensor.collect(gpu).map_err(|e| format!("virtual sensor: {e}"))?;
        let any = !frames.is_empty();
        for frame in frames {
            while self.pending.front().is_some_and(|p| p.tag != frame.tag) {
                self.pending.pop_front();
            }
            let Some(p) = self.pending.pop_front() else { continue };
            self.render_ms.push(p.sent.elapsed().as_secs_f64() * 1e3);
            self.rendered += 1;
            let k = p.key.intrinsics;
            let metrics = p.real.as_ref().map(|r| {
                let (sim_scale, real_scale) = (f64::from(p.key.units_per_metre), f64::from(r.units_per_metre));
                let rgb = difference_image(&frame.depth_units, sim_scale, &r.depth_units, real_scale, DIFFERENCE_MAX_MM);
                if let Ok(canvas) = ui::element::<web_sys::HtmlCanvasElement>(DIFFERENCE_CANVAS) {
                    view::draw_rgba(&canvas, k.width_px, k.height_px, &view::rgba_from_rgb(&rgb)).ok();
                }
                compare_depth(&frame.depth_units, sim_scale, &r.depth_units, real_scale)
            });
            if metrics.is_none() {
                clear_canvas(DIFFERENCE_CANVAS, k);
                clear_canvas(REAL_CANVAS, k);
            }
            ui::set_text("sim-caption", &caption(&p, metrics.as_ref(), frame.depth_units.iter().filter(|&&u| u > 0).count()));
            self.last = Some(Rendered { map_from_camera: p.map_from_camera, key: p.key, real_index: p.real.map(|r| r.index), depth_units: frame.depth_units, metrics });
        }
        Ok(any)
    }

    /// Offers the last render as a 16-bit PNG at the TUM scale (what `simulate` writes).
    pub(crate) fn download(&self) -> Result<(), String> {
        let Some(r) = &self.last else { return Err("nothing rendered yet".to_owned()) };
        let k = r.key.intrinsics;
        let image = webfusion_core::DepthImage { width_px: k.width_px, height_px: k.height_px, units: r.depth_units.clone() };
        let png = webfusion_core::codec::png::encode_depth16(&image).map_err(|e| e.to_string())?;
        let name = match (r.real_index, r.key.noise_seed) {
            (Some(i), Some(seed)) => format!("sim_depth_frame{i}_noise{seed}.png"),
            (Some(i), None) => format!("sim_depth_frame{i}.png"),
            (None, Some(seed)) => format!("sim_depth_noise{seed}.png"),
            (None, None) => "sim_depth.png".to_owned(),
        };
        ui::download(&name, &png, "image/png").map_err(|e| crate::link::js_text(&e))
    }

    pub(crate) fn status(&self, map: Option<&OpenedMap>) -> SensorStatus {
        SensorStatus {
            map: map.map(OpenedMap::status),
            follow: self.follow,
            noise_seed: self.noise_seed,
            rendered: self.rendered,
            skipped: self.skipped,
            in_flight: self.pending.len(),
            median_ms: self.render_ms.median(),
            unknown: UnknownStatus {
                asked: self.unknown.asked.is_some(),
                unavailable: self.unknown.unavailable.clone(),
                marked_percent: self.unknown.drawn.map(|(_, marked, pixels)| 100.0 * marked as f64 / pixels.max(1) as f64),
                marked_render: self.unknown.drawn.map(|(tag, _, _)| tag),
                stale: self.unknown.stale,
            },
            last: self.last.as_ref().map(|r| LastRender {
                pose: tum_pose(&r.map_from_camera),
                width_px: r.key.intrinsics.width_px,
                height_px: r.key.intrinsics.height_px,
                noise_seed: r.key.noise_seed,
                frame: r.real_index,
                valid_pixels: r.depth_units.iter().filter(|&&u| u > 0).count(),
                compare: r.metrics.map(|m| CompareStatus {
                    pixels_rel_error_over_10pct_percent: m.pixels_rel_error_over_10pct_percent,
                    new_valid_pixels_percent: m.new_valid_pixels_percent,
                    coverage_percent: m.coverage_percent,
                    mean_abs_error_mm: m.mean_abs_error_mm,
                    median_abs_error_mm: m.median_abs_error_mm,
                }),
            }),
        }
    }
}

/// Builds the sensor for `key` in `store` and its views' canvases.
/// The sensor's camera: the real frame's at its pose, else `camera` (the map's), else the
/// nominal Kinect.
fn sensor_intrinsics(real: Option<&RealFrame>, camera: Option<PinholeIntrinsics>) -> PinholeIntrinsics {
    real.map_or_else(|| camera.unwrap_or_else(|| PinholeIntrinsics::nominal_kinect(640, 480)), |r| r.intrinsics)
}

/// What a sensor render with `real` and `camera` (as [`SensorPanel::render`] takes them) reads
/// of a map: the cone a windowed map must hold (`map::window`).
pub(crate) fn sensor_cone(real: Option<&RealFrame>, camera: Option<PinholeIntrinsics>) -> ViewCone {
    ViewCone::for_camera(&sensor_intrinsics(real, camera), SensorOptions::default().depth_range_m)
}

fn bind(gpu: &Gpu, store: &dyn TsdfStore, key: SensorKey) -> Result<Bound, String> {
    let options = SensorOptions { units_per_metre: key.units_per_metre, noise: key.noise_seed.map(|seed| (KinectModel::default(), seed)), ..SensorOptions::default() };
    let sensor = VirtualSensor::new(gpu, store, key.intrinsics, options).map_err(|e| format!("virtual sensor: {e}"))?;
    let size = [key.intrinsics.width_px, key.intrinsics.height_px];
    let metres_per_unit = 1.0 / key.units_per_metre;
    let real_raw = gpu.storage_buffer::<u32>("web.sim.real_raw", key.intrinsics.pixel_count().div_ceil(2));
    Ok(Bound {
        sim_view: DepthView::new(gpu, sensor.depth_raw(), size, metres_per_unit, DEFAULT_DEPTH_VIEW_MAX_M),
        sim_canvas: GpuCanvas::new(gpu, SIM_CANVAS, size)?,
        real_view: DepthView::new(gpu, &real_raw, size, metres_per_unit, DEFAULT_DEPTH_VIEW_MAX_M),
        real_canvas: GpuCanvas::new(gpu, REAL_CANVAS, size)?,
        real_raw,
        key,
        sensor,
    })
}

fn clear_canvas(id: &str, k: PinholeIntrinsics) {
    if let Ok(canvas) = ui::element::<web_sys::HtmlCanvasElement>(id)
        && let Ok(ctx) = view::context_2d(&canvas, k.width_px, k.height_px)
    {
        ctx.clear_rect(0.0, 0.0, f64::from(k.width_px), f64::from(k.height_px));
    }
}

/// The panel's caption for a render.
fn caption(p: &Pending, metrics: Option<&DepthComparison>, valid: usize) -> String {
    let k = p.key.intrinsics;
    let noise = p.key.noise_seed.map_or_else(|| "exact".to_owned(), |s| format!("Kinect noise, seed {s}"));
    let at = p.real.as_ref().map_or_else(|| "a placed pose".to_owned(), |r| format!("frame {}'s pose", r.index));
    let valid = 100.0 * valid as f64 / k.pixel_count().max(1) as f64;
    match metrics {
        Some(m) => format!(
            "{}x{} at {at}, {noise}: {valid:.1} % valid · vs the real frame: coverage {:.1} % · {:.2} % of pixels over 10 % error · new valid {:+.1} % · |error| mean {:.1} mm, median {:.1} mm",
            k.width_px, k.height_px, m.coverage_percent, m.pixels_rel_error_over_10pct_percent, m.new_valid_pixels_percent, m.mean_abs_error_mm, m.median_abs_error_mm
        ),
        None => format!("{}x{} at {at}, {noise}: {valid:.1} % valid (no real frame at this pose)", k.width_px, k.height_px),
    }
}

/// `[tx, ty, tz, qx, qy, qz, qw]`, the TUM order.
fn tum_pose(p: &Se3) -> [f64; 7] {
    let (t, q) = (p.translation_m, p.rotation);
    [t.x, t.y, t.z, q.x, q.y, q.z, q.w]
}

/// A pose as the pose input shows it: `tx ty tz qx qy qz qw` (metres; TUM order).
pub(crate) fn format_pose(p: &Se3) -> String {
    tum_pose(p).iter().map(|v| format!("{v:.6}")).collect::<Vec<_>>().join(" ")
}

/// Reads the pose input's `tx ty tz qx qy qz qw` (metres, a quaternion of any non-zero norm).
pub(crate) fn parse_pose(text: &str) -> Result<Se3, String> {
    let values: Vec<f64> = text.split([' ', ',', '\t']).filter(|s| !s.is_empty()).map(|s| s.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| format!("{s:?} is not a finite number"))).collect::<Result<_, _>>()?;
    let [tx, ty, tz, qx, qy, qz, qw] = values[..] else { return Err(format!("a pose is 7 numbers (tx ty tz qx qy qz qw), not {}", values.len())) };
    let q = DQuat::from_xyzw(qx, qy, qz, qw);
    if q.length() < 1e-6 {
        return Err("the rotation quaternion is zero".to_owned());
    }
    Ok(Se3::new(q.normalize(), DVec3::new(tx, ty, tz)))
}

impl SensorStatus {
    /// The status panel's line for the opened map and the sensor, if either is in use.
    pub(crate) fn line(&self) -> Option<String> {
        let map = self.map.as_ref().map(|m| {
            let damage = m.damage.as_ref().map(|d| format!(" (damaged: {d}; its intact blocks kept)")).unwrap_or_default();
            let window = match (m.pool_blocks, m.free_view_complete_within_m) {
                (Some(pool), Some(within)) => format!(" · larger than its GPU pool of {pool} blocks: the free view shows the nearest of its blocks, complete within {within:.1} m ({} further blocks left out)", m.free_view_left_out),
                (Some(pool), None) => format!(" · through a window of {pool} blocks ({} uploaded)", m.windows),
                _ => String::new(),
            };
            format!("opened map {}: {} map, {} blocks of {:.1} mm, {:.0} MiB, {} frame{damage}{window}", m.name, m.kind, m.blocks, m.voxel_size_m * 1e3, m.memory_bytes as f64 / 1048576.0, m.frame)
        });
        let unknown = match (&self.unknown.unavailable, self.unknown.marked_percent) {
            (Some(why), _) => format!(" · no unknown marks: {why}"),
            (None, Some(p)) => format!(" · {p:.1} % of the pixels looked through never-observed space (magenta, from the bridge)"),
            (None, None) => String::new(),
        };
        let sensor = (self.rendered > 0).then(|| format!("virtual sensor: {} renders ({} skipped), {:.0} ms each{unknown}", self.rendered, self.skipped, self.median_ms.unwrap_or(0.0)));
        match (map, sensor) {
            (None, None) => None,
            (a, b) => Some([a, b].into_iter().flatten().collect::<Vec<_>>().join(" · ")),
        }
    }
}

/// A saved map's part of the status.
#[derive(Clone, Debug, serde::Serialize)]
pub(crate) struct OpenedMapStatus {
    name: String,
    kind: &'static str,
    blocks: usize,
    voxel_size_m: f32,
    frame: &'static str,
    memory_bytes: u64,
    damage: Option<String>,
    /// Mean of its blocks' centres and their RMS distance from it, metres.
    centre_m: [f64; 3],
    spread_m: f64,
    /// The up direction its file names (the free view orbits about it), if any.
    up_in_map: Option<[f32; 3]>,
    /// The GPU pool's blocks when the map is larger (rendered through a window), else `None`.
    pool_blocks: Option<usize>,
    /// Windows uploaded so far.
    windows: u64,
    /// Blocks the free view's last window could not hold (0: it was exact).
    free_view_left_out: usize,
    /// How far from the free view's camera its last image is exact, metres, when blocks were
    /// left out.
    free_view_complete_within_m: Option<f64>,
}

/// The virtual sensor's part of the status.
#[derive(Clone, Debug, serde::Serialize)]
pub(crate) struct SensorStatus {
    map: Option<OpenedMapStatus>,
    follow: bool,
    noise_seed: Option<u32>,
    rendered: u64,
    skipped: u64,
    in_flight: usize,
    median_ms: Option<f64>,
    unknown: UnknownStatus,
    last: Option<LastRender>,
}

/// The bridge's unknown marks of the renders.
#[derive(Clone, Debug, serde::Serialize)]
struct UnknownStatus {
    /// A request is in flight.
    asked: bool,
    /// Why the bridge cannot mark pixels (it has no occupancy grid), once it said so.
    unavailable: Option<String>,
    /// Of the last marked render, the pixels that looked through never-observed space, %.
    marked_percent: Option<f64>,
    /// Which render (counting from 0) that was.
    marked_render: Option<u64>,
    /// Masks that came back after a newer render (not drawn).
    stale: u64,
}

#[derive(Clone, Debug, serde::Serialize)]
struct LastRender {
    pose: [f64; 7],
    width_px: u32,
    height_px: u32,
    noise_seed: Option<u32>,
    frame: Option<u64>,
    valid_pixels: usize,
    compare: Option<CompareStatus>,
}

/// `webfusion compare`'s metrics (its JSON's keys).
#[derive(Clone, Copy, Debug, serde::Serialize)]
struct CompareStatus {
    pixels_rel_error_over_10pct_percent: f64,
    new_valid_pixels_percent: f64,
    coverage_percent: f64,
    mean_abs_error_mm: f64,
    median_abs_error_mm: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use wasm_bindgen_test::wasm_bindgen_test;

    #[wasm_bindgen_test]
    fn poses_round_trip_through_the_input_and_bad_ones_are_named() {
        let pose = Se3::new(DQuat::from_rotation_y(0.3) * DQuat::from_rotation_x(-0.2), DVec3::new(1.25, -0.5, 2.0));
        let back = parse_pose(&format_pose(&pose)).expect("its own text");
        assert!((back.translation_m - pose.translation_m).length() < 1e-6 && back.rotation.angle_between(pose.rotation) < 1e-5);
        // A quaternion of any norm, commas or spaces.
        let scaled = parse_pose("0,0,1, 0,0,0,2").expect("scaled");
        assert!(scaled.rotation.abs_diff_eq(DQuat::IDENTITY, 1e-12) && scaled.translation_m == DVec3::Z);
        assert!(parse_pose("1 2 3").is_err_and(|e| e.contains("7 numbers")));
        assert!(parse_pose("0 0 0 0 0 0 NaN").is_err_and(|e| e.contains("finite")));
        assert!(parse_pose("0 0 0 0 0 0 0").is_err_and(|e| e.contains("zero")));
    }
}
