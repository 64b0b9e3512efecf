//! `globus view`: a window on the planet, driven by the engine's [`CameraController`].
//!
//! * Left drag: pans (the grabbed point stays under the cursor).
//! * Wheel: zooms towards the point under the cursor, by a fifth of the height above ground
//!   per notch (never below 1 m above the ground).
//! * Right drag: looks around (turns and tilts the camera where it stands).
//! * Middle drag, or Ctrl + left drag: orbits the ground point under the cursor.
//! * F: flies to the point under the cursor; Home: flies back to the start.
//! * O: switches between the perspective camera and the orthographic top-down one (an ATC
//!   screen: the wheel changes the projection's size, a drag pans, right drag turns it).
//! * W/A/S/D fly forward/left/back/right, Q/E down/up, at a speed proportional to the height
//!   above ground; Esc quits.
//! * The Sun stands where it stands at `--time` (default now) and its clock runs at real
//!   speed; [ and ] move it an hour back and forward (the title shows its moment).
//!
//! With traffic (`globus traffic --record FILE`): Space pauses the replay, + and - double and
//! halve its speed, a click on an aircraft selects it (printed as one JSON line), C makes the
//! camera follow the selected aircraft (again: stop following).
//!
//! The title shows frames per second (with `--target-fps`, the target and the error bound
//! that holds it), tiles drawn and tiles loading (and the replay's moment, speed and
//! aircraft, or the Sun's moment).

use std::collections::HashSet;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, anyhow, bail};
use globus_engine::{
    CameraController, CameraSpec, DQuat, DVec3, Globe, GlobeBuilder, GpuContext, Overlay,
    VectorLayer, View,
};
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, KeyEvent, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, ModifiersState, PhysicalKey};
use winit::window::{Window, WindowId};

/// Settings of the viewer.
pub struct ViewerOptions {
    /// The globe.
    pub globe: GlobeBuilder,
    /// Where the camera starts.
    pub camera: CameraSpec,
    /// Vertical field of view, degrees.
    pub fov_deg: f64,
    /// Start with the orthographic top-down camera showing this many metres from the top to
    /// the bottom of the window.
    pub ortho_m: Option<f64>,
    /// Initial window size.
    pub width: u32,
    /// Initial window size.
    pub height: u32,
    /// Close the window after this long (for automated checks).
    pub exit_after: Option<Duration>,
    /// The vector data to draw (see [`crate::args::vector_layer`]).
    pub vectors: Option<VectorLayer>,
    /// A traffic record replayed over the globe (the Sun follows its clock).
    pub traffic: Option<ViewerTraffic>,
    /// The Sun of this moment, Unix seconds, from where its clock runs at real speed
    /// (without traffic; `None`: a fixed light from the south-west of the view).
    pub sun_time: Option<f64>,
}

/// Seconds [ and ] move the Sun's clock.
const SUN_STEP_S: f64 = 3600.0;

/// A replay shown in the viewer: its clock runs at `speed` seconds of record per second.
pub struct ViewerTraffic {
    scene: crate::traffic_cmd::Scene,
    speed: f64,
    paused: bool,
    /// The camera following an aircraft.
    follow: Option<globus_engine::Follow>,
}

impl ViewerTraffic {
    /// A replay of `scene` from its moment.
    pub fn new(scene: crate::traffic_cmd::Scene, speed: f64) -> Self {
        Self {
            scene,
            speed,
            paused: false,
            follow: None,
        }
    }

    /// Moves the clock by `dt` of wall time.
    fn tick(&mut self, dt: Duration) {
        if !self.paused {
            self.scene.time_s += dt.as_secs_f64() * self.speed;
        }
        if let Err(e) = self
            .scene
            .layer
            .play(&mut self.scene.replay, self.scene.time_s)
        {
            tracing::warn!("replay: {e}");
        }
    }

