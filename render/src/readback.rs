//! Reading a rendered frame back to the CPU (sRGB-encoded RGBA8): pictures, PNG frames and
//! the window's software framebuffer. A page never calls it: mapping means waiting for the GPU.

use crate::{RenderError, Renderer, extent};
use std::sync::mpsc;

impl Renderer {
    /// Copies the last rendered frame back to the CPU (sRGB-encoded RGBA8).
    pub fn read_pixels(&mut self) -> Result<image::RgbaImage, RenderError> {
        if !self.has_frame {
            return Err(RenderError::NoFrame);
        }
        self.copy_to_readback();
        let bytes = self.map_readback()?;
        image::RgbaImage::from_raw(self.width, self.height, bytes)
            .ok_or_else(|| RenderError::Readback("pixel buffer has the wrong size".into()))
    }

    fn copy_to_readback(&self) {
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.targets.color,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &self.targets.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.targets.padded_row),
                    rows_per_image: Some(self.height),
                },
            },
            extent(self.width, self.height),
        );
        self.queue.submit([encoder.finish()]);
    }

    /// Maps the readback buffer and returns the pixels without the row padding.
    fn map_readback(&self) -> Result<Vec<u8>, RenderError> {
        let slice = self.targets.readback.slice(..);
        let (tx, rx) = mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        rx.recv()
            .map_err(|e| RenderError::Readback(e.to_string()))?
            .map_err(|e| RenderError::Readback(e.to_string()))?;
        let pixels = {
            let mapped = slice
                .get_mapped_range()
                .map_err(|e| RenderError::Readback(e.to_string()))?;
            strip_padding(&mapped, self.targets.padded_row, self.width * 4)
        };
        self.targets.readback.unmap();
        Ok(pixels)
    }
}

/// Copies the first `row` bytes of each `padded`-byte row.
fn strip_padding(bytes: &[u8], padded: u32, row: u32) -> Vec<u8> {
    bytes
        .chunks(padded as usize)
        .flat_map(|r| &r[..(row as usize).min(r.len())])
        .copied()
        .collect()
}
