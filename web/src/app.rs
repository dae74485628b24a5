// SPDX-License-Identifier: MIT
//! App start-up, the replay loop and the DOM views.

use std::fmt::Write as _;

use wasm_bindgen::prelude::*;
use web_time::Instant;
use webfusion_core::preprocess::{DepthPreprocessor, PreprocessConfig};
use webfusion_core::recording::RecordingReader;
use webfusion_core::source::FrameSource;
use webfusion_core::{Gpu, GpuOptions};

/// The sample recording trunk copies next to the page.
const SAMPLE_URL: &str = "fr1_rpy.wfr";

/// Entry point: runs when the wasm module loads.
#[wasm_bindgen(start)]
pub fn start() {
    wasm_bindgen_futures::spawn_local(async {
        if let Err(e) = run().await {
            let message = e.as_string().unwrap_or_else(|| format!("{e:?}"));
            set_text("status", &format!("error: {message}"));
            publish(&serde_status("error", &message, 0, 0, "", &[]));
        }
    });
}

fn document() -> web_sys::Document {
    web_sys::window().and_then(|w| w.document()).expect("the app runs in a page with a document")
}

fn set_text(id: &str, text: &str) {
    if let Some(el) = document().get_element_by_id(id) {
        el.set_text_content(Some(text));
    }
}

/// Publishes status JSON on `window.webfusion.status` (parsed) for tests and tools.
fn publish(json: &str) {
    let Some(window) = web_sys::window() else { return };
    let hook = js_sys::Object::new();
    if let Ok(value) = js_sys::JSON::parse(json) {
        js_sys::Reflect::set(&hook, &"status".into(), &value).ok();
    }
    js_sys::Reflect::set(&window, &"webfusion".into(), &hook).ok();
}

fn serde_status(state: &str, message: &str, frames_done: usize, frames_total: usize, adapter: &str, stages: &[(String, f64)]) -> String {
    let mut s = String::new();
    let esc = |t: &str| t.replace('\\', "\\\\").replace('"', "\\\"");
    write!(s, "{{\"state\":\"{}\",\"message\":\"{}\",\"frames_done\":{frames_done},\"frames_total\":{frames_total},\"adapter\":\"{}\",\"stages_ms\":{{", esc(state), esc(message), esc(adapter)).ok();
    for (i, (name, ms)) in stages.iter().enumerate() {
        write!(s, "{}\"{}\":{ms:.3}", if i > 0 { "," } else { "" }, esc(name)).ok();
    }
    s.push_str("}}");
    s
}

async fn fetch_bytes(url: &str) -> Result<Vec<u8>, JsValue> {
    let window = web_sys::window().ok_or("no window")?;
    let response: web_sys::Response = wasm_bindgen_futures::JsFuture::from(window.fetch_with_str(url)).await?.dyn_into()?;
    if !response.ok() {
        return Err(format!("GET {url}: HTTP {}", response.status()).into());
    }
    let buffer = wasm_bindgen_futures::JsFuture::from(response.array_buffer()?).await?;
    Ok(js_sys::Uint8Array::new(&buffer).to_vec())
}

async fn run() -> Result<(), JsValue> {
    let has_webgpu = web_sys::window().map(|w| js_sys::Reflect::has(&w.navigator(), &"gpu".into()).unwrap_or(false)).unwrap_or(false);
    if !has_webgpu {
        return Err("this browser has no WebGPU (navigator.gpu is missing). Use Chrome/Edge 113+ or Chromium with --enable-unsafe-webgpu, Firefox 141+ on Windows, or Safari 26+.".into());
    }
    set_text("status", "requesting a WebGPU adapter…");
    let gpu = Gpu::new(&GpuOptions::default()).await.map_err(|e| e.to_string())?;
    let adapter = gpu.adapter_summary();
    set_text("adapter", &adapter);
    set_text("status", "loading the sample recording…");
    let bytes = fetch_bytes(SAMPLE_URL).await?;
    let mut source = RecordingReader::from_bytes(bytes).map_err(|e| e.to_string())?;
    let calibration = source.calibration();
    let pre = DepthPreprocessor::new(&gpu, calibration, PreprocessConfig::default()).map_err(|e| e.to_string())?;
    let k = calibration.intrinsics;
    let canvas: web_sys::HtmlCanvasElement = document().get_element_by_id("normals").ok_or("no #normals canvas")?.dyn_into()?;
    canvas.set_width(k.width_px);
    canvas.set_height(k.height_px);
    let ctx: web_sys::CanvasRenderingContext2d = canvas.get_context("2d")?.ok_or("no 2d context")?.dyn_into()?;
    let total = source.frame_count();
    let mut sums: Vec<(String, f64)> = Vec::new();
    for index in 0..total {
        let t0 = Instant::now();
        let frame = source.read_frame(index).map_err(|e| e.to_string())?;
        let t1 = Instant::now();
        pre.run(&gpu, &frame).await.map_err(|e| e.to_string())?;
        let t2 = Instant::now();
        let normals: Vec<[f32; 4]> = gpu.read_buffer(&pre.levels[0].normal_in_camera, k.pixel_count()).await.map_err(|e| e.to_string())?;
        let mut rgba = vec![0u8; 4 * normals.len()];
        for (px, n) in rgba.chunks_exact_mut(4).zip(&normals) {
            if !n[0].is_nan() {
                px[0] = ((0.5 - 0.5 * n[0]) * 255.0) as u8;
                px[1] = ((0.5 - 0.5 * n[1]) * 255.0) as u8;
                px[2] = ((0.5 - 0.5 * n[2]) * 255.0) as u8;
            }
            px[3] = 255;
        }
        let image = web_sys::ImageData::new_with_u8_clamped_array_and_sh(wasm_bindgen::Clamped(&rgba), k.width_px, k.height_px)?;
        ctx.put_image_data(&image, 0.0, 0.0)?;
        let t3 = Instant::now();
        let stage = [("decode", t1 - t0), ("gpu preprocess", t2 - t1), ("readback + draw", t3 - t2)];
        for (name, d) in stage {
            match sums.iter_mut().find(|(n, _)| n == name) {
                Some((_, s)) => *s += d.as_secs_f64() * 1e3,
                None => sums.push((name.to_owned(), d.as_secs_f64() * 1e3)),
            }
        }
        let done = index + 1;
        let means: Vec<(String, f64)> = sums.iter().map(|(n, s)| (n.clone(), s / done as f64)).collect();
        let mut line = format!("frame {done}/{total}");
        for (n, ms) in &means {
            write!(line, " · {n} {ms:.1} ms").ok();
        }
        set_text("status", &line);
        let state = if done == total { "done" } else { "running" };
        publish(&serde_status(state, "", done, total, &adapter, &means));
    }
    let errors = gpu.take_errors();
    if !errors.is_empty() {
        return Err(format!("WebGPU reported errors: {}", errors.join("; ")).into());
    }
    Ok(())
}
