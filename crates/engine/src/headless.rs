//! [`Headless`]: a globe rendering without a window (`globus render`, `globus bench`,
//! tests, server-side pictures), read back as RGBA.

use std::time::{Duration, Instant};

use globus_geo::{Ellipsoid, View};
use globus_render::{GpuContext, OffscreenTarget, RgbaImage};

use crate::overlay::Overlay;
use crate::{EngineError, FrameReport, Globe, GlobeBuilder};

/// A GPU context without a window, a globe and an offscreen colour target.
pub struct Headless {
    gpu: GpuContext,
    globe: Globe,
    target: OffscreenTarget,
}

/// One complete frame and how it was made.
pub struct RenderedFrame {
    /// The pixels (alpha: 255 where terrain or an opaque overlay was drawn, 0 background).
    pub image: RgbaImage,
    /// The final frame's report.
    pub report: FrameReport,
    /// Milliseconds spent waiting for tiles to load and upload.
    pub load_ms: f64,
    /// Whether every wanted tile was loaded before the timeout.
    pub complete: bool,
}

impl Headless {
    /// The best adapter there is (a GPU, else a software rasteriser such as lavapipe), the
    /// globe `builder` describes and a `width` x `height` target.
    pub fn new(builder: &GlobeBuilder, width: u32, height: u32) -> Result<Self, EngineError> {
        // Sources first: one that cannot be opened fails before a GPU context exists.
        let mut builder = builder.clone();
        builder.open_sources()?.viewport(width, height);
        let gpu = GpuContext::headless()?;
        let largest = gpu.device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 || width > largest || height > largest {
            return Err(EngineError::FrameSize {
                width,
                height,
                largest,
            });
        }
        // The target before the globe: a memory budget counts it in the process's footprint.
        let target = OffscreenTarget::new(&gpu.device, width, height);
        let globe = builder.build(&gpu, OffscreenTarget::FORMAT)?;
        Ok(Self { gpu, globe, target })
    }

    /// The globe.
    pub fn globe(&self) -> &Globe {
        &self.globe
    }

    /// The globe, to update and configure.
    pub fn globe_mut(&mut self) -> &mut Globe {
        &mut self.globe
    }

    /// The GPU context.
    pub fn gpu(&self) -> &GpuContext {
        &self.gpu
    }

    /// Width and height of the frames, pixels.
    pub fn size(&self) -> (u32, u32) {
        self.target.size()
    }

    /// Runs one frame's CPU work for `view` ([`Globe::update`]).
    pub fn update(&mut self, view: &View) -> FrameReport {
        self.globe.update(view)
    }

    /// Loads everything `view` needs (up to `timeout`), then renders with `overlays` and
    /// reads the picture back.
    pub fn render_complete(
        &mut self,
        view: &View,
        timeout: Duration,
        overlays: &mut [&mut dyn Overlay],
    ) -> Result<RenderedFrame, EngineError> {
        self.render_complete_reporting(view, timeout, overlays, &mut |_| {})
    }

    /// [`Headless::render_complete`], handing the report of every frame it waits through to
    /// `on_frame` (for a progress display).
    pub fn render_complete_reporting(
        &mut self,
        view: &View,
        timeout: Duration,
        overlays: &mut [&mut dyn Overlay],
        on_frame: &mut dyn FnMut(&FrameReport),
    ) -> Result<RenderedFrame, EngineError> {
        let started = Instant::now();
        let (_, complete) = self
            .globe
            .load_completely_reporting(view, timeout, on_frame);
        let load_ms = started.elapsed().as_secs_f64() * 1e3;
        // A final frame on the complete data, timed on its own.
        let report = self.globe.update_settled(view);
        let image = self.draw_and_read(overlays)?;
        Ok(RenderedFrame {
            image,
            report,
            load_ms,
            complete,
        })
    }

    /// Draws the frame prepared last and waits for the GPU (no readback).
    pub fn draw(&mut self, overlays: &mut [&mut dyn Overlay]) {
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        self.globe
            .render(&mut encoder, self.target.view(), overlays);
        self.gpu.queue.submit([encoder.finish()]);
        let _ = self.gpu.device.poll(wgpu::PollType::wait_indefinitely());
    }

