//! The vector overlay's GPU side: two pipelines (fills; lines and points as screen-space
//! capsules), one instance buffer and one fill vertex buffer that grow by doubling, and a
//! storage buffer of anchor offsets written every frame.

use std::mem::size_of;

use bytemuck::{Pod, Zeroable};
use globus_geo::DVec3;
use globus_vector::Rgba;

use crate::overlay::FrameContext;

/// How much nearer than its depth a draped fill is tested, as a fraction of its depth: it
/// lies on the terrain's own triangles, so only rounding separates them (1 cm at 1 km).
const FILL_TOLERANCE: f32 = 1.0e-5;
/// The same for a line's centre against the four terrain texels around it.
const LINE_TOLERANCE: f32 = 1.0e-4;

/// One line segment or point symbol (48 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct LineInstance {
    pub a: [f32; 3],
    pub anchor: u32,
    pub b: [f32; 3],
    pub id: u32,
    pub colour: u32,
    pub outline: u32,
    pub width_px: f32,
    pub outline_px: f32,
}

fn f32x3(p: DVec3) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

impl LineInstance {
    pub(crate) fn segment(a: DVec3, b: DVec3, id: u32, colour: Rgba, width_px: f32) -> Self {
        Self {
            a: f32x3(a),
            anchor: 0,
            b: f32x3(b),
            id,
            colour: colour.packed(),
            outline: colour.packed(),
            width_px,
            outline_px: 0.0,
        }
    }

    pub(crate) fn point(
        at: DVec3,
        id: u32,
        colour: Rgba,
        outline: Rgba,
        size_px: f32,
        outline_px: f32,
        square: bool,
    ) -> Self {
        Self {
            a: f32x3(at),
            anchor: 0,
            b: f32x3(at),
            id,
            colour: colour.packed(),
            outline: outline.packed(),
            width_px: size_px,
            outline_px: if square { -outline_px } else { outline_px },
        }
    }
}

/// One fill vertex (24 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct FillVertex {
    pub position: [f32; 3],
    pub anchor: u32,
    pub colour: u32,
    pub id: u32,
}

impl FillVertex {
    pub(crate) fn new(p: DVec3, anchor: u32, colour: Rgba, id: u32, draped: bool) -> Self {
        // The draped flag rides in the anchor's top bit (anchors stay far below 2^31).
        Self {
            position: f32x3(p),
            anchor: anchor | if draped { DRAPED_BIT } else { 0 },
            colour: colour.packed(),
            id,
        }
    }
}

/// Marks a draped fill vertex in [`FillVertex::anchor`].
pub(crate) const DRAPED_BIT: u32 = 1 << 31;

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Uniforms {
    clip_from_eye: [[f32; 4]; 4],
    viewport: [f32; 4],
    tolerance: [f32; 4],
}

/// A buffer that grows by doubling.
struct Growing {
    buffer: wgpu::Buffer,
    label: &'static str,
    usage: wgpu::BufferUsages,
}

impl Growing {
    fn new(device: &wgpu::Device, label: &'static str, usage: wgpu::BufferUsages) -> Self {
        let usage = usage | wgpu::BufferUsages::COPY_DST;
        Self {
            buffer: buffer(device, label, 256, usage),
            label,
            usage,
        }
    }

    fn write(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, bytes: &[u8]) {
        let need = (bytes.len() as u64).max(16);
        if need > self.buffer.size() {
            self.buffer = buffer(device, self.label, need.next_power_of_two(), self.usage);
        }
        if !bytes.is_empty() {
            queue.write_buffer(&self.buffer, 0, bytes);
        }
    }
}

fn buffer(
    device: &wgpu::Device,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.div_ceil(16) * 16,
        usage,
        mapped_at_creation: false,
    })
}

/// Pipelines and buffers.
pub(crate) struct Gpu {
    fill: wgpu::RenderPipeline,
    line: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    uniforms: wgpu::Buffer,
    anchors: Growing,
    lines: Growing,
    fills: Growing,
    bind_group: Option<(wgpu::BindGroup, u64, wgpu::TextureView)>,
    pub line_count: u32,
    pub fill_vertices: u32,
}

/// The shader.
pub const SHADER: &str = include_str!("vector.wgsl");

