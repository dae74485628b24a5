// SPDX-License-Identifier: MIT
//! `serve --map`: the virtual depth sensor behind the protocol's render requests.
//!
//! One worker thread owns the GPU, the saved map and a few [`VirtualSensor`]s (one per
//! combination of intrinsics and sensor options recently asked for, so a planner that queries
//! many poses with one camera allocates once). Sessions hand it requests over a bounded
//! channel and await the reply; requests from all clients are rendered one at a time, in the
//! order they arrive. With the map's occupancy grid (`--occupancy`) a request may also ask
//! which pixels looked through never-observed space (marked on the CPU from the sensor's hits,
//! as `simulate --occupancy` does).

use std::collections::VecDeque;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use tokio::sync::{mpsc, oneshot};
use webfusion_core::map::Map;
use webfusion_core::map::occupancy::OccupancyGrid;
use webfusion_core::map::window::{ViewCone, ViewedMap};
use webfusion_core::map::file::{read_map_file, read_map_file_recovering};
use webfusion_core::protocol::{RenderFailure, RenderOutcome, RenderRequest, RenderedView};
use webfusion_core::sim::sensor::{SensorOptions, VirtualSensor};
use webfusion_core::tsdf::TsdfStore as _;
use webfusion_core::{DepthImage, Gpu, GpuOptions, PinholeIntrinsics};

/// Requests that may wait for the worker before a session waits to hand in its own.
const QUEUED_REQUESTS: usize = 16;
/// Sensors kept between requests (each holds its images' buffers on the GPU).
const CACHED_SENSORS: usize = 4;

struct Job {
    request: RenderRequest,
    reply: oneshot::Sender<RenderOutcome>,
}

/// The render worker of `serve --map`.
pub(crate) struct Renderer {
    jobs: mpsc::Sender<Job>,
}