    /// Submits the uploads of the frame prepared last without drawing it.
    pub fn submit_uploads(&self) {
        self.gpu.queue.submit([]);
    }

    /// Draws the frame prepared last and reads it back.
    pub fn draw_and_read(
        &mut self,
        overlays: &mut [&mut dyn Overlay],
    ) -> Result<RgbaImage, EngineError> {
        self.draw(overlays);
        Ok(self.target.read_back(&self.gpu.device, &self.gpu.queue)?)
    }
}

/// Writes an image as PNG with alpha forced opaque, whole or not at all (a failed write leaves
/// an existing file as it was).
pub fn save_png(image: &RgbaImage, path: &std::path::Path) -> Result<(), std::io::Error> {
    use image::ImageEncoder;
    let mut px = image.pixels.clone();
    px.chunks_exact_mut(4).for_each(|p| p[3] = 255);
    let mut png = Vec::new();
    let cannot = |e: &dyn std::fmt::Display| {
        std::io::Error::other(format!("cannot write {}: {e}", path.display()))
    };
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(
            &px,
            image.width,
            image.height,
            image::ExtendedColorType::Rgba8,
        )
        .map_err(|e| cannot(&e))?;
    globus_tiling::files::write_atomic(path, &png).map_err(|e| cannot(&e))
}

/// How much one frame differs from the frame before, as popping is measured: the mean
/// absolute change of the colour channels (0..255) over all pixels, and the share of pixels
/// whose largest channel change exceeds `threshold`. `None` for frames of different sizes.
pub fn frame_change(before: &RgbaImage, after: &RgbaImage, threshold: u8) -> Option<FrameChange> {
    if (before.width, before.height) != (after.width, after.height) || before.pixels.is_empty() {
        return None;
    }
    let (mut sum, mut changed) = (0u64, 0u64);
    for (p, q) in before
        .pixels
        .chunks_exact(4)
        .zip(after.pixels.chunks_exact(4))
    {
        let d = [0, 1, 2].map(|k| p[k].abs_diff(q[k]));
        sum += u64::from(d[0]) + u64::from(d[1]) + u64::from(d[2]);
        changed += u64::from(d[0].max(d[1]).max(d[2]) > threshold);
    }
    let n = (before.pixels.len() / 4) as f64;
    Some(FrameChange {
        mean_abs: sum as f64 / (3.0 * n),
        changed_share: changed as f64 / n,
    })
}

/// One frame of [`Headless::sweep`].
#[derive(Clone, Debug, PartialEq)]
pub struct SweepFrame {
    /// The error bound it was drawn with, pixels.
    pub sse_bound_px: f64,
    /// Tiles drawn.
    pub tiles: u32,
    /// The deepest level drawn.
    pub max_level: u8,
    /// How the picture changed from the frame before (`None` for the first).
    pub change: Option<FrameChange>,
}

/// What [`Headless::sweep`] measured: each frame's change, and the change from the first
/// frame to the last.
#[derive(Clone, Debug, PartialEq)]
pub struct Sweep {
    /// Per frame, in order.
    pub frames: Vec<SweepFrame>,
    /// The last frame against the first (`None` with fewer than two frames): what the sweep
    /// changed in all. The frames' changes add up to at least this much (the triangle
    /// inequality, pixel by pixel); what they add beyond it went back and forth on the way.
    pub net: Option<FrameChange>,
}

impl Sweep {
    /// The frames' mean absolute changes added up (of 255): at least [`Sweep::net`]'s, and
    /// the frames' largest change is at least this over the number of changes.
    pub fn total_mean_abs(&self) -> f64 {
        self.frames
            .iter()
            .filter_map(|f| f.change.map(|c| c.mean_abs))
            .sum()
    }
}