    /// The selected aircraft as one JSON line.
    fn describe(&self, id: u64) -> serde_json::Value {
        let time = self.scene.time_s;
        let state = self.scene.layer.fleet().state_of(id, time);
        let track = self.scene.replay.track_of(id);
        serde_json::json!({
            "icao24": format!("{:06x}", globus_engine::traffic::Replay::icao24_of(id)),
            "callsign": track.map(|t| t.callsign.trim()),
            "typecode": track.map(|t| t.typecode.as_str()),
            "time": crate::traffic_cmd::format_time(time),
            "lon": state.map(|s| s.0[0]),
            "lat": state.map(|s| s.0[1]),
            "altitude_m": state.map(|s| s.0[2]),
            "heading_deg": state.map(|s| s.1[0]),
        })
    }
}

/// Seconds a fly-to takes.
const FLIGHT_S: f64 = 3.0;

/// Opens the window and runs until it is closed.
pub fn run(mut options: ViewerOptions) -> anyhow::Result<()> {
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
    options.globe.open_sources()?;
    let vectors = options.vectors.take();
    let traffic = options.traffic.take();
    let mut app = App {
        vectors,
        traffic,
        options,
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
    vectors: Option<VectorLayer>,
    traffic: Option<ViewerTraffic>,
    state: Option<State>,
    error: Option<anyhow::Error>,
    started: Instant,
}

/// Which drag is under way.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Drag {
    Pan,
    Orbit,
    Look(PhysicalPosition<f64>),
}