impl Renderer {
    /// Loads the map at `path` onto the GPU (and its occupancy grid at `occupancy`) in a new
    /// worker thread; a map or grid that cannot be read or loaded fails here, before the server
    /// listens. Returns the worker and a line describing the map.
    pub(crate) fn start(options: GpuOptions, path: &Path, occupancy: Option<&Path>, skip_corrupt: bool) -> anyhow::Result<(Self, String)> {
        let (jobs, mut queue) = mpsc::channel::<Job>(QUEUED_REQUESTS);
        let (ready_tx, ready) = std::sync::mpsc::sync_channel::<anyhow::Result<String>>(1);
        let path: PathBuf = path.to_owned();
        let occupancy: Option<PathBuf> = occupancy.map(Path::to_owned);
        std::thread::Builder::new()
            .name("webfusion-render".to_owned())
            .spawn(move || {
                let (gpu, mut map, grid) = match load(&options, &path, occupancy.as_deref(), skip_corrupt) {
                    Ok((gpu, map, grid, summary)) => {
                        let _ = ready_tx.send(Ok(summary));
                        (gpu, map, grid)
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                let mut sensors = SensorCache::default();
                while let Some(job) = queue.blocking_recv() {
                    let outcome = render(&gpu, &mut map, grid.as_ref(), &mut sensors, &job.request);
                    // A client that left before its answer needs none.
                    let _ = job.reply.send(outcome);
                }
            })
            .context("starting the render worker")?;
        let summary = ready.recv().context("the render worker stopped while loading the map")??;
        Ok((Self { jobs }, summary))
    }

    /// Renders `request`, waiting behind the requests queued before it.
    pub(crate) async fn render(&self, request: RenderRequest) -> RenderOutcome {
        let stopped = || RenderOutcome::Failed { code: RenderFailure::RenderFailed, message: "the server's render worker has stopped".to_owned() };
        let (reply, answer) = oneshot::channel();
        if self.jobs.send(Job { request, reply }).await.is_err() {
            return stopped();
        }
        answer.await.unwrap_or_else(|_| stopped())
    }
}

/// The GPU and the map at `path` on it, the map's occupancy grid at `occupancy`, and a line
/// describing them.
fn load(options: &GpuOptions, path: &Path, occupancy: Option<&Path>, skip_corrupt: bool) -> anyhow::Result<(Gpu, ViewedMap, Option<OccupancyGrid>, String)> {
    let mut file = if skip_corrupt { read_map_file_recovering(path) } else { read_map_file(path) }.with_context(|| format!("reading the map {}", path.display()))?;
    if let Some(damage) = &file.damage {
        eprintln!("warning: {}: {damage}; serving the intact blocks", path.display());
    }
    let grid = occupancy.map(|g| crate::occupancy::read_grid_for_map(g, file.header.frame, path)).transpose()?;
    let gpu = pollster::block_on(Gpu::new(options))?;
    let n_blocks = file.blocks.len();
    // A map larger than the device's largest pool is rendered through a window that holds
    // each request's view (map::window).
    let map = ViewedMap::load(&gpu, &file.header, std::mem::take(&mut file.blocks), None).with_context(|| format!("loading {}", path.display()))?;
    let summary = format!(
        "map {}: {n_blocks} blocks of {:.1} mm voxels ({} map, {:.1} MiB on the GPU{}); render requests are answered{}",
        path.display(),
        file.header.voxel_size_m * 1e3,
        file.header.kind.name(),
        map.map().memory_bytes() as f64 / 1048576.0,
        map.window().map(|w| format!(", through a window of {} blocks", w.capacity())).unwrap_or_default(),
        if grid.is_some() { ", with unknown masks from the occupancy grid" } else { "" }
    );
    Ok((gpu, map, grid, summary))
}

/// The most recently used sensors, newest first.
#[derive(Default)]
struct SensorCache(VecDeque<(PinholeIntrinsics, SensorOptions, VirtualSensor)>);

impl SensorCache {
    /// The sensor for `k` and `options`, made (evicting the least recently used) when missing.
    fn get(&mut self, gpu: &Gpu, map: &Map, k: PinholeIntrinsics, options: SensorOptions) -> webfusion_core::Result<&mut VirtualSensor> {
        if let Some(at) = self.0.iter().position(|(ck, co, _)| *ck == k && *co == options) {
            let entry = self.0.remove(at).expect("found");
            self.0.push_front(entry);
        } else {
            let sensor = VirtualSensor::new(gpu, map, k, options)?;
            self.0.truncate(CACHED_SENSORS - 1);
            self.0.push_front((k, options, sensor));
        }
        Ok(&mut self.0.front_mut().expect("just placed").2)
    }
}

/// Renders one request: its view, or why there is none.
fn render(gpu: &Gpu, viewed: &mut ViewedMap, grid: Option<&OccupancyGrid>, sensors: &mut SensorCache, request: &RenderRequest) -> RenderOutcome {
    let failed = |code, message: String| RenderOutcome::Failed { code, message };
    let k = request.intrinsics;
    if request.unknown && grid.is_none() {
        return failed(RenderFailure::InvalidRequest, "this server has no occupancy grid to mark unknown pixels from (start it with --map M --occupancy G.json)".to_owned());
    }
    let options = match crate::simulate::kinect_sensor(request.depth_units_per_metre, request.radial, request.noise.map(|n| n.seed), (request.depth_range_m.map(|r| r.0), request.depth_range_m.map(|r| r.1)), request.color) {
        // The unknown mask needs each pixel's hit distance.
        Ok(options) => SensorOptions { hits: request.unknown, ..options },
        Err(e) => return failed(RenderFailure::InvalidRequest, format!("{e:#}")),
    };
    match viewed.prepare(gpu, &request.world_from_camera, &ViewCone::for_camera(&k, options.depth_range_m)) {
        Ok(_) => {}
        // The view alone needs more than the pool: the request must ask for less.
        Err(e @ webfusion_core::Error::ViewExceedsPool { .. }) => return failed(RenderFailure::InvalidRequest, e.to_string()),
        Err(e) => return failed(RenderFailure::RenderFailed, e.to_string()),
    }
    let map = viewed.map();
    let sensor = match sensors.get(gpu, map, k, options) {
        Ok(sensor) => sensor,
        // The sensor refuses what the protocol cannot check alone (a range past the u16 scale).
        Err(webfusion_core::Error::InvalidConfig(reason)) => return failed(RenderFailure::InvalidRequest, reason),
        Err(e) => return failed(RenderFailure::RenderFailed, e.to_string()),
    };
    let frame_index = request.noise.map_or(0, |n| n.frame_index);
    let frame = pollster::block_on(sensor.render(gpu, map, &request.world_from_camera, frame_index));
    let errors = gpu.take_errors();
    if !errors.is_empty() {
        return failed(RenderFailure::RenderFailed, format!("the GPU reported errors: {}", errors.join("; ")));
    }
    let frame = match frame {
        Ok(frame) => frame,
        Err(e) => return failed(RenderFailure::RenderFailed, e.to_string()),
    };
    let unknown_mask = match (grid, &frame.hit_m) {
        (Some(grid), Some(hit_m)) if request.unknown => match crate::occupancy::unknown_mask(grid, k, &request.world_from_camera, hit_m, options.depth_range_m) {
            Ok(mask) => Some(mask),
            Err(e) => return failed(RenderFailure::RenderFailed, e.to_string()),
        },
        (_, None) if request.unknown => return failed(RenderFailure::RenderFailed, "the sensor returned no hit distances for the unknown mask".to_owned()),
        _ => None,
    };
    let depth = match DepthImage::new(k.width_px, k.height_px, frame.depth_units) {
        Ok(depth) => depth,
        Err(e) => return failed(RenderFailure::RenderFailed, e.to_string()),
    };
    RenderOutcome::View(RenderedView {
        width_px: k.width_px,
        height_px: k.height_px,
        depth_units_per_metre: request.depth_units_per_metre,
        radial: request.radial,
        depth_encoding: request.depth_encoding,
        depth_payload: request.depth_encoding.encode(&depth),
        color_rgb8: frame.color_rgb8.map(|rgb| rgb.as_flattened().to_vec()),
        unknown_mask,
    })
}
