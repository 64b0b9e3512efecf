//! Renders one PNG of the procedural Alps with a marker of our own over a summit, drawn
//! through the [`Overlay`] trait, then picks it back.
//!
//! ```sh
//! cargo run --release -p globus-engine --example marker -- alps-marker.png
//! ```
//!
//! Prints one JSON line: where the marker is drawn (pixels), the id and ground point picked
//! there. The marker is hidden wherever terrain stands in front of it, as everything drawn
//! in the world and screen-aligned passes is.

use std::time::Duration;

use globus_engine::{
    CameraSpec, Cartographic, FrameContext, Globe, Headless, Overlay, OverlayPass, save_png,
};

/// The shader's uniforms.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Anchor {
    clip_from_eye: [[f32; 4]; 4],
    offset: [f32; 4],
    viewport: [f32; 4],
    id: [u32; 4],
}

/// A red square 16 pixels wide facing the screen, anchored at a world point, pickable as
/// `id`.
struct Marker {
    at: globus_engine::DVec3,
    id: u32,
    gpu: Option<(wgpu::RenderPipeline, wgpu::Buffer, wgpu::BindGroup)>,
}

const SHADER: &str = r#"
struct Anchor { clip_from_eye: mat4x4<f32>, offset: vec4<f32>, viewport: vec4<f32>, id: vec4<u32> }
@group(0) @binding(0) var<uniform> a: Anchor;

@vertex
fn vs(@builtin(vertex_index) v: u32) -> @builtin(position) vec4<f32> {
    let corner = vec2<f32>(f32(v & 1u), f32((v >> 1u) & 1u)) * 2.0 - 1.0;
    let clip = a.clip_from_eye * vec4<f32>(a.offset.xyz, 1.0);
    // 8 pixels each way from the anchor, at the anchor's depth.
    return vec4<f32>(clip.xy + corner * 8.0 * 2.0 / a.viewport.xy * clip.w, clip.zw);
}

struct Out { @location(0) colour: vec4<f32>, @location(1) id: u32 }

@fragment
fn fs() -> Out {
    return Out(vec4<f32>(1.0, 0.0, 0.0, 1.0), a.id.x);
}
"#;

impl Overlay for Marker {
    fn passes(&self) -> &[OverlayPass] {
        &[OverlayPass::ScreenAligned]
    }

    fn prepare(&mut self, frame: &FrameContext<'_>) {
        let device = frame.device();
        let (_, uniforms, _) = self.gpu.get_or_insert_with(|| {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("marker"),
                source: wgpu::ShaderSource::Wgsl(SHADER.into()),
            });
            let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("marker"),
                layout: None,
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleStrip,
                    ..Default::default()
                },
                depth_stencil: Some(frame.formats().depth_test(false)),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs"),
                    compilation_options: Default::default(),
                    targets: &frame.formats().colour_targets(None, true),
                }),
                multiview_mask: None,
                cache: None,
            });
            let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("marker"),
                size: std::mem::size_of::<Anchor>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("marker"),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniforms.as_entire_binding(),
                }],
            });
            (pipeline, uniforms, bind_group)
        });
        // The anchor relative to the frame's origin, subtracted in f64: no jitter anywhere.
        let camera = frame.camera();
        let offset = camera.relative(self.at);
        let (w, h) = camera.viewport_px();
        let anchor = Anchor {
            clip_from_eye: camera.clip_from_eye().to_cols_array_2d(),
            offset: [offset.x, offset.y, offset.z, 0.0],
            viewport: [w as f32, h as f32, 0.0, 0.0],
            id: [self.id, 0, 0, 0],
        };
        frame
            .queue()
            .write_buffer(uniforms, 0, bytemuck::bytes_of(&anchor));
    }

    fn draw(&self, _: OverlayPass, _: &FrameContext<'_>, pass: &mut wgpu::RenderPass<'_>) {
        if let Some((pipeline, _, bind_group)) = &self.gpu {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind_group, &[]);
            pass.draw(0..4, 0..1);
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "alps-marker.png".into());
    let (width, height) = (960, 540);
    let mut headless = Headless::new(&Globe::builder(), width, height)?;
    let camera = CameraSpec {
        lon_deg: 7.6,
        lat_deg: 46.0,
        alt_m: 3000.0,
        heading_deg: 200.0,
        pitch_deg: -10.0,
        above_ground: true,
    };
    let view = camera.view(headless.globe(), 60.0, width, height);
    // Load the view, then put the marker 100 m above the ground at the centre of the picture.
    headless.render_complete(&view, Duration::from_secs(120), &mut [])?;
    let globe = headless.globe();
    let ground = globe
        .ray_pick(view.position, view.ray_direction(480.0, 300.0))
        .ok_or("no ground at the centre")?;
    let c = globe
        .cartographic(ground)
        .ok_or("the ground is at the centre of the Earth")?;
    let mut marker = Marker {
        at: globe.world_position(Cartographic {
            height_m: c.height_m + 100.0,
            ..c
        }),
        id: 1,
        gpu: None,
    };
    let frame = headless.render_complete(&view, Duration::from_secs(120), &mut [&mut marker])?;
    save_png(&frame.image, out.as_ref())?;
    let globe = headless.globe();
    let px = globe
        .camera()
        .and_then(|c| c.project(marker.at))
        .ok_or("the marker is behind the camera")?;
    let pick = globe.pick(px.x, px.y)?.ok_or("outside the frame")?;
    let picked_ground = pick
        .surface()
        .and_then(|p| globe.cartographic(p))
        .map(|c| [c.lon_deg(), c.lat_deg(), c.height_m]);
    println!(
        "{}",
        serde_json::json!({
            "png": out,
            "marker_px": [px.x, px.y],
            "picked_id": pick.object(),
            "picked_ground": picked_ground,
            "tiles": frame.report.draw.tiles,
        })
    );
    Ok(())
}
