//! Drawing placed labels: one storage buffer of labels (a box at a pixel position, its
//! object's depth, opacity, colour) and one of glyphs (an atlas glyph at a place in a
//! label), drawn as two instanced draws in the screen-aligned pass, leaders then glyphs
//! (Kaiser 5.3: one instanced label shader for all). The traffic layer's data blocks and the
//! vector layer's point names both go through it.

use std::mem::size_of;

use bytemuck::{Pod, Zeroable};

use std::time::Instant;

use crate::gpu_util::{Growing, Pipelines, buffer, buffer_entry, texture_entry};
use crate::labels::{LabelPlacer, LabelRequest, PlacedLabel};
use crate::overlay::FrameContext;
use crate::text::GlyphAtlas;

/// A placed label as the shaders read it (48 bytes); mirrored in `labels.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct LabelGpu {
    /// The object on screen (pixels), its reversed-Z depth (0: never hidden by terrain), the
    /// label's opacity.
    pub anchor: [f32; 2],
    pub depth: f32,
    pub opacity: f32,
    /// The box's top-left and size, pixels.
    pub origin: [f32; 2],
    pub size: [f32; 2],
    /// Text colour (sRGB, packed) and where the leader starts from the anchor (pixels;
    /// negative: no leader).
    pub colour: u32,
    pub clearance: f32,
    /// Pixels per atlas pixel of this label's text (0: the frame's).
    pub scale: f32,
    pub spare: f32,
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

/// Per-frame constants; mirrored in `labels.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct LabelFrame {
    viewport: [f32; 4],
    /// Pixels per atlas pixel, atlas size, halo width in field units at 1 pixel per atlas
    /// pixel.
    scale: [f32; 4],
    /// Depth tolerance (fraction).
    params: [f32; 4],
}

/// One overlay's labels from requests to GPU rows: what a frame asks for and places, and
/// the placer that remembers corners and fades between frames.
#[derive(Default)]
pub(crate) struct LabelBatch {
    placer: Option<LabelPlacer>,
    /// This frame's requests.
    pub requests: Vec<LabelRequest>,
    /// Per request: the caller's item (a slot, a point) and its object's depth.
    pub items: Vec<(u32, f32)>,
    /// Boxes labels keep off (the objects' symbols).
    pub obstacles: Vec<[f32; 4]>,
    /// This frame's placed labels.
    pub placed: Vec<PlacedLabel>,
    /// What the GPU draws of them.
    pub rows: Vec<LabelGpu>,
    pub glyphs: Vec<GlyphInstance>,
    last_prepare: Option<Instant>,
}

impl LabelBatch {
    /// Starts a frame: no requests, obstacles or rows yet.
    pub(crate) fn begin(&mut self) {
        self.requests.clear();
        self.items.clear();
        self.obstacles.clear();
        self.rows.clear();
        self.glyphs.clear();
    }

    /// Asks for a label for `item` (its object at `depth`), keeping other labels off the
    /// object's symbol `obstacle`.
    pub(crate) fn request(
        &mut self,
        request: LabelRequest,
        item: u32,
        depth: f32,
        obstacle: [f32; 4],
    ) {
        self.requests.push(request);
        self.items.push((item, depth));
        self.obstacles.push(obstacle);
    }

    /// Claims the objects' symbols ([`LabelBatch::obstacles`]) on the frame's screen, so
    /// every overlay's labels keep off them ([`FrameContext::claim_screen_boxes`]).
    pub(crate) fn claim_symbols(&self, frame: &FrameContext<'_>) {
        frame.claim_screen_boxes(self.obstacles.iter().copied());
    }

    /// Places the requests on the frame's screen, fading over `fade_s`, clear of every
    /// symbol and of the labels placed before ([`FrameContext::screen_boxes`]), then claims
    /// its labels for the overlays after. The first frame shows its labels at once (a still
    /// picture must not be caught mid-fade); later ones fade by the time between frames.
    pub(crate) fn place(&mut self, frame: &FrameContext<'_>, fade_s: f32) {
        let now = Instant::now();
        let dt = self
            .last_prepare
            .replace(now)
            .map_or(f32::INFINITY, |t| (now - t).as_secs_f32());
        let (w, h) = frame.camera().viewport_px();
        // Its own symbols are among the frame's boxes already.
        let own = std::mem::replace(&mut self.obstacles, frame.screen_boxes());
        let placer = self.placer.get_or_insert_with(|| LabelPlacer::new(fade_s));
        placer.place(
            &self.requests,
            &self.obstacles,
            [w as f32, h as f32],
            dt,
            &mut self.placed,
        );
        self.obstacles = own;
        frame.claim_screen_boxes(self.placed.iter().map(|p| p.bounds));
    }

