// SPDX-License-Identifier: MIT
//! Views: images colour-mapped on the GPU (`view/` kernels, one shared colour map) into
//! buffers that copy straight into an `Rgba8Unorm` texture, a browser canvas's included. No
//! pixel goes through the host.

use crate::kernels::depth_colormap::{self, DepthColormapParams};
use crate::kernels::label_colormap::{self, LabelColormapParams};
use crate::kernels::normal_colormap::{self, NormalColormapParams};
use crate::{Error, Gpu, Result};

/// Depth drawn at the warm end of the depth colour map, metres (a Kinect's useful range).
pub const DEFAULT_DEPTH_VIEW_MAX_M: f32 = 4.5;
/// Row stride of view buffers, pixels: a copy into a texture needs rows a multiple of
/// `wgpu::COPY_BYTES_PER_ROW_ALIGNMENT` (256 bytes, 64 RGBA8 pixels) apart.
pub const ROW_ALIGN_PX: u32 = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT / 4;

/// An RGBA8 image in a storage buffer (red in the low byte of each u32), rows
/// [`Self::row_stride_px`] apart.
#[derive(Debug)]
pub struct ViewImage {
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Pixels from one row to the next (`width_px` rounded up to [`ROW_ALIGN_PX`]).
    pub row_stride_px: u32,
    /// The pixels.
    pub rgba8: wgpu::Buffer,
}

impl ViewImage {
    /// An image of `width_px` × `height_px` pixels with aligned rows.
    pub fn new(gpu: &Gpu, label: &str, width_px: u32, height_px: u32) -> Self {
        let row_stride_px = width_px.next_multiple_of(ROW_ALIGN_PX);
        let rgba8 = gpu.storage_buffer::<u32>(label, (row_stride_px * height_px) as usize);
        Self { width_px, height_px, row_stride_px, rgba8 }
    }

    /// Records a copy of the image into `texture` (`Rgba8Unorm`, the image's size, `COPY_DST`).
    pub fn copy_to_texture(&self, encoder: &mut wgpu::CommandEncoder, texture: &wgpu::Texture) -> Result<()> {
        copy_packed_to_texture(encoder, &self.rgba8, self.row_stride_px, [self.width_px, self.height_px], texture)
    }
}

/// Records a copy of packed RGBA8 pixels (rows `row_stride_px` apart, a multiple of
/// [`ROW_ALIGN_PX`]) into `texture`, which must have `size_px` and the `Rgba8Unorm` format.
pub fn copy_packed_to_texture(encoder: &mut wgpu::CommandEncoder, buffer: &wgpu::Buffer, row_stride_px: u32, size_px: [u32; 2], texture: &wgpu::Texture) -> Result<()> {
    if texture.format() != wgpu::TextureFormat::Rgba8Unorm || texture.width() != size_px[0] || texture.height() != size_px[1] {
        return Err(Error::InvalidConfig(format!(
            "a {}x{} RGBA8 view cannot be copied into a {}x{} {:?} texture",
            size_px[0],
            size_px[1],
            texture.width(),
            texture.height(),
            texture.format()
        )));
    }
    if !row_stride_px.is_multiple_of(ROW_ALIGN_PX) || row_stride_px < size_px[0] {
        return Err(Error::InvalidConfig(format!("rows {row_stride_px} px apart cannot be copied into a texture (a multiple of {ROW_ALIGN_PX} px, at least the width {})", size_px[0])));
    }
    encoder.copy_buffer_to_texture(
        wgpu::TexelCopyBufferInfo { buffer, layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(4 * row_stride_px), rows_per_image: Some(size_px[1]) } },
        texture.as_image_copy(),
        wgpu::Extent3d { width: size_px[0], height: size_px[1], depth_or_array_layers: 1 },
    );
    Ok(())
}

/// A raw depth image (sensor units, as uploaded) through the depth colour map.
#[derive(Debug)]
pub struct DepthView {
    /// The coloured image.
    pub image: ViewImage,
    bind_group: wgpu::BindGroup,
}

impl DepthView {
    /// Colours `depth_raw` (`width_px` × `height_px` u16, two per word) at `metres_per_unit`,
    /// `max_depth_m` at the warm end.
    pub fn new(gpu: &Gpu, depth_raw: &wgpu::Buffer, size_px: [u32; 2], metres_per_unit: f32, max_depth_m: f32) -> Self {
        let image = ViewImage::new(gpu, "core.view.depth", size_px[0], size_px[1]);
        let params = DepthColormapParams { width_px: size_px[0], height_px: size_px[1], row_stride_px: image.row_stride_px, metres_per_unit, max_depth_m, ..Default::default() };
        let params = gpu.uniform_buffer("core.view.depth.params", &params);
        let bind_group = depth_colormap::Bindings { params: &params, depth_raw, rgba8: &image.rgba8 }.bind_group(gpu);
        Self { image, bind_group }
    }

    /// Records the colouring.
    pub fn dispatch_in(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        gpu.kernels.depth_colormap.dispatch_in(pass, &self.bind_group, [self.image.width_px, self.image.height_px, 1]);
    }
}

/// Plane labels over the frame's colour (seed 003's segmentation view).
#[derive(Debug)]
pub struct LabelView {
    /// The coloured image.
    pub image: ViewImage,
    bind_group: wgpu::BindGroup,
}

impl LabelView {
    /// Colours `labels` (`width_px` × `height_px` u32, [`crate::planes::NO_LABEL`] = none,
    /// planes below [`crate::planes::MAX_PLANES`]) over `color` (vec4 per pixel).
    pub fn new(gpu: &Gpu, label: &str, labels: &wgpu::Buffer, color: &wgpu::Buffer, size_px: [u32; 2]) -> Self {
        let image = ViewImage::new(gpu, label, size_px[0], size_px[1]);
        let params = LabelColormapParams { width_px: size_px[0], height_px: size_px[1], row_stride_px: image.row_stride_px, label_count: crate::planes::MAX_PLANES as u32 };
        let params = gpu.uniform_buffer(&format!("{label}.params"), &params);
        let bind_group = label_colormap::Bindings { params: &params, labels, color, rgba8: &image.rgba8 }.bind_group(gpu);
        Self { image, bind_group }
    }

    /// Records the colouring.
    pub fn dispatch_in(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        gpu.kernels.label_colormap.dispatch_in(pass, &self.bind_group, [self.image.width_px, self.image.height_px, 1]);
    }
}

/// A normal map through the normal colour map.
#[derive(Debug)]
pub struct NormalView {
    /// The coloured image.
    pub image: ViewImage,
    bind_group: wgpu::BindGroup,
}

impl NormalView {
    /// Colours `normals` (`width_px` × `height_px` vec4, NaN = none).
    pub fn new(gpu: &Gpu, label: &str, normals: &wgpu::Buffer, size_px: [u32; 2]) -> Self {
        let image = ViewImage::new(gpu, label, size_px[0], size_px[1]);
        let params = NormalColormapParams { width_px: size_px[0], height_px: size_px[1], row_stride_px: image.row_stride_px, ..Default::default() };
        let params = gpu.uniform_buffer(&format!("{label}.params"), &params);
        let bind_group = normal_colormap::Bindings { params: &params, normals, rgba8: &image.rgba8 }.bind_group(gpu);
        Self { image, bind_group }
    }

    /// Records the colouring.
    pub fn dispatch_in(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        gpu.kernels.normal_colormap.dispatch_in(pass, &self.bind_group, [self.image.width_px, self.image.height_px, 1]);
    }
}
