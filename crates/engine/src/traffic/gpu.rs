//! The traffic layer's GPU side: one storage buffer of aircraft (rewritten every frame: the
//! interpolated positions change), one of trail points mirroring the fleet's ring buffers
//! (only written points are uploaded, in pages), the built-in models' vertex buffer, and
//! three pipelines: trails and models in the world pass, symbols in the screen-aligned pass.
//! Trails are one draw per length bucket, symbols one, models one per kind and level of
//! detail drawn this frame (the full mesh from 64 px, its clustered coarse level below).

use std::mem::size_of;
use std::ops::Range;

use bytemuck::{Pod, Zeroable};

use super::models::{MODEL_LOD_CELLS, ModelMesh};
use crate::gpu_util::{Growing, Pipelines, buffer, buffer_entry, texture_entry};
use crate::labels::gpu::{GlyphInstance, LabelDrawer, LabelGpu};
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

/// Model vertex (24 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct ModelVertex {
    position: [f32; 3],
    normal: [f32; 3],
    accent: u32,
}

/// Levels of detail of each model: the mesh, and its clustered coarse level.
pub(crate) const MODEL_LODS: usize = 2;
/// Model draws at most: one per kind and level.
pub(crate) const MODEL_DRAWS: usize = 4 * MODEL_LODS;

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
    labels: LabelDrawer,
    layout: wgpu::BindGroupLayout,
    uniforms: wgpu::Buffer,
    aircraft: Growing,
    trail_points: Growing,
    models: wgpu::Buffer,
    /// Vertex range of each kind's model in `models`, per level of detail (index
    /// `kind * MODEL_LODS + level`: 0 full, 1 coarse).
    model_ranges: [Range<u32>; MODEL_DRAWS],
    instances: Growing,
    /// Instance range of each kind and level this frame (into `instances`).
    instance_ranges: [Range<u32>; MODEL_DRAWS],
    trail_instances: Growing,
    /// Instance range and segments per instance of each trail bucket this frame.
    trail_ranges: [(Range<u32>, u32); 3],
    bind_group: Option<(wgpu::BindGroup, [u64; 2], wgpu::TextureView)>,
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
                // The terrain's depth: symbols test it per fragment.
                texture_entry(3, false, wgpu::TextureViewDimension::D2),
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
        let mut vertices = Vec::new();
        let mut model_ranges: [Range<u32>; MODEL_DRAWS] = Default::default();
        let levels = meshes
            .iter()
            .flat_map(|m| [m.clone(), m.simplified(MODEL_LOD_CELLS)]);
        for (k, mesh) in levels.enumerate() {
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
            labels: LabelDrawer::new(frame, text, "traffic labels"),
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
            + self.labels.gpu_bytes()
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

    /// Writes the frame's labels and their glyphs, laid out at `text_px` pixels per line.
    pub(crate) fn write_labels(
        &mut self,
        frame: &FrameContext<'_>,
        text_px: f32,
        tolerance: f32,
        labels: &[LabelGpu],
        glyphs: &[GlyphInstance],
    ) {
        self.labels.write(frame, text_px, tolerance, labels, glyphs);
    }

    /// Writes the frame's uniforms, aircraft and model instances, and (re)makes the bind
    /// group when a buffer or the depth texture changed.
    pub(crate) fn write_frame(
        &mut self,
        frame: &FrameContext<'_>,
        uniforms: &Uniforms,
        aircraft: &[AircraftGpu],
        instances: &[Vec<u32>; MODEL_DRAWS],
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
        let sizes = [self.aircraft.buffer.size(), self.trail_points.buffer.size()];
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
        1 + self.labels.draw(pass)
    }
}

/// A range of u32 instances as a vertex buffer of their own (so draws need no first-instance
/// feature).
fn instance_slice<'a>(buffer: &'a Growing, r: &Range<u32>) -> wgpu::BufferSlice<'a> {
    buffer
        .buffer
        .slice(u64::from(r.start) * 4..u64::from(r.end) * 4)
}
