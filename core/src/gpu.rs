// SPDX-License-Identifier: MIT
//! The GPU context: one adapter, device and queue, with every kernel pipeline built once.
//!
//! Natively this is Vulkan (Mesa lavapipe is a valid adapter, device type `Cpu`); in the
//! browser it is WebGPU. The constructor is async so the same code serves both: native callers
//! drive it with `pollster::block_on`, the web app with `wasm_bindgen_futures`.

use std::sync::{Arc, Mutex};

use crate::kernels::Kernels;
use crate::{Error, Result};

/// Bytes of workgroup memory requested where the adapter offers them (lavapipe and desktop
/// GPUs do; wgpu's default is 16 KiB).
pub const PREFERRED_WORKGROUP_STORAGE_BYTES: u32 = 32 * 1024;
/// Storage-buffer binding size the volume kernels need: a 256^3 TSDF of 2 x 16-bit voxels.
pub const REQUIRED_STORAGE_BINDING_BYTES: u64 = 128 * 1024 * 1024;
/// Seconds a native wait on the GPU may take before it is reported as an error.
pub const POLL_TIMEOUT_S: u64 = 30;

/// How to pick the adapter.
#[derive(Clone, Debug, Default)]
pub struct GpuOptions {
    /// Only use an adapter whose name contains this (case-insensitive), e.g. `llvmpipe`.
    /// Natively the environment variable `WEBFUSION_ADAPTER` supplies a default.
    pub adapter_name_contains: Option<String>,
    /// Prefer a CPU adapter (lavapipe) over real GPUs, as the test suite does for determinism.
    pub prefer_cpu_adapter: bool,
}

/// Device, queue, adapter facts and the kernel pipelines.
pub struct Gpu {
    /// The logical device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Name, backend and type of the adapter.
    pub adapter_info: wgpu::AdapterInfo,
    /// The limits the device was created with.
    pub limits: wgpu::Limits,
    /// Every kernel, compiled for this device.
    pub kernels: Kernels,
    errors: Arc<Mutex<Vec<String>>>,
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gpu").field("adapter", &self.adapter_info.name).field("backend", &self.adapter_info.backend).finish()
    }
}

impl Gpu {
    /// Finds an adapter, checks it offers what the kernels need, creates the device and builds
    /// every pipeline.
    pub async fn new(options: &GpuOptions) -> Result<Self> {
        let backends = if cfg!(target_arch = "wasm32") { wgpu::Backends::BROWSER_WEBGPU } else { wgpu::Backends::VULKAN };
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = backends;
        desc.flags = wgpu::InstanceFlags::from_build_config().with_env();
        let instance = wgpu::Instance::new(desc);
        let adapter = select_adapter(&instance, backends, options).await?;
        Self::from_adapter(&adapter).await
    }

