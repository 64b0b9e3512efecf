//! The traffic layer's GPU side: one storage buffer of aircraft (rewritten every frame: the
//! interpolated positions change), one of trail points mirroring the fleet's ring buffers
//! (only written points are uploaded, in pages), the built-in models' vertex buffer, and
//! three pipelines: trails and models in the world pass, symbols in the screen-aligned pass.
//! Trails are one draw, symbols one, models one per kind drawn this frame.

use std::mem::size_of;
use std::ops::Range;

use bytemuck::{Pod, Zeroable};

use super::models::ModelMesh;
use crate::gpu_util::{Growing, Pipelines, buffer, buffer_entry, texture_entry};
use crate::overlay::FrameContext;
use crate::text::GlyphAtlas;

/// One aircraft as the shaders read it (64 bytes); mirrored in `traffic.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct AircraftGpu {
    /// Position minus the eye, metres.
    pub position: [f32; 3],
    /// sRGB colour, packed.
    pub colour: u32,
    /// The geodetic normal at the aircraft (unit, ECEF axes): the shaders turn it, the
    /// heading and the pitch into the airframe's axes.
    pub normal: [f32; 3],
    /// [`bits`] and the kind in bits 8-9.
    pub bits: u32,
    /// The trail anchor minus the eye, metres.
    pub anchor: [f32; 3],
    /// Trail ring head (low 16 bits) and length (high 16).
    pub ring: u32,
    /// Heading (clockwise from north) and pitch, radians.
    pub heading_rad: f32,
    pub pitch_rad: f32,
    /// Trail points older than now (low 16 bits) and the stride drawn (high 16).
    pub trail: u32,
    pub spare: u32,
}

/// Bits of [`AircraftGpu::bits`].
pub(crate) mod bits {
    pub const LIVE: u32 = 1;
    pub const SELECTED: u32 = 2;
    pub const STALE: u32 = 4;
    pub const KIND_SHIFT: u32 = 8;
}

/// Per-frame constants; mirrored in `traffic.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct Uniforms {
    pub clip_from_eye: [[f32; 4]; 4],
    pub viewport: [f32; 4],
    /// Focal length (pixels), now (s since the epoch), trail length (s), depth tolerance.
    pub params: [f32; 4],
    /// Towards the sun, ambient light.
    pub sun: [f32; 4],
    /// Trail points per aircraft, first pick id, trail width (f32 bits), unused.
    pub counts: [u32; 4],
    /// Per kind: symbol size (pixels), model extent (metres).
    pub kinds: [[f32; 4]; 4],
}

/// A placed label as the shaders read it (48 bytes); mirrored in `traffic.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct LabelGpu {
    /// The aircraft on screen (pixels), its reversed-Z depth, the label's opacity.
    pub anchor: [f32; 2],
    pub depth: f32,
    pub opacity: f32,
    /// The box's top-left and size, pixels.
    pub origin: [f32; 2],
    pub size: [f32; 2],
    /// Text colour (sRGB, packed) and where the leader starts from the anchor (pixels).
    pub colour: u32,
    pub clearance: f32,
    pub spare: [f32; 2],
}

/// One glyph drawn: its label, its atlas glyph, its quad's top-left from the label's origin
/// (pixels).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct GlyphInstance {
    pub label: u32,
    pub glyph: u32,
    pub at: [f32; 2],
}

/// An atlas glyph for the shaders: texel rectangle, offset from the pen.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct GlyphGpu {
    rect: [f32; 4],
    offset: [f32; 2],
    spare: [f32; 2],
}

/// How labels are drawn: pixels per atlas pixel, atlas size, halo width in field units.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct LabelStyle {
    pub scale: [f32; 4],
}

/// Model vertex (24 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct ModelVertex {
    position: [f32; 3],
    normal: [f32; 3],
    accent: u32,
}

/// Trail points per upload page (4 KiB): written points are uploaded by whole pages, and
/// runs of dirty pages in one write.
pub(crate) const PAGE_POINTS: usize = 256;

