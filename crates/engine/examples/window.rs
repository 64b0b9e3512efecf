//! A window on the planet: the globe embedded with winit, driven by the engine's camera
//! controller, with a HUD of our own (a crosshair and a compass needle pointing north)
//! drawn through the [`Overlay`] trait in the screen pass.
//!
//! ```sh
//! cargo run --release -p globus-engine --example window
//! ```
//!
//! Left drag pans, the wheel zooms towards the cursor, right drag looks around, middle drag
//! orbits the point under the cursor; the title shows what was picked at the last click.

use std::sync::Arc;
use std::time::Instant;

use globus_engine::{
    CameraController, CameraSpec, FrameContext, Globe, GpuContext, Overlay, OverlayPass,
};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalPosition;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::window::{Window, WindowId};

/// Crosshair and compass, in pixels from the top-left corner.
struct Hud {
    heading_rad: f32,
    gpu: Option<(wgpu::RenderPipeline, wgpu::Buffer)>,
    vertices: u32,
}

const HUD_SHADER: &str = r#"
struct V { @location(0) px: vec2<f32>, @location(1) viewport: vec2<f32> }
@vertex
fn vs(v: V) -> @builtin(position) vec4<f32> {
    return vec4<f32>(v.px / v.viewport * vec2<f32>(2.0, -2.0) + vec2<f32>(-1.0, 1.0), 0.0, 1.0);
}
@fragment
fn fs() -> @location(0) vec4<f32> { return vec4<f32>(1.0, 0.9, 0.2, 1.0); }
"#;

impl Hud {
    /// Triangles of the HUD for a viewport of `w` x `h`, each vertex with the viewport size.
    fn triangles(&self, w: f32, h: f32) -> Vec<[f32; 4]> {
        let mut out = Vec::new();
        let mut quad = |x0: f32, y0: f32, x1: f32, y1: f32| {
            for (x, y) in [(x0, y0), (x1, y0), (x1, y1), (x0, y0), (x1, y1), (x0, y1)] {
                out.push([x, y, w, h]);
            }
        };
        // The crosshair.
        let (cx, cy) = (w / 2.0, h / 2.0);
        quad(cx - 12.0, cy - 1.0, cx + 12.0, cy + 1.0);
        quad(cx - 1.0, cy - 12.0, cx + 1.0, cy + 12.0);
        // The compass needle, 60 px from the top-right corner, pointing north.
        let (ox, oy) = (w - 60.0, 60.0);
        let (s, c) = (-self.heading_rad).sin_cos();
        let turn = |x: f32, y: f32| [ox + x * c - y * s, oy + x * s + y * c, w, h];
        out.extend([turn(0.0, -40.0), turn(10.0, 10.0), turn(-10.0, 10.0)]);
        out
    }
}

impl Overlay for Hud {
    fn passes(&self) -> &[OverlayPass] {
        &[OverlayPass::Screen]
    }

    fn prepare(&mut self, frame: &FrameContext<'_>) {
        let device = frame.device();
        let (w, h) = frame.camera().viewport_px();
        let triangles = self.triangles(w as f32, h as f32);
        self.vertices = triangles.len() as u32;
        let (_, buffer) = self.gpu.get_or_insert_with(|| {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("hud"),
                source: wgpu::ShaderSource::Wgsl(HUD_SHADER.into()),
            });
            let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("hud"),
                layout: None,
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[Some(wgpu::VertexBufferLayout {
                        array_stride: 16,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &wgpu::vertex_attr_array![0 => Float32x2, 1 => Float32x2],
                    })],
                },
                primitive: Default::default(),
                // The screen pass has no depth buffer.
                depth_stencil: None,
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs"),
                    compilation_options: Default::default(),
                    targets: &frame.formats().colour_targets(None, false),
                }),
                multiview_mask: None,
                cache: None,
            });
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("hud"),
                size: 64 * 16,
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            (pipeline, buffer)
        });
        frame
            .queue()
            .write_buffer(buffer, 0, bytemuck::cast_slice(&triangles));
    }

    fn draw(&self, _: OverlayPass, _: &FrameContext<'_>, pass: &mut wgpu::RenderPass<'_>) {
        if let Some((pipeline, buffer)) = &self.gpu {
            pass.set_pipeline(pipeline);
            pass.set_vertex_buffer(0, buffer.slice(..));
            pass.draw(0..self.vertices, 0..1);
        }
    }
}

struct Running {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    gpu: GpuContext,
    globe: Globe,
    controller: CameraController,
    hud: Hud,
    cursor: PhysicalPosition<f64>,
    dragging: Option<MouseButton>,
    picked: String,
    started: Instant,
}

#[derive(Default)]
struct App {
    running: Option<Running>,
}

