// SPDX-License-Identifier: MIT
//! WebGPU canvases: views colour-mapped on the GPU (`core::view`) are copied straight into a
//! canvas's texture, so no pixel of the depth, normal, model or free views is read back.

use wasm_bindgen::JsCast as _;
use webfusion_core::Gpu;
use webfusion_core::view::{ViewImage, copy_packed_to_texture};

use crate::ui;

/// A `<canvas>` configured for WebGPU with an `Rgba8Unorm` texture the views copy into.
pub(crate) struct GpuCanvas {
    surface: wgpu::Surface<'static>,
    size_px: [u32; 2],
    id: &'static str,
}

impl GpuCanvas {
    /// Sizes canvas `id` to `size_px` and configures its WebGPU context on `gpu`'s device.
    pub(crate) fn new(gpu: &Gpu, id: &'static str, size_px: [u32; 2]) -> Result<Self, String> {
        let canvas: web_sys::HtmlCanvasElement = ui::element(id)?;
        canvas.set_width(size_px[0]);
        canvas.set_height(size_px[1]);
        let instance = gpu.instance.as_ref().ok_or("the GPU has no wgpu instance to create canvas surfaces on")?;
        let surface = instance.create_surface(wgpu::SurfaceTarget::Canvas(canvas.unchecked_into())).map_err(|e| format!("canvas #{id}: no WebGPU context ({e})"))?;
        surface.configure(
            &gpu.device,
            &wgpu::SurfaceConfiguration {
                // COPY_DST: the views arrive by copy, not by a render pass.
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_DST,
                format: wgpu::TextureFormat::Rgba8Unorm,
                color_space: wgpu::SurfaceColorSpace::Auto,
                width: size_px[0],
                height: size_px[1],
                present_mode: wgpu::PresentMode::Fifo,
                desired_maximum_frame_latency: 2,
                alpha_mode: wgpu::CompositeAlphaMode::Opaque,
                view_formats: vec![],
            },
        );
        Ok(Self { surface, size_px, id })
    }

    /// Records a copy of `image` into the canvas's current texture; the caller submits
    /// `encoder`, then [`Self::present`]s what this returns. `None` when the canvas has no
    /// texture to give now (hidden page): the view is skipped, not an error.
    pub(crate) fn draw(&self, encoder: &mut wgpu::CommandEncoder, image: &ViewImage) -> Result<Option<wgpu::SurfaceTexture>, String> {
        self.draw_packed(encoder, &image.rgba8, image.row_stride_px)
    }

    /// As [`Self::draw`], for packed RGBA8 in `buffer` with rows `row_stride_px` apart.
    pub(crate) fn draw_packed(&self, encoder: &mut wgpu::CommandEncoder, buffer: &wgpu::Buffer, row_stride_px: u32) -> Result<Option<wgpu::SurfaceTexture>, String> {
        let texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(None),
            other => return Err(format!("canvas #{}: no texture ({other:?})", self.id)),
        };
        copy_packed_to_texture(encoder, buffer, row_stride_px, self.size_px, &texture.texture).map_err(|e| format!("canvas #{}: {e}", self.id))?;
        Ok(Some(texture))
    }

    /// Shows textures drawn into by a submitted encoder.
    pub(crate) fn present(gpu: &Gpu, textures: impl IntoIterator<Item = Option<wgpu::SurfaceTexture>>) {
        for texture in textures.into_iter().flatten() {
            gpu.queue.present(texture);
        }
    }
}
