//! How the viewer's pixels reach its window: through a wgpu surface on the
//! device that renders (the GPU backend), or a software framebuffer
//! (softbuffer) on the CPU backend, or when the device's surface cannot be
//! made.

use anyhow::{anyhow, bail, Result};
use std::num::NonZeroU32;
use std::sync::Arc;
use winit::window::Window;

pub enum Presenter {
    Software(softbuffer::Surface<Arc<Window>, Arc<Window>>),
    Device(Box<DeviceSurface>),
}

pub struct DeviceSurface {
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    format: wgpu::TextureFormat,
    alpha: wgpu::CompositeAlphaMode,
    /// The size the surface is configured for (none yet, or lost).
    configured: Option<(u32, u32)>,
    bytes: Vec<u8>,
}

impl Presenter {
    pub fn software(window: &Arc<Window>) -> Result<Presenter> {
        let context = softbuffer::Context::new(window.clone()).map_err(|e| anyhow!("softbuffer: {e}"))?;
        let surface = softbuffer::Surface::new(&context, window.clone()).map_err(|e| anyhow!("softbuffer: {e}"))?;
        Ok(Presenter::Software(surface))
    }

    /// A surface on the rendering device. The image is already tone-mapped
    /// and sRGB-encoded, so it is copied in as bytes (a copy does not
    /// convert, whether the format is `Unorm` or `UnormSrgb`).
    pub fn device(
        window: &Arc<Window>,
        (instance, adapter, device, queue): (wgpu::Instance, wgpu::Adapter, wgpu::Device, wgpu::Queue),
    ) -> Result<Presenter> {
        let surface = instance
            .create_surface(wgpu::SurfaceTarget::DisplayAndWindow(Box::new(window.clone())))
            .map_err(|e| anyhow!("cannot make a wgpu surface for the window: {e}"))?;
        let caps = surface.get_capabilities(&adapter);
        use wgpu::TextureFormat as F;
        let Some(format) = [F::Bgra8Unorm, F::Bgra8UnormSrgb, F::Rgba8Unorm, F::Rgba8UnormSrgb]
            .into_iter()
            .find(|f| caps.formats.contains(f))
        else {
            bail!("the device's surface offers no 8-bit RGBA format (it offers {:?})", caps.formats);
        };
        if !caps.usages.contains(wgpu::TextureUsages::COPY_DST) {
            bail!("the device's surface cannot be copied to (its usages: {:?})", caps.usages);
        }
        let alpha = if caps.alpha_modes.contains(&wgpu::CompositeAlphaMode::Opaque) {
            wgpu::CompositeAlphaMode::Opaque
        } else {
            caps.alpha_modes.first().copied().unwrap_or(wgpu::CompositeAlphaMode::Auto)
        };
        Ok(Presenter::Device(Box::new(DeviceSurface {
            surface,
            device,
            queue,
            format,
            alpha,
            configured: None,
            bytes: Vec::new(),
        })))
    }

    pub fn describe(&self) -> String {
        match self {
            Presenter::Software(_) => "a software framebuffer".into(),
            Presenter::Device(d) => format!("the device's wgpu surface ({:?})", d.format),
        }
    }

    /// Shows `pixels` (0x00RRGGBB, `width` x `height`, the window's size).
    pub fn present(&mut self, pixels: &[u32], width: u32, height: u32) -> Result<()> {
        let (Some(w), Some(h)) = (NonZeroU32::new(width), NonZeroU32::new(height)) else {
            return Ok(()); // minimised
        };
        match self {
            Presenter::Software(surface) => {
                surface.resize(w, h).map_err(|e| anyhow!("{e}"))?;
                let mut buffer = surface.buffer_mut().map_err(|e| anyhow!("{e}"))?;
                buffer.copy_from_slice(pixels);
                buffer.present().map_err(|e| anyhow!("{e}"))
            }
            Presenter::Device(d) => d.present(pixels, width, height),
        }
    }
}

impl DeviceSurface {
    fn present(&mut self, pixels: &[u32], width: u32, height: u32) -> Result<()> {
        if self.configured != Some((width, height)) {
            self.surface.configure(
                &self.device,
                &wgpu::SurfaceConfiguration {
                    usage: wgpu::TextureUsages::COPY_DST,
                    format: self.format,
                    width,
                    height,
                    present_mode: wgpu::PresentMode::AutoVsync,
                    desired_maximum_frame_latency: 2,
                    alpha_mode: self.alpha,
                    view_formats: Vec::new(),
                    // sRGB, standard dynamic range: what the PNG holds.
                    color_space: wgpu::SurfaceColorSpace::Auto,
                },
            );
            self.configured = Some((width, height));
        }
        let texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) => t,
            wgpu::CurrentSurfaceTexture::Suboptimal(t) => {
                self.configured = None; // configure again next time
                t
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(()),
            other => {
                self.configured = None;
                bail!("the surface's texture: {}", surface_status(&other));
            }
        };
        let bgra = matches!(self.format, wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb);
        self.bytes.clear();
        self.bytes.extend(pixels.iter().flat_map(|p| {
            let [b, g, r, _] = p.to_le_bytes();
            if bgra {
                [b, g, r, 255]
            } else {
                [r, g, b, 255]
            }
        }));
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture.texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            &self.bytes,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(4 * width), rows_per_image: Some(height) },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        );
        self.queue.submit([]);
        self.queue.present(texture);
        Ok(())
    }
}

fn surface_status(s: &wgpu::CurrentSurfaceTexture) -> &'static str {
    match s {
        wgpu::CurrentSurfaceTexture::Outdated => "outdated",
        wgpu::CurrentSurfaceTexture::Lost => "lost",
        _ => "not available",
    }
}