/// Trail draws: instances whose trails need at most this many segments go together (one
/// draw each, of that many segments per instance; the last holds the rest).
pub(crate) const TRAIL_BUCKETS: [u32; 3] = [6, 20, u32::MAX];

/// The shader.
pub const SHADER: &str = concat!(
    include_str!("../overlay_common.wgsl"),
    include_str!("traffic.wgsl")
);

pub(crate) struct Gpu {
    trail: wgpu::RenderPipeline,
    model: wgpu::RenderPipeline,
    symbol: wgpu::RenderPipeline,
    leader: wgpu::RenderPipeline,
    glyph: wgpu::RenderPipeline,
    atlas: wgpu::TextureView,
    atlas_sampler: wgpu::Sampler,
    atlas_glyphs: wgpu::Buffer,
    label_style: wgpu::Buffer,
    labels: Growing,
    glyphs: Growing,
    label_count: u32,
    glyph_count: u32,
    layout: wgpu::BindGroupLayout,
    uniforms: wgpu::Buffer,
    aircraft: Growing,
    trail_points: Growing,
    models: wgpu::Buffer,
    /// Vertex range of each kind's model in `models`.
    model_ranges: [Range<u32>; 4],
    instances: Growing,
    /// Instance range of each kind this frame (into `instances`).
    instance_ranges: [Range<u32>; 4],
    trail_instances: Growing,
    /// Instance range and segments per instance of each trail bucket this frame.
    trail_ranges: [(Range<u32>, u32); 3],
    bind_group: Option<(wgpu::BindGroup, [u64; 4], wgpu::TextureView)>,
    /// Slots drawn (symbols) this frame.
    slots: u32,
}