    /// Creates the device on a given adapter.
    pub async fn from_adapter(adapter: &wgpu::Adapter) -> Result<Self> {
        let adapter_info = adapter.get_info();
        let required_limits = required_limits(&adapter_info.name, &adapter.limits())?;
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("core.device"),
                required_features: wgpu::Features::empty(),
                required_limits: required_limits.clone(),
                memory_hints: wgpu::MemoryHints::Performance,
                ..Default::default()
            })
            .await?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let message = e.to_string();
            log_error(&message);
            if let Ok(mut v) = sink.lock() {
                v.push(message);
            }
        }));
        let kernels = Kernels::new(&device);
        Ok(Self { device, queue, adapter_info, limits: required_limits, kernels, errors })
    }

    /// Validation and out-of-memory errors wgpu reported since the last call. Tests fail on
    /// any, even when the outputs look right.
    pub fn take_errors(&self) -> Vec<String> {
        self.errors.lock().map(|mut v| std::mem::take(&mut *v)).unwrap_or_default()
    }

    /// One line describing the adapter, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)`.
    pub fn adapter_summary(&self) -> String {
        format!("{} ({:?}, {:?})", self.adapter_info.name, self.adapter_info.backend, self.adapter_info.device_type)
    }

    /// A storage buffer of `len` elements of `T`, usable as kernel input or output and as a
    /// copy source/destination.
    pub fn storage_buffer<T: bytemuck::Pod>(&self, label: &str, len: usize) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (len.max(1) * std::mem::size_of::<T>()).next_multiple_of(4) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// A uniform buffer holding `value`.
    pub fn uniform_buffer<T: bytemuck::Pod>(&self, label: &str, value: &T) -> wgpu::Buffer {
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: std::mem::size_of::<T>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.queue.write_buffer(&buffer, 0, bytemuck::bytes_of(value));
        buffer
    }

    /// Uploads `data` to the start of `buffer`; odd byte lengths are zero-padded to 4 bytes.
    pub fn write_buffer<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, data: &[T]) {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.len().is_multiple_of(4) {
            self.queue.write_buffer(buffer, 0, bytes);
        } else {
            let mut padded = bytes.to_vec();
            padded.resize(bytes.len().next_multiple_of(4), 0);
            self.queue.write_buffer(buffer, 0, &padded);
        }
    }

    /// Fills `buffer` with copies of `value` (tests use a sentinel so "not written" cannot pass).
    pub fn fill_buffer<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, value: T) {
        let n = buffer.size() as usize / std::mem::size_of::<T>();
        self.queue.write_buffer(buffer, 0, bytemuck::cast_slice(&vec![value; n]));
    }

    /// Submits the encoder and waits until the GPU has finished it.
    pub async fn submit_and_wait(&self, encoder: wgpu::CommandEncoder) -> Result<()> {
        let index = self.queue.submit(Some(encoder.finish()));
        self.wait(Some(index)).await
    }

    /// Waits for the queue (natively blocking with a timeout; in the browser by yielding to
    /// the event loop).
    pub async fn wait(&self, index: Option<wgpu::SubmissionIndex>) -> Result<()> {
        #[cfg(not(target_arch = "wasm32"))]
        {
            self.device
                .poll(wgpu::PollType::Wait { submission_index: index, timeout: Some(std::time::Duration::from_secs(POLL_TIMEOUT_S)) })
                .map_err(|e| Error::Poll(e.to_string()))?;
        }
        #[cfg(target_arch = "wasm32")]
        {
            let _ = index;
            let (sender, receiver) = oneshot();
            self.queue.on_submitted_work_done(move || sender.send(()));
            receiver.await;
        }
        Ok(())
    }

    /// Copies the first `len` elements of `buffer` back to the CPU.
    pub async fn read_buffer<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, len: usize) -> Result<Vec<T>> {
        self.read_buffers(&[(buffer, len)]).await
    }

    /// Copies the first `len` elements of each buffer back to the CPU in one submission and
    /// one mapping, concatenated in order (ICP reads its two partial-sum buffers this way).
    pub async fn read_buffers<T: bytemuck::Pod>(&self, parts: &[(&wgpu::Buffer, usize)]) -> Result<Vec<T>> {
        let sizes: Vec<u64> = parts.iter().map(|&(_, len)| ((len * std::mem::size_of::<T>()) as u64).next_multiple_of(4)).collect();
        let total: u64 = sizes.iter().sum();
        let label = "core.readback".to_owned();
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&label),
            size: total.max(4),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(&label) });
        let mut offset = 0;
        for (&(buffer, _), &size) in parts.iter().zip(&sizes) {
            encoder.copy_buffer_to_buffer(buffer, 0, &staging, offset, size);
            offset += size;
        }
        let index = self.queue.submit(Some(encoder.finish()));
        let (sender, receiver) = oneshot();
        staging.map_async(wgpu::MapMode::Read, .., move |r| sender.send(r));
        self.wait(Some(index)).await?;
        receiver.await.map_err(|e| Error::BufferMap { label: label.clone(), message: e.to_string() })?;
        let view = staging.get_mapped_range(..).map_err(|e| Error::BufferMap { label: label.clone(), message: e.to_string() })?;
        let mut out = Vec::with_capacity(parts.iter().map(|p| p.1).sum());
        let mut offset = 0usize;
        for (&(_, len), &size) in parts.iter().zip(&sizes) {
            out.extend(bytemuck::pod_collect_to_vec::<u8, T>(&view[offset..offset + len * std::mem::size_of::<T>()]));
            offset += size as usize;
        }
        drop(view);
        staging.unmap();
        Ok(out)
    }
}

fn log_error(message: &str) {
    #[cfg(not(target_arch = "wasm32"))]
    eprintln!("wgpu error: {message}");
    #[cfg(target_arch = "wasm32")]
    let _ = message;
}