struct State {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    gpu: GpuContext,
    globe: Globe,
    controller: CameraController,
    start: View,
    cursor: PhysicalPosition<f64>,
    drag: Option<Drag>,
    modifiers: ModifiersState,
    keys: HashSet<KeyCode>,
    last_tick: Instant,
    fps: FpsCounter,
    vectors: Option<VectorLayer>,
    traffic: Option<ViewerTraffic>,
    /// The Sun's clock without traffic, Unix seconds (`None`: a fixed light).
    sun_time: Option<f64>,
    /// Where the left button went down (a release close to it is a click).
    pressed_at: Option<PhysicalPosition<f64>>,
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
        match State::new(event_loop, &self.options) {
            Ok(mut s) => {
                s.window.request_redraw();
                s.vectors = self.vectors.take();
                s.traffic = self.traffic.take();
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
            WindowEvent::ModifiersChanged(m) => state.modifiers = m.state(),
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
                    state.key_pressed(code);
                } else {
                    state.keys.remove(&code);
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
                let (x, y) = (state.cursor.x, state.cursor.y);
                state.controller.zoom(&state.globe, x, y, notches);
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
    fn new(event_loop: &ActiveEventLoop, options: &ViewerOptions) -> anyhow::Result<Self> {
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
        let gpu = GpuContext::with_adapter(instance, adapter)?;
        let size = window.inner_size();
        let caps = surface.get_capabilities(&gpu.adapter);
        let format = caps
            .formats
            .iter()
            .copied()
            .find(wgpu::TextureFormat::is_srgb)
            .or_else(|| caps.formats.first().copied())
            .context("the window surface offers no pixel format")?;
        let config = surface
            .get_default_config(&gpu.adapter, size.width.max(1), size.height.max(1))
            .map(|c| wgpu::SurfaceConfiguration {
                format,
                present_mode: wgpu::PresentMode::AutoVsync,
                ..c
            })
            .context("the window surface is not supported by the adapter")?;
        surface.configure(&gpu.device, &config);
        let mut builder = options.globe.clone();
        builder.viewport(config.width, config.height);
        let mut globe = builder.build(&gpu, format)?;
        if let Some(t) = options.sun_time {
            globe.set_lighting(Some(globus_engine::Lighting::at_time(t)));
        }
        let start = match options.ortho_m {
            Some(m) => options.camera.orthographic_view(
                &globe,
                m,
                options.fov_deg,
                config.width,
                config.height,
            ),
            None => options
                .camera
                .view(&globe, options.fov_deg, config.width, config.height),
        };
        Ok(Self {
            window,
            surface,
            config,
            gpu,
            globe,
            controller: CameraController::new(start),
            start,
            cursor: PhysicalPosition::default(),
            drag: None,
            modifiers: ModifiersState::default(),
            keys: HashSet::new(),
            last_tick: Instant::now(),
            fps: FpsCounter {
                frames: 0,
                since: Instant::now(),
                fps: 0.0,
            },
            vectors: None,
            traffic: None,
            sun_time: options.sun_time,
            pressed_at: None,
        })
    }

    fn resize(&mut self, size: PhysicalSize<u32>) {
        if size.width == 0 || size.height == 0 {
            return;
        }
        self.config.width = size.width;
        self.config.height = size.height;
        self.surface.configure(&self.gpu.device, &self.config);
        self.controller.resize(size.width, size.height);
    }

    fn key_pressed(&mut self, code: KeyCode) {
        match code {
            KeyCode::KeyF => {
                let view = *self.controller.view();
                let target =
                    self.controller
                        .ground_under(&self.globe, self.cursor.x, self.cursor.y);
                let up = self
                    .globe
                    .ellipsoid()
                    .geodetic_normal(view.position)
                    .unwrap_or(globus_engine::DVec3::Z);
                if let (Some(point), Some(size)) = (target, view.ortho_height_m()) {
                    // Orthographic: a quarter of the size, centred on the point.
                    let (w, h) = (f64::from(view.width_px), f64::from(view.height_px));
                    let centre = self.controller.ground_under(&self.globe, 0.5 * w, 0.5 * h);
                    if let Some((from, to)) = centre
                        .and_then(|c| c.try_normalize())
                        .zip(point.try_normalize())
                    {
                        let q = DQuat::from_rotation_arc(from, to);
                        let to = View {
                            position: q * view.position,
                            orientation: (q * view.orientation).normalize(),
                            ..view
                        }
                        .orthographic(size * 0.25);
                        self.controller
                            .fly_to(&self.globe, to, Duration::from_secs_f64(FLIGHT_S));
                    }
                } else if let Some(point) = target
                    && let Some(eye_dir) = (view.position - point).try_normalize()
                {
                    let distance = (view.position - point).length() * 0.25;
                    let eye = point + eye_dir * distance.max(10.0);
                    if let Some(to) = View::look_at(
                        eye,
                        point,
                        up,
                        view.fov_y_rad,
                        view.width_px,
                        view.height_px,
                    ) {
                        self.controller
                            .fly_to(&self.globe, to, Duration::from_secs_f64(FLIGHT_S));
                    }
                }
            }
            KeyCode::Space if self.traffic.is_some() => {
                if let Some(t) = self.traffic.as_mut() {
                    t.paused = !t.paused;
                }
            }
            KeyCode::Equal | KeyCode::NumpadAdd if self.traffic.is_some() => {
                if let Some(t) = self.traffic.as_mut() {
                    t.speed = (t.speed * 2.0).min(crate::traffic_cmd::MAX_SPEED);
                }
            }
            KeyCode::Minus | KeyCode::NumpadSubtract if self.traffic.is_some() => {
                if let Some(t) = self.traffic.as_mut() {
                    t.speed = (t.speed / 2.0).max(1.0 / 64.0);
                }
            }
            KeyCode::KeyC if self.traffic.is_some() => self.toggle_follow(),
            KeyCode::BracketLeft | KeyCode::BracketRight if self.traffic.is_none() => {
                let step = if code == KeyCode::BracketLeft {
                    -SUN_STEP_S
                } else {
                    SUN_STEP_S
                };
                if let Some(t) = self.sun_time.as_mut() {
                    *t += step;
                }
            }
            KeyCode::KeyO => {
                let on = !self.controller.is_orthographic();
                self.controller.set_orthographic(&self.globe, on);
            }
            KeyCode::Home => {
                let to = View {
                    width_px: self.config.width,
                    height_px: self.config.height,
                    ..self.start
                };
                self.controller
                    .fly_to(&self.globe, to, Duration::from_secs_f64(FLIGHT_S));
            }
            _ => {
                self.keys.insert(code);
            }
        }
    }

    fn mouse_button(&mut self, button: MouseButton, pressed: bool) {
        let (x, y) = (self.cursor.x, self.cursor.y);
        let orbit_key = self.modifiers.control_key();
        if !pressed {
            if button == MouseButton::Left
                && let Some(at) = self.pressed_at.take()
                && (at.x - x).hypot(at.y - y) < 3.0
            {
                self.click(x, y);
            }
            self.controller.end_pan();
            self.controller.end_orbit();
            self.drag = None;
            return;
        }
        if button == MouseButton::Left {
            self.pressed_at = Some(self.cursor);
        }
        self.drag = match button {
            MouseButton::Left if orbit_key => self
                .controller
                .begin_orbit(&self.globe, x, y)
                .then_some(Drag::Orbit),
            MouseButton::Middle => self
                .controller
                .begin_orbit(&self.globe, x, y)
                .then_some(Drag::Orbit),
            MouseButton::Left => self
                .controller
                .begin_pan(&self.globe, x, y)
                .then_some(Drag::Pan),
            MouseButton::Right => Some(Drag::Look(self.cursor)),
            _ => self.drag,
        };
    }

    /// C: follow the selected aircraft (the camera looks at it from behind and above, then
    /// moves with it, keeping the view the user gives it), or stop following.
    fn toggle_follow(&mut self) {
        let Some(t) = self.traffic.as_mut() else {
            return;
        };
        if t.follow.take().is_some() {
            return;
        }
        let Some(id) = t.scene.layer.selected() else {
            tracing::warn!("nothing to follow: click an aircraft first");
            return;
        };
        let Some(at) = t.scene.layer.position_now(id) else {
            return;
        };
        let view = *self.controller.view();
        let up = self
            .globe
            .ellipsoid()
            .geodetic_normal(at)
            .unwrap_or(DVec3::Z);
        let back = (view.position - at)
            .reject_from(up)
            .normalize_or(up.any_orthonormal_vector());
        let eye = at + back * 2_500.0 + up * 1_500.0;
        if let Some(to) = View::look_at(eye, at, up, view.fov_y_rad, view.width_px, view.height_px)
        {
            self.controller.set_view(to);
        }
        t.follow = globus_engine::Follow::start(&t.scene.layer, id);
    }

    /// A click: selects the aircraft under the cursor (printed as one JSON line), or prints
    /// the picked vector feature's properties, or the ground position.
    fn click(&mut self, x: f64, y: f64) {
        let pick = match self.globe.pick(x, y) {
            Ok(Some(p)) => p,
            Ok(None) => return,
            Err(e) => {
                tracing::warn!("picking failed: {e}");
                return;
            }
        };
        let ground = pick
            .surface()
            .and_then(|p| self.globe.cartographic(p))
            .map(|c| [c.lon_deg(), c.lat_deg(), c.height_m]);
        if let Some(t) = self.traffic.as_mut() {
            let aircraft = pick
                .object()
                .and_then(|o| t.scene.layer.aircraft_for_pick(o));
            if let Some(id) = aircraft {
                t.scene.layer.select(Some(id));
                println!("{}", t.describe(id));
                return;
            }
            if pick.object().is_none() {
                t.scene.layer.select(None);
                t.follow = None;
            }
        }
        let feature = pick
            .object()
            .and_then(|o| self.vectors.as_ref()?.feature_for_pick(o));
        let line = match feature {
            Some((id, f)) => serde_json::json!({
                "feature": id.0,
                "index": f.index,
                "properties": f.properties,
                "ground": ground,
            }),
            None => serde_json::json!({ "ground": ground }),
        };
        println!("{line}");
    }

    fn cursor_moved(&mut self, position: PhysicalPosition<f64>) {
        let last = self.cursor;
        self.cursor = position;
        match self.drag {
            Some(Drag::Pan) => self.controller.pan_to(&self.globe, position.x, position.y),
            Some(Drag::Orbit) => {
                let per_px = std::f64::consts::PI / f64::from(self.config.height.max(1));
                self.controller.orbit_by(
                    &self.globe,
                    position.x - last.x,
                    position.y - last.y,
                    per_px,
                );
            }
            Some(Drag::Look(from)) => {
                self.controller
                    .look(&self.globe, position.x - from.x, position.y - from.y);
                self.drag = Some(Drag::Look(position));
            }
            None => {}
        }
    }

    fn tick(&mut self) {
        let now = Instant::now();
        let dt = now - self.last_tick;
        self.last_tick = now;
        // From one frame's start to the next's: what a target frame rate is held to.
        self.globe.frame_time(dt.as_secs_f64());
        self.controller.update(&self.globe, dt);
        let axis = |plus: KeyCode, minus: KeyCode| {
            f64::from(u8::from(self.keys.contains(&plus)))
                - f64::from(u8::from(self.keys.contains(&minus)))
        };
        let forward = axis(KeyCode::KeyW, KeyCode::KeyS);
        let right = axis(KeyCode::KeyD, KeyCode::KeyA);
        let up = axis(KeyCode::KeyE, KeyCode::KeyQ);
        self.controller.fly(&self.globe, forward, right, up, dt);
        if self.traffic.is_none()
            && let Some(t) = self.sun_time.as_mut()
        {
            *t += dt.as_secs_f64();
            self.globe
                .set_lighting(Some(globus_engine::Lighting::at_time(*t)));
        }
        if let Some(t) = self.traffic.as_mut() {
            t.tick(dt);
            self.globe
                .set_lighting(Some(globus_engine::Lighting::at_time(t.scene.time_s)));
            // The camera moves with the followed aircraft before the frame is drawn.
            if let Some(f) = t.follow.as_mut() {
                let mut view = *self.controller.view();
                if f.update(&t.scene.layer, &mut view) {
                    self.controller.set_view(view);
                } else {
                    t.follow = None;
                }
            }
        }
    }

    fn redraw(&mut self) -> anyhow::Result<()> {
        self.tick();
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.gpu.device, &self.config);
                return Ok(());
            }
            other => bail!("the window surface failed: {other:?}"),
        };
        let view = *self.controller.view();
        let report = self.globe.update(&view);
        let target = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        {
            let mut overlays: Vec<&mut dyn Overlay> = Vec::new();
            if let Some(v) = self.vectors.as_mut() {
                overlays.push(v);
            }
            if let Some(t) = self.traffic.as_mut() {
                overlays.push(&mut t.scene.layer);
            }
            self.globe.render(&mut encoder, &target, &mut overlays);
        }
        self.gpu.queue.submit([encoder.finish()]);
        self.window.pre_present_notify();
        self.gpu.queue.present(frame);