impl Gpu {
    pub(crate) fn new(
        frame: &FrameContext<'_>,
        meshes: &[ModelMesh; 4],
        text: &GlyphAtlas,
    ) -> Self {
        let device = frame.device();
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("traffic"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        use wgpu::ShaderStages as Stage;
        let storage = wgpu::BufferBindingType::Storage { read_only: true };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("traffic"),
            entries: &[
                buffer_entry(0, Stage::VERTEX_FRAGMENT, wgpu::BufferBindingType::Uniform),
                buffer_entry(1, Stage::VERTEX, storage),
                buffer_entry(2, Stage::VERTEX, storage),
                // The terrain's depth: symbols test it per fragment, labels per vertex.
                wgpu::BindGroupLayoutEntry {
                    visibility: Stage::VERTEX_FRAGMENT,
                    ..texture_entry(3, false, wgpu::TextureViewDimension::D2)
                },
                texture_entry(4, true, wgpu::TextureViewDimension::D2),
                wgpu::BindGroupLayoutEntry {
                    binding: 5,
                    visibility: Stage::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
                buffer_entry(6, Stage::VERTEX, storage),
                buffer_entry(7, Stage::VERTEX, storage),
                buffer_entry(8, Stage::VERTEX, storage),
                buffer_entry(9, Stage::VERTEX_FRAGMENT, wgpu::BufferBindingType::Uniform),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("traffic"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let formats = frame.formats();
        let blend = Some(wgpu::BlendState::ALPHA_BLENDING);
        let kit = Pipelines {
            device,
            layout: &pipeline_layout,
            module: &module,
        };
        // Trails: colour only, tested against the terrain and what the world pass drew.
        let trail_attrs = wgpu::vertex_attr_array![0 => Uint32];
        let trail_buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: 4,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &trail_attrs,
        })];
        let trail = kit.make(
            "traffic trails",
            "trail_vs",
            "trail_fs",
            &trail_buffers,
            formats.depth_test(false),
            &formats.colour_targets(blend, false),
        );
        let model_attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 3 => Uint32];
        let slot_attrs = wgpu::vertex_attr_array![2 => Uint32];
        let model_buffers = [
            Some(wgpu::VertexBufferLayout {
                array_stride: size_of::<ModelVertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &model_attrs,
            }),
            Some(wgpu::VertexBufferLayout {
                array_stride: 4,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &slot_attrs,
            }),
        ];
        let model = kit.make(
            "traffic models",
            "model_vs",
            "model_fs",
            &model_buffers,
            formats.depth_test(true),
            &formats.colour_targets(None, true),
        );
        let mut no_depth_test = formats.depth_test(false);
        no_depth_test.depth_compare = Some(wgpu::CompareFunction::Always);
        let symbol = kit.make(
            "traffic symbols",
            "symbol_vs",
            "symbol_fs",
            &[],
            no_depth_test.clone(),
            &formats.colour_targets(blend, true),
        );
        let leader = kit.make(
            "traffic label leaders",
            "leader_vs",
            "leader_fs",
            &[],
            no_depth_test.clone(),
            &formats.colour_targets(blend, false),
        );
        let glyph = kit.make(
            "traffic label glyphs",
            "glyph_vs",
            "glyph_fs",
            &[],
            no_depth_test,
            &formats.colour_targets(blend, false),
        );
        let (atlas, atlas_sampler, atlas_glyphs) = upload_atlas(frame, text);
        let mut vertices = Vec::new();
        let mut model_ranges: [Range<u32>; 4] = Default::default();
        for (k, mesh) in meshes.iter().enumerate() {
            let start = vertices.len() as u32;
            vertices.extend(mesh.positions.iter().zip(&mesh.normals).enumerate().map(
                |(i, (&position, &normal))| ModelVertex {
                    position,
                    normal,
                    accent: u32::from(mesh.accents.get(i).copied().unwrap_or(0)),
                },
            ));
            model_ranges[k] = start..vertices.len() as u32;
        }
        let models = buffer(
            device,
            "traffic models",
            (vertices.len() * size_of::<ModelVertex>()) as u64,
            wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        );
        frame
            .queue()
            .write_buffer(&models, 0, bytemuck::cast_slice(&vertices));
        let storage_usage = wgpu::BufferUsages::STORAGE;
        Self {
            trail,
            model,
            symbol,
            leader,
            glyph,
            atlas,
            atlas_sampler,
            atlas_glyphs,
            label_style: buffer(
                device,
                "traffic label style",
                size_of::<LabelStyle>() as u64,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            ),
            labels: Growing::new(device, "traffic labels", storage_usage, 48 * 256),
            glyphs: Growing::new(device, "traffic label glyphs", storage_usage, 16 * 4096),
            label_count: 0,
            glyph_count: 0,
            layout,
            uniforms: buffer(
                device,
                "traffic uniforms",
                size_of::<Uniforms>() as u64,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            ),
            aircraft: Growing::new(device, "traffic aircraft", storage_usage, 64 * 256),
            trail_points: Growing::new(device, "traffic trail points", storage_usage, 16 * 4096),
            models,
            model_ranges,
            instances: Growing::new(
                device,
                "traffic model instances",
                wgpu::BufferUsages::VERTEX,
                4096,
            ),
            instance_ranges: Default::default(),
            trail_instances: Growing::new(
                device,
                "traffic trail instances",
                wgpu::BufferUsages::VERTEX,
                4096,
            ),
            trail_ranges: Default::default(),
            bind_group: None,
            slots: 0,
        }
    }

    /// GPU bytes held.
    pub(crate) fn gpu_bytes(&self) -> u64 {
        self.aircraft.buffer.size()
            + self.trail_points.buffer.size()
            + self.models.size()
            + self.instances.buffer.size()
            + self.trail_instances.buffer.size()
            + self.labels.buffer.size()
            + self.glyphs.buffer.size()
            + self.atlas_glyphs.size()
            + self.atlas.texture().size().width as u64 * self.atlas.texture().size().height as u64
            + self.uniforms.size()
    }

