//! `globus view`: a window on the planet with globe camera controls.
//!
//! * Left drag: rotates the globe so the grabbed point stays under the cursor.
//! * Wheel: zooms towards the point under the cursor, by a fifth of the height above ground
//!   per notch (never below 1 m above the ground).
//! * Right drag: turns (horizontal) and tilts (vertical) the camera where it stands.
//! * W/A/S/D fly forward/left/back/right, Q/E down/up, at a speed proportional to the height
//!   above ground; Esc quits.
//!
//! The title shows frames per second, tiles drawn and tiles loading.

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, anyhow, bail};
use globus_geo::{DQuat, DVec3, View};
use globus_render::{DepthTarget, GpuContext};
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, KeyEvent, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::engine::{CameraSpec, Globe, GlobeOptions};

/// Settings of the viewer.
#[derive(Clone, Debug)]
pub struct ViewerOptions {
    /// The globe.
    pub globe: GlobeOptions,
    /// Where the camera starts.
    pub camera: CameraSpec,
    /// Vertical field of view, degrees.
    pub fov_deg: f64,
    /// Initial window size.
    pub width: u32,
    /// Initial window size.
    pub height: u32,
    /// Close the window after this long (for automated checks).
    pub exit_after: Option<Duration>,
}

/// Opens the window and runs until it is closed.
pub fn run(options: ViewerOptions) -> anyhow::Result<()> {
    if cfg!(target_os = "linux")
        && std::env::var_os("DISPLAY").is_none()
        && std::env::var_os("WAYLAND_DISPLAY").is_none()
    {
        bail!(
            "no display to open a window on (neither DISPLAY nor WAYLAND_DISPLAY is set); use `globus render` to draw a frame offscreen"
        );
    }
    let event_loop = EventLoop::new().map_err(|e| {
        anyhow!("cannot open a window ({e}); use `globus render` to draw a frame offscreen")
    })?;
    // Sources first: one that cannot be opened fails before a window opens.
    let source = crate::engine::terrain_source(&options.globe)?;
    let mut app = App {
        options,
        source,
        state: None,
        error: None,
        started: Instant::now(),
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| anyhow!("the window's event loop failed: {e}"))?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

struct App {
    options: ViewerOptions,
    source: Arc<dyn globus_stream::TerrainSource>,
    state: Option<State>,
    error: Option<anyhow::Error>,
    started: Instant,
}

struct State {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    ctx: GpuContext,
    globe: Globe,
    depth: DepthTarget,
    view: View,
    input: Input,
    fps: FpsCounter,
}

#[derive(Default)]
struct Input {
    cursor: PhysicalPosition<f64>,
    /// The grabbed world point and its distance from the centre, while left-dragging.
    grab: Option<(DVec3, f64)>,
    /// The cursor position when the right drag last moved.
    look: Option<PhysicalPosition<f64>>,
    keys: std::collections::HashSet<KeyCode>,
    last_tick: Option<Instant>,
}

struct FpsCounter {
    frames: u32,
    since: Instant,
    fps: f64,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.state.is_some() {
            return;
        }
        match State::new(event_loop, &self.options, Arc::clone(&self.source)) {
            Ok(s) => {
                s.window.request_redraw();
                self.state = Some(s);
            }
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(state) = self.state.as_mut() else {
            return;
        };
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::KeyboardInput {
                event:
                    KeyEvent {
                        physical_key: PhysicalKey::Code(code),
                        state: key_state,
                        ..
                    },
                ..
            } => {
                if code == KeyCode::Escape {
                    event_loop.exit();
                } else if key_state == ElementState::Pressed {
                    state.input.keys.insert(code);
                } else {
                    state.input.keys.remove(&code);
                }
            }
            WindowEvent::Resized(size) => state.resize(size),
            WindowEvent::CursorMoved { position, .. } => state.cursor_moved(position),
            WindowEvent::MouseInput {
                state: s, button, ..
            } => state.mouse_button(button, s == ElementState::Pressed),
            WindowEvent::MouseWheel { delta, .. } => {
                let notches = match delta {
                    MouseScrollDelta::LineDelta(_, y) => f64::from(y),
                    MouseScrollDelta::PixelDelta(p) => p.y / 60.0,
                };
                state.zoom(notches);
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = state.redraw() {
                    self.error = Some(e);
                    event_loop.exit();
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        if let Some(limit) = self.options.exit_after
            && self.started.elapsed() >= limit
        {
            event_loop.exit();
            return;
        }
        event_loop.set_control_flow(ControlFlow::Poll);
        if let Some(s) = &self.state {
            s.window.request_redraw();
        }
    }
}

impl State {
    fn new(
        event_loop: &ActiveEventLoop,
        options: &ViewerOptions,
        source: Arc<dyn globus_stream::TerrainSource>,
    ) -> anyhow::Result<Self> {
        let attributes = Window::default_attributes()
            .with_title("Globus")
            .with_inner_size(PhysicalSize::new(options.width, options.height));
        let window = Arc::new(
            event_loop
                .create_window(attributes)
                .context("cannot create a window")?,
        );
        let instance = wgpu::Instance::new(
            wgpu::InstanceDescriptor::new_with_display_handle(Box::new(
                event_loop.owned_display_handle(),
            ))
            .with_env(),
        );
        let surface = instance
            .create_surface(Arc::clone(&window))
            .map_err(|e| anyhow!("cannot draw into the window: {e}"))?;
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            compatible_surface: Some(&surface),
            ..Default::default()
        }))
        .map_err(|e| anyhow!("no graphics adapter can draw into the window: {e}"))?;
        let ctx = GpuContext::with_adapter(instance, adapter)?;
        let size = window.inner_size();
        let caps = surface.get_capabilities(&ctx.adapter);
        let format = caps
            .formats
            .iter()
            .copied()
            .find(wgpu::TextureFormat::is_srgb)
            .or_else(|| caps.formats.first().copied())
            .context("the window surface offers no pixel format")?;
        let config = surface
            .get_default_config(&ctx.adapter, size.width.max(1), size.height.max(1))
            .map(|c| wgpu::SurfaceConfiguration {
                format,
                present_mode: wgpu::PresentMode::AutoVsync,
                ..c
            })
            .context("the window surface is not supported by the adapter")?;
        surface.configure(&ctx.device, &config);
        let globe = Globe::with_source(&ctx.device, format, &options.globe, source)?;
        let view = options
            .camera
            .view(&globe, options.fov_deg, config.width, config.height);
        let depth = DepthTarget::new(&ctx.device, config.width, config.height);
        Ok(Self {
            window,
            surface,
            config,
            ctx,
            globe,
            depth,
            view,
            input: Input::default(),
            fps: FpsCounter {
                frames: 0,
                since: Instant::now(),
                fps: 0.0,
            },
        })
    }

    fn resize(&mut self, size: PhysicalSize<u32>) {
        if size.width == 0 || size.height == 0 {
            return;
        }
        self.config.width = size.width;
        self.config.height = size.height;
        self.surface.configure(&self.ctx.device, &self.config);
        self.depth = DepthTarget::new(&self.ctx.device, size.width, size.height);
        self.view.width_px = size.width;
        self.view.height_px = size.height;
    }

    /// Height of the eye above the ground, metres.
    fn height_above_ground(&self) -> f64 {
        let e = self.globe.ellipsoid();
        let c = e
            .ecef_to_cartographic(self.view.position)
            .unwrap_or_default();
        c.height_m - self.globe.ground_height_m(c.lon_rad, c.lat_rad)
    }

    /// The surface point under a pixel: the ellipsoid hit raised to the ground there.
    fn pick(&self, x: f64, y: f64) -> Option<DVec3> {
        let e = self.globe.ellipsoid();
        let dir = self.view.ray_direction(x, y);
        let hit = e.ray_hit(self.view.position, dir)?;
        let c = e.ecef_to_cartographic(hit)?;
        let ground = self.globe.ground_height_m(c.lon_rad, c.lat_rad);
        let raised = e.grown(ground.max(0.0));
        raised.ray_hit(self.view.position, dir).or(Some(hit))
    }

    fn mouse_button(&mut self, button: MouseButton, pressed: bool) {
        let (x, y) = (self.input.cursor.x, self.input.cursor.y);
        match (button, pressed) {
            (MouseButton::Left, true) => {
                self.input.grab = self.pick(x, y).map(|p| (p, p.length()));
            }
            (MouseButton::Left, false) => self.input.grab = None,
            (MouseButton::Right, true) => self.input.look = Some(self.input.cursor),
            (MouseButton::Right, false) => self.input.look = None,
            _ => {}
        }
    }

    fn cursor_moved(&mut self, position: PhysicalPosition<f64>) {
        self.input.cursor = position;
        if let Some((grabbed, radius)) = self.input.grab {
            let dir = self.view.ray_direction(position.x, position.y);
            if let Some((t, _)) =
                globus_geo::Ellipsoid::sphere(radius).intersect_ray(self.view.position, dir)
                && t > 0.0
            {
                let under_cursor = self.view.position + dir * t;
                // Rotate the camera about the centre so the ray through the cursor meets the
                // grabbed point again.
                let q = DQuat::from_rotation_arc(under_cursor.normalize(), grabbed.normalize());
                self.view.position = q * self.view.position;
                self.view.orientation = (q * self.view.orientation).normalize();
            }
        }
        if let Some(last) = self.input.look {
            let (dx, dy) = (position.x - last.x, position.y - last.y);
            let per_px = self.view.fov_y_rad / f64::from(self.view.height_px.max(1));
            let up = self
                .globe
                .ellipsoid()
                .geodetic_normal(self.view.position)
                .unwrap_or(DVec3::Z);
            let turn = DQuat::from_axis_angle(up, -dx * per_px);
            let right = self.view.right();
            let tilt = DQuat::from_axis_angle(right, -dy * per_px);
            let candidate = (turn * tilt * self.view.orientation).normalize();
            // Keep the horizon level-ish: refuse to tilt past straight up or down.
            let forward = candidate * DVec3::NEG_Z;
            if forward.dot(up).abs() < 0.999 {
                self.view.orientation = candidate;
            } else {
                self.view.orientation = (turn * self.view.orientation).normalize();
            }
            self.input.look = Some(position);
        }
    }

    fn zoom(&mut self, notches: f64) {
        let h = self.height_above_ground().max(1.0);
        let (x, y) = (self.input.cursor.x, self.input.cursor.y);
        let target = self.pick(x, y);
        let dir = match target {
            Some(t) => (t - self.view.position).normalize_or_zero(),
            None => self.view.forward(),
        };
        let step = if notches > 0.0 {
            0.2 * h * notches.min(5.0)
        } else {
            -0.25 * h * (-notches).min(5.0)
        };
        let step = match target {
            Some(t) => step.min((t - self.view.position).length() - 1.0),
            None => step,
        };
        self.move_by(dir * step);
    }

    /// Moves the eye, keeping it at least 1 m above the ground and within 100,000 km.
    fn move_by(&mut self, delta: DVec3) {
        let e = self.globe.ellipsoid();
        let candidate = self.view.position + delta;
        let Some(mut c) = e.ecef_to_cartographic(candidate) else {
            return;
        };
        let ground = self.globe.ground_height_m(c.lon_rad, c.lat_rad);
        c.height_m = c.height_m.clamp(ground + 1.0, 1.0e8);
        let old_up = e.geodetic_normal(self.view.position).unwrap_or(DVec3::Z);
        self.view.position = e.cartographic_to_ecef(c);
        // Carry the orientation along the curve of the planet.
        let new_up = e.geodetic_normal(self.view.position).unwrap_or(DVec3::Z);
        let q = DQuat::from_rotation_arc(old_up, new_up);
        self.view.orientation = (q * self.view.orientation).normalize();
    }

    fn fly(&mut self) {
        let now = Instant::now();
        let dt = self
            .input
            .last_tick
            .map_or(0.0, |t| (now - t).as_secs_f64())
            .min(0.1);
        self.input.last_tick = Some(now);
        if self.input.keys.is_empty() || dt == 0.0 {
            return;
        }
        let speed = self.height_above_ground().max(1.0) * 1.5;
        let up = self
            .globe
            .ellipsoid()
            .geodetic_normal(self.view.position)
            .unwrap_or(DVec3::Z);
        let forward =
            (self.view.forward() - up * self.view.forward().dot(up)).normalize_or(self.view.up());
        let right = forward.cross(up);
        let mut v = DVec3::ZERO;
        for (key, dir) in [
            (KeyCode::KeyW, forward),
            (KeyCode::KeyS, -forward),
            (KeyCode::KeyD, right),
            (KeyCode::KeyA, -right),
            (KeyCode::KeyE, up),
            (KeyCode::KeyQ, -up),
        ] {
            if self.input.keys.contains(&key) {
                v += dir;
            }
        }
        self.move_by(v * speed * dt);
    }

    fn redraw(&mut self) -> anyhow::Result<()> {
        self.fly();
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.ctx.device, &self.config);
                return Ok(());
            }
            other => bail!("the window surface failed: {other:?}"),
        };
        let report = self
            .globe
            .frame(&self.ctx.device, &self.ctx.queue, &self.view);
        let target = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
        let mut encoder = self
            .ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        self.globe.render(&mut encoder, &target, &self.depth.view);
        self.ctx.queue.submit([encoder.finish()]);
        self.window.pre_present_notify();
        self.ctx.queue.present(frame);

        self.fps.frames += 1;
        let elapsed = self.fps.since.elapsed().as_secs_f64();
        if elapsed >= 0.5 {
            self.fps.fps = f64::from(self.fps.frames) / elapsed;
            self.fps.frames = 0;
            self.fps.since = Instant::now();
            self.window.set_title(&format!(
                "Globus | {:.1} fps | {} tiles drawn | {} loading | {} imagery loading | {:.0} m \
                 above ground",
                self.fps.fps,
                report.draw.tiles,
                report.wanted,
                report.colours_pending,
                self.height_above_ground()
            ));
        }
        Ok(())
    }
}