        self.fps.frames += 1;
        let elapsed = self.fps.since.elapsed().as_secs_f64();
        if elapsed >= 0.5 {
            self.fps.fps = f64::from(self.fps.frames) / elapsed;
            self.fps.frames = 0;
            self.fps.since = Instant::now();
            let traffic = match (&self.traffic, self.sun_time) {
                (Some(t), _) => format!(
                    " | {} x{}{} | {} aircraft",
                    crate::traffic_cmd::format_time(t.scene.time_s),
                    t.speed,
                    if t.paused { " paused" } else { "" },
                    t.scene.layer.stats().aircraft
                ),
                (None, Some(t)) => format!(" | sun {}", crate::traffic_cmd::format_time(t)),
                (None, None) => String::new(),
            };
            // Orthographic: the projection's size; perspective: the height above ground.
            let scale = match self.controller.view().ortho_height_m() {
                Some(m) => format!("top-down {:.1} km", m / 1e3),
                None => format!(
                    "{:.0} m above ground",
                    self.controller.height_above_ground_m(&self.globe)
                ),
            };
            // With a target frame rate, the error bound it holds the frames to.
            let quality = self.globe.quality().map_or(String::new(), |q| {
                format!(
                    " (target {:.0}, error {:.1} px)",
                    1.0 / q.options().target_frame_s,
                    report.sse_bound_px
                )
            });
            self.window.set_title(&format!(
                "Globus | {:.1} fps{quality} | {} tiles drawn | {} loading | {} imagery loading | \
                 {scale}{traffic}",
                self.fps.fps, report.draw.tiles, report.wanted, report.colours_pending,
            ));
        }
        Ok(())
    }
}