impl Gpu {
    pub(crate) fn new(frame: &FrameContext<'_>) -> Self {
        let device = frame.device();
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("vector"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let entry = |binding, visibility, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty,
            count: None,
        };
        let both = wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vector"),
            entries: &[
                entry(
                    0,
                    both,
                    wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                ),
                entry(
                    1,
                    wgpu::ShaderStages::VERTEX,
                    wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                ),
                entry(
                    2,
                    wgpu::ShaderStages::FRAGMENT,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                ),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("vector"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let formats = frame.formats();
        let blend = Some(wgpu::BlendState::ALPHA_BLENDING);
        let targets = formats.colour_targets(blend, true);
        let pipeline = |label,
                        vs,
                        fs,
                        buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
                        depth: wgpu::DepthStencilState| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(vs),
                    compilation_options: Default::default(),
                    buffers,
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: Some(depth),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(fs),
                    compilation_options: Default::default(),
                    targets: &targets,
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let fill_attrs =
            wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32, 2 => Uint32, 3 => Uint32];
        let fill = pipeline(
            "vector fills",
            "fill_vs",
            "fill_fs",
            &[Some(wgpu::VertexBufferLayout {
                array_stride: size_of::<FillVertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &fill_attrs,
            })],
            formats.depth_test(false),
        );
        let line_attrs = wgpu::vertex_attr_array![
            0 => Float32x3, 1 => Uint32, 2 => Float32x3, 3 => Uint32,
            4 => Uint32, 5 => Uint32, 6 => Float32, 7 => Float32
        ];
        let mut no_depth_test = formats.depth_test(false);
        no_depth_test.depth_compare = Some(wgpu::CompareFunction::Always);
        let line = pipeline(
            "vector lines",
            "line_vs",
            "line_fs",
            &[Some(wgpu::VertexBufferLayout {
                array_stride: size_of::<LineInstance>() as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &line_attrs,
            })],
            no_depth_test,
        );
        let uniforms = buffer(
            device,
            "vector uniforms",
            size_of::<Uniforms>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        Self {
            fill,
            line,
            layout,
            uniforms,
            anchors: Growing::new(device, "vector anchors", wgpu::BufferUsages::STORAGE),
            lines: Growing::new(device, "vector lines", wgpu::BufferUsages::VERTEX),
            fills: Growing::new(device, "vector fills", wgpu::BufferUsages::VERTEX),
            bind_group: None,
            line_count: 0,
            fill_vertices: 0,
        }
    }

    /// Uploads new geometry.
    pub(crate) fn upload(
        &mut self,
        frame: &FrameContext<'_>,
        lines: &[LineInstance],
        fills: &[FillVertex],
    ) {
        let (device, queue) = (frame.device(), frame.queue());
        self.lines.write(device, queue, bytemuck::cast_slice(lines));
        self.fills.write(device, queue, bytemuck::cast_slice(fills));
        self.line_count = lines.len() as u32;
        self.fill_vertices = fills.len() as u32;
    }

    /// Writes this frame's uniforms and anchor offsets (anchor minus eye, in f64 first).
    pub(crate) fn frame(&mut self, frame: &FrameContext<'_>, anchors: &[DVec3]) {
        let (device, queue) = (frame.device(), frame.queue());
        let camera = frame.camera();
        let (w, h) = camera.viewport_px();
        let (w, h) = (w.max(1) as f32, h.max(1) as f32);
        let u = Uniforms {
            clip_from_eye: camera.clip_from_eye().to_cols_array_2d(),
            viewport: [w, h, 1.0 / w, 1.0 / h],
            tolerance: [FILL_TOLERANCE, LINE_TOLERANCE, 0.0, 0.0],
        };
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&u));
        let offsets: Vec<[f32; 4]> = anchors
            .iter()
            .map(|&a| {
                let r = camera.relative(a);
                [r.x, r.y, r.z, 0.0]
            })
            .collect();
        self.anchors
            .write(device, queue, bytemuck::cast_slice(&offsets));
        // The bind group follows the anchor buffer and the frame's depth texture.
        let depth = frame.terrain_depth();
        let anchor_size = self.anchors.buffer.size();
        if self
            .bind_group
            .as_ref()
            .is_none_or(|(_, size, view)| *size != anchor_size || view != depth)
        {
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("vector"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: self.uniforms.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: self.anchors.buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: wgpu::BindingResource::TextureView(frame.terrain_depth()),
                    },
                ],
            });
            self.bind_group = Some((group, anchor_size, depth.clone()));
        }
    }

    /// Draws fills, then lines and points: two draw calls.
    pub(crate) fn draw(&self, pass: &mut wgpu::RenderPass<'_>) -> u32 {
        let Some((group, _, _)) = &self.bind_group else {
            return 0;
        };
        let mut calls = 0;
        pass.set_bind_group(0, group, &[]);
        if self.fill_vertices > 0 {
            pass.set_pipeline(&self.fill);
            pass.set_vertex_buffer(0, self.fills.buffer.slice(..));
            pass.draw(0..self.fill_vertices, 0..1);
            calls += 1;
        }
        if self.line_count > 0 {
            pass.set_pipeline(&self.line);
            pass.set_vertex_buffer(0, self.lines.buffer.slice(..));
            pass.draw(0..6, 0..self.line_count);
            calls += 1;
        }
        calls
    }

    /// GPU bytes held.
    pub(crate) fn bytes(&self) -> u64 {
        self.anchors.buffer.size() + self.lines.buffer.size() + self.fills.buffer.size()
    }
}