/// Picks an adapter by the options: name filter, then device type preference.
async fn select_adapter(instance: &wgpu::Instance, backends: wgpu::Backends, options: &GpuOptions) -> Result<wgpu::Adapter> {
    let wanted = options.adapter_name_contains.clone().or_else(|| {
        if cfg!(target_arch = "wasm32") { None } else { std::env::var("WEBFUSION_ADAPTER").ok().filter(|s| !s.is_empty()) }
    });
    let no_adapter = || Error::NoAdapter { backends: format!("{backends:?}"), wanted: wanted.clone() };
    #[cfg(target_arch = "wasm32")]
    {
        let _ = options;
        instance
            .request_adapter(&wgpu::RequestAdapterOptions { power_preference: wgpu::PowerPreference::HighPerformance, ..Default::default() })
            .await
            .map_err(|_| no_adapter())
    }
    #[cfg(not(target_arch = "wasm32"))]
    {
        let adapters = instance.enumerate_adapters(backends).await;
        let rank = |t: wgpu::DeviceType| -> u8 {
            use wgpu::DeviceType as D;
            match (options.prefer_cpu_adapter, t) {
                (true, D::Cpu) => 0,
                (false, D::DiscreteGpu) => 0,
                (_, D::IntegratedGpu) => 1,
                (_, D::VirtualGpu) => 2,
                (false, D::Cpu) => 3,
                _ => 4,
            }
        };
        adapters
            .into_iter()
            .filter(|a| wanted.as_ref().is_none_or(|w| a.get_info().name.to_lowercase().contains(&w.to_lowercase())))
            .min_by_key(|a| rank(a.get_info().device_type))
            .ok_or_else(no_adapter)
    }
}

/// WebGPU's default limits raised to what the kernels need, or an error naming the first limit
/// the adapter lacks.
fn required_limits(adapter: &str, available: &wgpu::Limits) -> Result<wgpu::Limits> {
    let mut limits = wgpu::Limits::default();
    let need_storage_buffers = webfusion_shaders::ALL
        .iter()
        .map(|k| k.bindings.iter().filter(|b| b.kind != webfusion_shaders::BindingKind::Uniform).count() as u32)
        .max()
        .unwrap_or(0);
    let need_invocations = webfusion_shaders::ALL.iter().map(|k| k.workgroup_size.iter().product::<u32>()).max().unwrap_or(1);
    let check = |name: &'static str, required: u64, got: u64| -> Result<()> {
        if got < required { Err(Error::MissingLimit { adapter: adapter.to_owned(), name, required, available: got }) } else { Ok(()) }
    };
    check("max_storage_buffers_per_shader_stage", need_storage_buffers.into(), available.max_storage_buffers_per_shader_stage.into())?;
    check("max_compute_invocations_per_workgroup", need_invocations.into(), available.max_compute_invocations_per_workgroup.into())?;
    check("max_storage_buffer_binding_size", REQUIRED_STORAGE_BINDING_BYTES, available.max_storage_buffer_binding_size)?;
    check("max_compute_workgroup_storage_size", 16 * 1024, available.max_compute_workgroup_storage_size.into())?;
    limits.max_storage_buffers_per_shader_stage = limits.max_storage_buffers_per_shader_stage.max(need_storage_buffers);
    limits.max_storage_buffer_binding_size = limits.max_storage_buffer_binding_size.max(REQUIRED_STORAGE_BINDING_BYTES);
    limits.max_buffer_size = limits.max_buffer_size.max(REQUIRED_STORAGE_BINDING_BYTES).min(available.max_buffer_size);
    limits.max_compute_workgroup_storage_size = PREFERRED_WORKGROUP_STORAGE_BYTES.min(available.max_compute_workgroup_storage_size);
    Ok(limits)
}

/// A single-use channel whose receiver is a future; works without threads (browser) and with
/// them (native map callbacks).
fn oneshot<T: Send + 'static>() -> (OneshotSender<T>, OneshotReceiver<T>) {
    let shared = Arc::new(Mutex::new(OneshotState { value: None, waker: None }));
    (OneshotSender(shared.clone()), OneshotReceiver(shared))
}

struct OneshotState<T> {
    value: Option<T>,
    waker: Option<std::task::Waker>,
}

struct OneshotSender<T>(Arc<Mutex<OneshotState<T>>>);
struct OneshotReceiver<T>(Arc<Mutex<OneshotState<T>>>);

impl<T> OneshotSender<T> {
    fn send(self, value: T) {
        let waker = match self.0.lock() {
            Ok(mut s) => {
                s.value = Some(value);
                s.waker.take()
            }
            Err(_) => None,
        };
        if let Some(w) = waker {
            w.wake();
        }
    }
}

impl<T> std::future::Future for OneshotReceiver<T> {
    type Output = T;
    fn poll(self: std::pin::Pin<&mut Self>, cx: &mut std::task::Context<'_>) -> std::task::Poll<T> {
        let mut s = self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        match s.value.take() {
            Some(v) => std::task::Poll::Ready(v),
            None => {
                s.waker = Some(cx.waker().clone());
                std::task::Poll::Pending
            }
        }
    }
}