impl Headless {
    /// The popping measurement (issue 20): draws `frames` (a view and the error bound to
    /// draw it with) in order, each loaded completely before it is drawn (within `timeout`),
    /// and compares each picture with the one before; a channel change above `visible` (of
    /// 255) counts as visible. With the camera still and the bound falling, all that changes
    /// is what the finer bound split; along a slow path, motion adds its own change. Fails if
    /// a frame does not finish loading.
    pub fn sweep(
        &mut self,
        frames: &[(View, f64)],
        visible: u8,
        timeout: Duration,
    ) -> Result<Sweep, EngineError> {
        self.sweep_each(frames, visible, timeout, |_, _| {})
    }

    /// [`Headless::sweep`], handing each picture to `each` with its number as it is drawn
    /// (to write the frames out and look at them).
    pub fn sweep_each(
        &mut self,
        frames: &[(View, f64)],
        visible: u8,
        timeout: Duration,
        mut each: impl FnMut(u32, &RgbaImage),
    ) -> Result<Sweep, EngineError> {
        let mut out = Vec::with_capacity(frames.len());
        let mut first: Option<RgbaImage> = None;
        let mut before: Option<RgbaImage> = None;
        for (step, (view, bound)) in frames.iter().enumerate() {
            self.globe.set_error_bound_px(*bound)?;
            let frame = self.render_complete(view, timeout, &mut [])?;
            if !frame.complete {
                return Err(EngineError::Incomplete {
                    what: "the popping sweep",
                    frame: step as u32,
                    timeout,
                });
            }
            each(step as u32, &frame.image);
            out.push(SweepFrame {
                sse_bound_px: frame.report.sse_bound_px,
                tiles: frame.report.selection.selected,
                max_level: frame.report.selection.max_level,
                change: before
                    .as_ref()
                    .and_then(|b| frame_change(b, &frame.image, visible)),
            });
            if first.is_none() {
                first = Some(frame.image.clone());
            }
            before = Some(frame.image);
        }
        let net = match (&first, &before) {
            (Some(a), Some(b)) if out.len() > 1 => frame_change(a, b, visible),
            _ => None,
        };
        Ok(Sweep { frames: out, net })
    }
}

/// `steps + 1` values from `from` to `to`, geometrically (equal ratios between neighbours).
pub fn geometric_steps(from: f64, to: f64, steps: u32) -> Vec<f64> {
    (0..=steps)
        .map(|k| from * (to / from).powf(f64::from(k) / f64::from(steps.max(1))))
        .collect()
}

/// See [`frame_change`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameChange {
    /// Mean absolute change of a colour channel, 0..255.
    pub mean_abs: f64,
    /// Share of pixels with a channel changed by more than the threshold, 0..1.
    pub changed_share: f64,
}

/// Pixels whose centre ray hits `body`, and how many of those show no terrain (alpha below
/// 255): the holes a viewer would see inside the planet's silhouette.
pub fn holes_inside(img: &RgbaImage, view: &View, body: &Ellipsoid) -> (u32, u32) {
    let (mut inside, mut holes) = (0, 0);
    for y in 0..img.height {
        for x in 0..img.width {
            let (origin, dir) = view.ray(f64::from(x) + 0.5, f64::from(y) + 0.5);
            if body.ray_hit(origin, dir).is_some() {
                inside += 1;
                if img.pixels[((y * img.width + x) * 4 + 3) as usize] != 255 {
                    holes += 1;
                }
            }
        }
    }
    (inside, holes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_change_counts_channels_and_pixels() {
        let image = |pixels: Vec<u8>| RgbaImage {
            width: 2,
            height: 1,
            pixels,
        };
        let a = image(vec![10, 10, 10, 255, 100, 100, 100, 255]);
        // The first pixel moves by 9 in one channel (over a threshold of 8), the second by 3
        // in each; alpha is not colour.
        let b = image(vec![19, 10, 10, 0, 103, 103, 103, 255]);
        let c = frame_change(&a, &b, 8).expect("same size");
        assert!((c.mean_abs - 18.0 / 6.0).abs() < 1e-12, "{c:?}");
        assert_eq!(c.changed_share, 0.5);
        assert_eq!(frame_change(&a, &a, 8).map(|c| c.mean_abs), Some(0.0));
        let other = RgbaImage {
            width: 1,
            height: 2,
            pixels: a.pixels.clone(),
        };
        assert!(frame_change(&a, &other, 8).is_none());
    }
}