    /// Makes the trail buffer hold `points` (slots times points per slot); returns whether
    /// it was replaced (its contents are then to be uploaded whole).
    pub(crate) fn reserve_trails(&mut self, frame: &FrameContext<'_>, points: usize) -> bool {
        let bytes = (points.max(1) * 16) as u64;
        if bytes <= self.trail_points.buffer.size() {
            return false;
        }
        // Contents are rewritten whole by the caller: no copy needed.
        self.trail_points
            .write(frame.device(), frame.queue(), &vec![0u8; bytes as usize]);
        true
    }

    /// Uploads trail points `range` (indices of points) from `all`.
    pub(crate) fn upload_trails(
        &self,
        frame: &FrameContext<'_>,
        all: &[[f32; 4]],
        range: Range<usize>,
    ) {
        let end = range.end.min(all.len());
        if range.start >= end {
            return;
        }
        frame.queue().write_buffer(
            &self.trail_points.buffer,
            (range.start * 16) as u64,
            bytemuck::cast_slice(&all[range.start..end]),
        );
    }

    /// Writes the frame's labels and their glyphs.
    pub(crate) fn write_labels(
        &mut self,
        frame: &FrameContext<'_>,
        style: &LabelStyle,
        labels: &[LabelGpu],
        glyphs: &[GlyphInstance],
    ) {
        let (device, queue) = (frame.device(), frame.queue());
        queue.write_buffer(&self.label_style, 0, bytemuck::bytes_of(style));
        self.labels
            .write(device, queue, bytemuck::cast_slice(labels));
        self.glyphs
            .write(device, queue, bytemuck::cast_slice(glyphs));
        self.label_count = labels.len() as u32;
        self.glyph_count = glyphs.len() as u32;
    }

    /// Writes the frame's uniforms, aircraft and model instances, and (re)makes the bind
    /// group when a buffer or the depth texture changed.
    pub(crate) fn write_frame(
        &mut self,
        frame: &FrameContext<'_>,
        uniforms: &Uniforms,
        aircraft: &[AircraftGpu],
        instances: &[Vec<u32>; 4],
        trails: &[(Vec<u32>, u32); 3],
    ) {
        let (device, queue) = (frame.device(), frame.queue());
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(uniforms));
        self.aircraft
            .write(device, queue, bytemuck::cast_slice(aircraft));
        let mut flat = Vec::with_capacity(instances.iter().map(Vec::len).sum());
        for (k, list) in instances.iter().enumerate() {
            let start = flat.len() as u32;
            flat.extend_from_slice(list);
            self.instance_ranges[k] = start..flat.len() as u32;
        }
        self.instances
            .write(device, queue, bytemuck::cast_slice(&flat));
        flat.clear();
        for (k, (list, segments)) in trails.iter().enumerate() {
            let start = flat.len() as u32;
            flat.extend_from_slice(list);
            self.trail_ranges[k] = (start..flat.len() as u32, *segments);
        }
        self.trail_instances
            .write(device, queue, bytemuck::cast_slice(&flat));
        self.slots = aircraft.len() as u32;
        let depth = frame.terrain_depth();
        let sizes = [
            self.aircraft.buffer.size(),
            self.trail_points.buffer.size(),
            self.labels.buffer.size(),
            self.glyphs.buffer.size(),
        ];
        if self
            .bind_group
            .as_ref()
            .is_none_or(|(_, s, view)| *s != sizes || view != depth)
        {
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("traffic"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: self.uniforms.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: self.aircraft.buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: self.trail_points.buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: wgpu::BindingResource::TextureView(depth),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: wgpu::BindingResource::TextureView(&self.atlas),
                    },
                    wgpu::BindGroupEntry {
                        binding: 5,
                        resource: wgpu::BindingResource::Sampler(&self.atlas_sampler),
                    },
                    wgpu::BindGroupEntry {
                        binding: 6,
                        resource: self.atlas_glyphs.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 7,
                        resource: self.labels.buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 8,
                        resource: self.glyphs.buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 9,
                        resource: self.label_style.as_entire_binding(),
                    },
                ],
            });
            self.bind_group = Some((group, sizes, depth.clone()));
        }
    }

    /// Trails then models: the world pass. Returns the draw calls.
    pub(crate) fn draw_world(&self, pass: &mut wgpu::RenderPass<'_>) -> u32 {
        let Some((group, _, _)) = &self.bind_group else {
            return 0;
        };
        if self.slots == 0 {
            return 0;
        }
        let mut calls = 0;
        pass.set_bind_group(0, group, &[]);
        if self.trail_ranges.iter().any(|(r, _)| !r.is_empty()) {
            pass.set_pipeline(&self.trail);
            for (r, segments) in &self.trail_ranges {
                if r.is_empty() {
                    continue;
                }
                pass.set_vertex_buffer(0, instance_slice(&self.trail_instances, r));
                pass.draw(0..segments * 6, 0..r.end - r.start);
                calls += 1;
            }
        }
        if self.instance_ranges.iter().any(|r| !r.is_empty()) {
            pass.set_pipeline(&self.model);
            pass.set_vertex_buffer(0, self.models.slice(..));
            for (k, r) in self.instance_ranges.iter().enumerate() {
                if r.is_empty() {
                    continue;
                }
                // The kind's instances as the instance buffer itself (no first-instance
                // feature needed).
                pass.set_vertex_buffer(1, instance_slice(&self.instances, r));
                pass.draw(self.model_ranges[k].clone(), 0..r.end - r.start);
                calls += 1;
            }
        }
        calls
    }

    /// Symbols, then labels' leaders and glyphs: the screen-aligned pass. Returns the draw
    /// calls.
    pub(crate) fn draw_symbols(&self, pass: &mut wgpu::RenderPass<'_>) -> u32 {
        let Some((group, _, _)) = &self.bind_group else {
            return 0;
        };
        if self.slots == 0 {
            return 0;
        }
        pass.set_bind_group(0, group, &[]);
        pass.set_pipeline(&self.symbol);
        pass.draw(0..self.slots * 6, 0..1);
        let mut calls = 1;
        if self.label_count > 0 {
            pass.set_pipeline(&self.leader);
            pass.draw(0..self.label_count * 6, 0..1);
            calls += 1;
        }
        if self.glyph_count > 0 {
            pass.set_pipeline(&self.glyph);
            pass.draw(0..self.glyph_count * 6, 0..1);
            calls += 1;
        }
        calls
    }
}