    /// Adds a placed label's row and its glyphs (atlas glyph, top-left from the text's
    /// top-left), the text `pad_px` inside the box.
    pub(crate) fn push_row(&mut self, row: LabelGpu, glyphs: &[(u16, [f32; 2])], pad_px: f32) {
        let index = self.rows.len() as u32;
        self.rows.push(row);
        self.glyphs
            .extend(glyphs.iter().map(|&(g, [x, y])| GlyphInstance {
                label: index,
                glyph: u32::from(g),
                at: [x + pad_px, y + pad_px],
            }));
    }

    /// Forgets the last frame (the next placement starts afresh, without fades).
    pub(crate) fn reset(&mut self) {
        self.begin();
        self.placed.clear();
        self.last_prepare = None;
    }
}

/// The shader.
pub const SHADER: &str = concat!(
    include_str!("../overlay_common.wgsl"),
    include_str!("labels.wgsl")
);

/// The GPU side of a set of labels (see the module documentation).
pub(crate) struct LabelDrawer {
    leader: wgpu::RenderPipeline,
    glyph: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    uniforms: wgpu::Buffer,
    atlas: wgpu::TextureView,
    atlas_sampler: wgpu::Sampler,
    atlas_glyphs: wgpu::Buffer,
    atlas_size: [u32; 2],
    line_height: f32,
    labels: Growing,
    glyphs: Growing,
    label_count: u32,
    glyph_count: u32,
    bind_group: Option<(wgpu::BindGroup, [u64; 2], wgpu::TextureView)>,
}

