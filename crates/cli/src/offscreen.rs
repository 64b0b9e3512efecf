//! Rendering frames without a window (`globus render`, `globus bench`, tests).

use std::time::{Duration, Instant};

use globus_geo::View;
use globus_render::{GpuContext, OffscreenTarget, RgbaImage};

use crate::engine::{FrameReport, Globe, GlobeOptions};

/// A GPU context, a globe and an offscreen target.
pub struct Offscreen {
    /// The device.
    pub ctx: GpuContext,
    /// The globe.
    pub globe: Globe,
    /// The target.
    pub target: OffscreenTarget,
}

/// One complete frame and how it was made.
pub struct RenderedFrame {
    /// The pixels (alpha: 255 terrain, 0 background).
    pub image: RgbaImage,
    /// The final frame's report.
    pub report: FrameReport,
    /// Milliseconds spent waiting for tiles to load and upload.
    pub load_ms: f64,
    /// Whether every wanted tile was loaded before the timeout.
    pub complete: bool,
}

impl Offscreen {
    /// A headless context and a `width` x `height` target.
    pub fn new(options: &GlobeOptions, width: u32, height: u32) -> anyhow::Result<Self> {
        // Sources first: one that cannot be opened fails before a GPU context exists.
        let source = crate::engine::terrain_source(options)?;
        Self::with_source(options, source, width, height)
    }

    /// Like [`Offscreen::new`], over a terrain source opened beforehand (tests wrap sources).
    pub fn with_source(
        options: &GlobeOptions,
        source: std::sync::Arc<dyn globus_stream::TerrainSource>,
        width: u32,
        height: u32,
    ) -> anyhow::Result<Self> {
        let ctx = GpuContext::headless()?;
        // The target first: a memory budget counts it in the process's footprint.
        let target = OffscreenTarget::new(&ctx.device, width, height);
        let globe = Globe::with_source(&ctx.device, OffscreenTarget::FORMAT, options, source)?;
        Ok(Self { ctx, globe, target })
    }

    /// Loads everything `view` needs (up to `timeout`), then renders and reads back.
    pub fn render_complete(
        &mut self,
        view: &View,
        timeout: Duration,
    ) -> anyhow::Result<RenderedFrame> {
        let started = Instant::now();
        let (_, complete) =
            self.globe
                .load_completely(&self.ctx.device, &self.ctx.queue, view, timeout);
        let load_ms = started.elapsed().as_secs_f64() * 1e3;
        // A final frame on the complete data, timed on its own.
        let report = self.globe.frame(&self.ctx.device, &self.ctx.queue, view);
        let image = self.draw_and_read()?;
        Ok(RenderedFrame {
            image,
            report,
            load_ms,
            complete,
        })
    }

    /// Draws the frame prepared last and waits for the GPU (no readback).
    pub fn draw(&self) {
        let mut encoder = self
            .ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        self.globe.render(
            &mut encoder,
            &self.target.colour_view,
            &self.target.depth.view,
        );
        self.ctx.queue.submit([encoder.finish()]);
        let _ = self.ctx.device.poll(wgpu::PollType::wait_indefinitely());
    }

    /// Draws the frame prepared last and reads it back.
    pub fn draw_and_read(&self) -> anyhow::Result<RgbaImage> {
        self.draw();
        Ok(self.target.read_back(&self.ctx.device, &self.ctx.queue)?)
    }
}

/// Writes an image as PNG with alpha forced opaque.
pub fn save_png(image: &RgbaImage, path: &std::path::Path) -> anyhow::Result<()> {
    let mut px = image.pixels.clone();
    px.chunks_exact_mut(4).for_each(|p| p[3] = 255);
    image::save_buffer(
        path,
        &px,
        image.width,
        image.height,
        image::ColorType::Rgba8,
    )
    .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
}

/// Pixels whose centre ray hits `body`, and how many of those show no terrain (alpha below
/// 255): the holes a viewer would see inside the planet's silhouette.
pub fn holes_inside(img: &RgbaImage, view: &View, body: &globus_geo::Ellipsoid) -> (u32, u32) {
    let (mut inside, mut holes) = (0, 0);
    for y in 0..img.height {
        for x in 0..img.width {
            let dir = view.ray_direction(f64::from(x) + 0.5, f64::from(y) + 0.5);
            if body.ray_hit(view.position, dir).is_some() {
                inside += 1;
                if img.pixels[((y * img.width + x) * 4 + 3) as usize] != 255 {
                    holes += 1;
                }
            }
        }
    }
    (inside, holes)
}