/// A range of u32 instances as a vertex buffer of their own (so draws need no first-instance
/// feature).
fn instance_slice<'a>(buffer: &'a Growing, r: &Range<u32>) -> wgpu::BufferSlice<'a> {
    buffer
        .buffer
        .slice(u64::from(r.start) * 4..u64::from(r.end) * 4)
}

/// The glyph atlas as a texture, its sampler and its glyph table.
fn upload_atlas(
    frame: &FrameContext<'_>,
    text: &GlyphAtlas,
) -> (wgpu::TextureView, wgpu::Sampler, wgpu::Buffer) {
    let device = frame.device();
    let size = wgpu::Extent3d {
        width: text.size[0],
        height: text.size[1],
        depth_or_array_layers: 1,
    };
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("traffic glyph atlas"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::R8Unorm,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    frame.queue().write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: &texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        &text.texels,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(text.size[0]),
            rows_per_image: Some(text.size[1]),
        },
        size,
    );
    let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("traffic glyph atlas"),
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        ..Default::default()
    });
    let table: Vec<GlyphGpu> = text
        .glyphs
        .iter()
        .map(|g| GlyphGpu {
            rect: g.rect.map(|v| v as f32),
            offset: g.offset,
            spare: [0.0; 2],
        })
        .collect();
    let glyphs = buffer(
        device,
        "traffic glyph table",
        (table.len() * size_of::<GlyphGpu>()) as u64,
        wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
    );
    frame
        .queue()
        .write_buffer(&glyphs, 0, bytemuck::cast_slice(&table));
    (
        texture.create_view(&wgpu::TextureViewDescriptor::default()),
        sampler,
        glyphs,
    )
}