impl LabelDrawer {
    /// Pipelines and the atlas on the GPU; `name` labels the GPU objects.
    pub(crate) fn new(frame: &FrameContext<'_>, text: &GlyphAtlas, name: &'static str) -> Self {
        let device = frame.device();
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(name),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        use wgpu::ShaderStages as Stage;
        let storage = wgpu::BufferBindingType::Storage { read_only: true };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(name),
            entries: &[
                buffer_entry(0, Stage::VERTEX_FRAGMENT, wgpu::BufferBindingType::Uniform),
                // The terrain's depth: labels of hidden objects go, in the vertex stage.
                wgpu::BindGroupLayoutEntry {
                    visibility: Stage::VERTEX,
                    ..texture_entry(1, false, wgpu::TextureViewDimension::D2)
                },
                texture_entry(2, true, wgpu::TextureViewDimension::D2),
                wgpu::BindGroupLayoutEntry {
                    binding: 3,
                    visibility: Stage::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
                buffer_entry(4, Stage::VERTEX, storage),
                buffer_entry(5, Stage::VERTEX, storage),
                buffer_entry(6, Stage::VERTEX, storage),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(name),
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
        let mut no_depth_test = formats.depth_test(false);
        no_depth_test.depth_compare = Some(wgpu::CompareFunction::Always);
        let leader = kit.make(
            name,
            "leader_vs",
            "leader_fs",
            &[],
            no_depth_test.clone(),
            &formats.colour_targets(blend, false),
        );
        let glyph = kit.make(
            name,
            "glyph_vs",
            "glyph_fs",
            &[],
            no_depth_test,
            &formats.colour_targets(blend, false),
        );
        let (atlas, atlas_sampler, atlas_glyphs) = upload_atlas(frame, text, name);
        let storage_usage = wgpu::BufferUsages::STORAGE;
        Self {
            leader,
            glyph,
            layout,
            uniforms: buffer(
                device,
                name,
                size_of::<LabelFrame>() as u64,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            ),
            atlas,
            atlas_sampler,
            atlas_glyphs,
            atlas_size: text.size,
            line_height: text.line_height,
            labels: Growing::new(device, name, storage_usage, 48 * 256),
            glyphs: Growing::new(device, name, storage_usage, 16 * 4096),
            label_count: 0,
            glyph_count: 0,
            bind_group: None,
        }
    }

    /// GPU bytes held.
    pub(crate) fn gpu_bytes(&self) -> u64 {
        self.labels.buffer.size()
            + self.glyphs.buffer.size()
            + self.atlas_glyphs.size()
            + u64::from(self.atlas_size[0]) * u64::from(self.atlas_size[1])
            + self.uniforms.size()
    }

    /// Pixels per atlas pixel of text `text_px` pixels per line ([`LabelGpu::scale`]).
    pub(crate) fn scale_for(&self, text_px: f32) -> f32 {
        text_px / self.line_height
    }

    /// Writes the frame's labels and glyphs, laid out at `text_px` pixels per line (unless
    /// a label says otherwise);
    /// `tolerance` is how much nearer than an object's depth the terrain may be before its
    /// label goes (fraction of the depth).
    pub(crate) fn write(
        &mut self,
        frame: &FrameContext<'_>,
        text_px: f32,
        tolerance: f32,
        labels: &[LabelGpu],
        glyphs: &[GlyphInstance],
    ) {
        let (device, queue) = (frame.device(), frame.queue());
        let (w, h) = frame.camera().viewport_px();
        let (w, h) = (w.max(1) as f32, h.max(1) as f32);
        let scale = self.scale_for(text_px);
        // A halo 1.5 pixels wide, in the field's units (255ths per SPREAD_PX atlas pixels),
        // at one pixel per atlas pixel (the shader divides by each label's scale).
        let halo = 1.5 * 127.0 / (255.0 * crate::text::SPREAD_PX);
        let uniforms = LabelFrame {
            viewport: [w, h, 1.0 / w, 1.0 / h],
            scale: [
                scale,
                self.atlas_size[0] as f32,
                self.atlas_size[1] as f32,
                halo,
            ],
            params: [tolerance, 0.0, 0.0, 0.0],
        };
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&uniforms));
        self.labels
            .write(device, queue, bytemuck::cast_slice(labels));
        self.glyphs
            .write(device, queue, bytemuck::cast_slice(glyphs));
        self.label_count = labels.len() as u32;
        self.glyph_count = glyphs.len() as u32;
        let depth = frame.terrain_depth();
        let sizes = [self.labels.buffer.size(), self.glyphs.buffer.size()];
        if self
            .bind_group
            .as_ref()
            .is_none_or(|(_, s, view)| *s != sizes || view != depth)
        {
            let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("labels"),
                layout: &self.layout,
                entries: &[
                    entry(0, self.uniforms.as_entire_binding()),
                    entry(1, wgpu::BindingResource::TextureView(depth)),
                    entry(2, wgpu::BindingResource::TextureView(&self.atlas)),
                    entry(3, wgpu::BindingResource::Sampler(&self.atlas_sampler)),
                    entry(4, self.atlas_glyphs.as_entire_binding()),
                    entry(5, self.labels.buffer.as_entire_binding()),
                    entry(6, self.glyphs.buffer.as_entire_binding()),
                ],
            });
            self.bind_group = Some((group, sizes, depth.clone()));
        }
    }

    /// Draws calls this frame's labels take (0 or 2).
    pub(crate) fn draw_calls(&self) -> u32 {
        2 * u32::from(self.label_count > 0)
    }

    /// Leaders, then glyphs. Returns the draw calls.
    pub(crate) fn draw(&self, pass: &mut wgpu::RenderPass<'_>) -> u32 {
        let Some((group, _, _)) = &self.bind_group else {
            return 0;
        };
        if self.label_count == 0 {
            return 0;
        }
        pass.set_bind_group(0, group, &[]);
        pass.set_pipeline(&self.leader);
        pass.draw(0..self.label_count * 6, 0..1);
        let mut calls = 1;
        if self.glyph_count > 0 {
            pass.set_pipeline(&self.glyph);
            pass.draw(0..self.glyph_count * 6, 0..1);
            calls += 1;
        }
        calls
    }
}

/// The glyph atlas as a texture, its sampler and its glyph table.
fn upload_atlas(
    frame: &FrameContext<'_>,
    text: &GlyphAtlas,
    name: &'static str,
) -> (wgpu::TextureView, wgpu::Sampler, wgpu::Buffer) {
    let device = frame.device();
    let size = wgpu::Extent3d {
        width: text.size[0],
        height: text.size[1],
        depth_or_array_layers: 1,
    };
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some(name),
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
        label: Some(name),
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
        name,
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