impl Running {
    fn new(event_loop: &ActiveEventLoop) -> Result<Self, Box<dyn std::error::Error>> {
        let window = Arc::new(event_loop.create_window(Window::default_attributes())?);
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle(
            Box::new(event_loop.owned_display_handle()),
        ));
        let surface = instance.create_surface(Arc::clone(&window))?;
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            compatible_surface: Some(&surface),
            ..Default::default()
        }))?;
        let gpu = GpuContext::with_adapter(instance, adapter)?;
        let size = window.inner_size();
        let format = surface.get_capabilities(&gpu.adapter).formats[0];
        let config = surface
            .get_default_config(&gpu.adapter, size.width.max(1), size.height.max(1))
            .ok_or("the window cannot be drawn into")?;
        let config = wgpu::SurfaceConfiguration { format, ..config };
        surface.configure(&gpu.device, &config);
        let globe = Globe::builder().build(&gpu, format)?;
        let start = CameraSpec {
            lon_deg: 7.6,
            lat_deg: 46.0,
            alt_m: 6000.0,
            heading_deg: 200.0,
            pitch_deg: -15.0,
            above_ground: true,
        }
        .view(&globe, 60.0, config.width, config.height);
        Ok(Self {
            window,
            surface,
            config,
            gpu,
            globe,
            controller: CameraController::new(start),
            hud: Hud {
                heading_rad: 0.0,
                gpu: None,
                vertices: 0,
            },
            cursor: PhysicalPosition::default(),
            dragging: None,
            picked: String::new(),
            started: Instant::now(),
        })
    }

    fn redraw(&mut self) {
        let view = *self.controller.view();
        let report = self.globe.update(&view);
        self.hud.heading_rad = view
            .heading_pitch(&self.globe.ellipsoid())
            .map_or(0.0, |(h, _)| h as f32);
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            _ => {
                self.surface.configure(&self.gpu.device, &self.config);
                return;
            }
        };
        let target = frame.texture.create_view(&Default::default());
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        self.globe
            .render(&mut encoder, &target, &mut [&mut self.hud]);
        self.gpu.queue.submit([encoder.finish()]);
        self.gpu.queue.present(frame);
        self.window.set_title(&format!(
            "Globus example | {} tiles | {:.0} s | {}",
            report.draw.tiles,
            self.started.elapsed().as_secs_f64(),
            self.picked
        ));
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.running.is_none() {
            match Running::new(event_loop) {
                Ok(r) => self.running = Some(r),
                Err(e) => {
                    eprintln!("cannot start: {e}");
                    event_loop.exit();
                }
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        let Some(r) = self.running.as_mut() else {
            return;
        };
        let (x, y) = (r.cursor.x, r.cursor.y);
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) if size.width > 0 && size.height > 0 => {
                r.config.width = size.width;
                r.config.height = size.height;
                r.surface.configure(&r.gpu.device, &r.config);
                r.controller.resize(size.width, size.height);
            }
            WindowEvent::CursorMoved { position, .. } => {
                let (dx, dy) = (position.x - x, position.y - y);
                r.cursor = position;
                match r.dragging {
                    Some(MouseButton::Left) => {
                        r.controller.pan_to(&r.globe, position.x, position.y)
                    }
                    Some(MouseButton::Right) => r.controller.look(&r.globe, dx, dy),
                    Some(MouseButton::Middle) => r.controller.orbit_by(&r.globe, dx, dy, 0.005),
                    _ => {}
                }
            }
            WindowEvent::MouseInput { state, button, .. } => {
                if state == ElementState::Released {
                    r.dragging = None;
                    r.controller.end_pan();
                    r.controller.end_orbit();
                    return;
                }
                r.dragging = Some(button);
                match button {
                    MouseButton::Left => {
                        r.controller.begin_pan(&r.globe, x, y);
                        // What is under the cursor, from the last frame's id and depth buffers.
                        if let Ok(Some(pick)) = r.globe.pick(x, y) {
                            r.picked = pick.surface().and_then(|p| r.globe.cartographic(p)).map_or(
                                "sky".into(),
                                |c| {
                                    format!(
                                        "{:.4}, {:.4}, {:.0} m",
                                        c.lat_deg(),
                                        c.lon_deg(),
                                        c.height_m
                                    )
                                },
                            );
                        }
                    }
                    MouseButton::Middle => {
                        r.controller.begin_orbit(&r.globe, x, y);
                    }
                    _ => {}
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let notches = match delta {
                    MouseScrollDelta::LineDelta(_, n) => f64::from(n),
                    MouseScrollDelta::PixelDelta(p) => p.y / 60.0,
                };
                r.controller.zoom(&r.globe, x, y, notches);
            }
            WindowEvent::RedrawRequested => {
                r.redraw();
                r.window.request_redraw();
            }
            _ => {}
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let event_loop = EventLoop::new()?;
    event_loop.run_app(&mut App::default())?;
    Ok(())
}
