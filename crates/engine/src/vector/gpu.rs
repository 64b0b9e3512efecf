//! The vector overlay's GPU side: two pipelines (fills; lines and points as screen-space
//! quads, a segment reading its neighbours for its joins) drawing from a pool that mirrors
//! the CPU pieces.
//!
//! The pool holds, per *entry* (a drawn tile's draped pieces, or one chunk of a feature's
//! geometry at altitude), a range of the line buffer (a storage buffer the vertex shader
//! indexes by `vertex_index / 6`, so ranges need no first-instance feature) and a range of
//! the fill vertex buffer, sub-allocated first fit, plus an anchor slot. An entry is
//! uploaded once; a frame whose entries changed rewrites only the two indirect argument
//! lists (one record per drawn entry, or per run of its drawn quadrants: a tile's draped
//! pieces are stored quadrant by quadrant, and a tile drawn in part beside finer children
//! draws only its drawn quadrants' pieces) and uploads the new entries; every frame writes the
//! anchors' offsets from the eye. Everything is drawn with two `multi_draw_indirect` calls.
//! Buffers grow by doubling, copied on the GPU, so ranges stay valid, up to the device's
//! limits (a storage buffer no larger than one binding may see) and the layer's GPU budget:
//! an entry that does not fit is refused, and the layer makes room by dropping entries not
//! drawn this frame, or leaves it out.

use std::mem::size_of;
use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use globus_geo::DVec3;
use globus_render::RangeAllocator;
use globus_tiling::{Quadrants, TileKey};
use globus_vector::{LineCap, LineJoin, Rgba};
use rustc_hash::FxHashMap;

use crate::gpu_util::{Growing, Pipelines, buffer, buffer_entry, texture_entry};
use crate::overlay::FrameContext;

/// How much nearer than its depth a draped fill is tested, as a fraction of its depth: it
/// lies on the terrain's own triangles, so only rounding separates them (1 cm at 1 km).
const FILL_TOLERANCE: f32 = 1.0e-5;
/// The same for a line's centre against the four terrain texels around it.
const LINE_TOLERANCE: f32 = 1.0e-4;

/// One line segment or point symbol (80 bytes).
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
    /// Low 16 bits: a point's icon, its layer in the icon array plus one (0: none); high 16
    /// bits: a segment's [`line_flags`].
    pub icon_flags: u32,
    /// Metres along the line at `a` and `b`, less a multiple of [`ALONG_PERIOD_M`] (dashes).
    pub along: [f32; 2],
    /// Dash pattern, pixels, one per byte (dash, gap, dash, gap); 0: solid.
    pub dash: u32,
    /// Morph heights at `a` and `b` (draped on a tile growing out of its parent: metres
    /// along the body's normal to the parent's surface; see `globus_vector::SurfacePoint`).
    pub lift: [f32; 2],
    /// Pads to WGSL's 16-byte struct alignment.
    pub pad: [f32; 2],
}

/// Bits of [`LineInstance::icon_flags`] (from bit 16) saying how a segment meets its
/// neighbours; mirrored in `vector.wgsl`.
pub(crate) mod line_flags {
    /// The record before this one continues the line into this segment's start.
    pub const JOINED_PREV: u32 = 1 << 16;
    /// The record after this one continues the line from this segment's end.
    pub const JOINED_NEXT: u32 = 1 << 17;
    /// The start is the line's own start (drawn with its cap).
    pub const START: u32 = 1 << 18;
    /// The end is the line's own end.
    pub const END: u32 = 1 << 19;
    /// Join: bits 20-21 (0 round, 1 miter, 2 bevel).
    pub const JOIN_SHIFT: u32 = 20;
    /// Cap: bits 22-23 (0 round, 1 butt, 2 square).
    pub const CAP_SHIFT: u32 = 22;
    /// The line continues from this segment's start in a record drawn apart, whose end
    /// meets this start exactly (a draped line crossing a tile's midline into the next
    /// quadrant's pieces): cut square there, so the two abut without overlapping (a
    /// translucent line would show round ends overlapping as a darker dot).
    pub const SEAM_PREV: u32 = 1 << 24;
    /// The same at this segment's end.
    pub const SEAM_NEXT: u32 = 1 << 25;
}

/// Distances along lines are stored modulo this (2^21 m): every power-of-two dash period up
/// to it repeats within it, so dash phases stay continuous, and f32 keeps 0.125 m of
/// precision however long the line (a route across the world).
pub(crate) const ALONG_PERIOD_M: f64 = 2_097_152.0;

fn f32x3(p: DVec3) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

/// How a line is drawn, per segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct LineLook {
    pub colour: Rgba,
    pub width_px: f32,
    pub join: LineJoin,
    pub cap: LineCap,
    /// Packed dash pattern (0: solid).
    pub dash: u32,
}

impl LineLook {
    /// How `style` strokes lines.
    pub(crate) fn of(style: &globus_vector::Style) -> Self {
        Self {
            colour: style.stroke,
            width_px: style.stroke_width_px,
            join: style.line_join,
            cap: style.line_cap,
            dash: style.dash_px.map_or(0, u32::from_le_bytes),
        }
    }

    fn style_bits(&self) -> u32 {
        let join = match self.join {
            LineJoin::Round => 0,
            LineJoin::Miter => 1,
            LineJoin::Bevel => 2,
        };
        let cap = match self.cap {
            LineCap::Round => 0,
            LineCap::Butt => 1,
            LineCap::Square => 2,
        };
        (join << line_flags::JOIN_SHIFT) | (cap << line_flags::CAP_SHIFT)
    }
}

/// How a run of a line's segments ends at either side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum RunEnd {
    /// The line's own start or end: capped.
    Line,
    /// The line goes on in a run drawn apart whose end meets this one (a draped line
    /// crossing a tile's midline, or its border, where the neighbour's run starts at the same
    /// point of the border; a neighbour of another level keeps the line's vertices to its
    /// own sub-pixel tolerance): cut square, abutting it.
    Seam,
    /// The line goes on elsewhere, not necessarily meeting this end (where the vertices a
    /// tile keeps leave a gap, or a chunk at altitude ends): drawn round.
    Break,
}

/// Appends the segments of a polyline run (`pts`, metres along the line `along`) to `out`,
/// joined to each other, its two ends as `ends` say. `lifts`: the points' morph heights when
/// draped (empty: none).
pub(crate) fn push_run(
    out: &mut Vec<LineInstance>,
    pts: &[DVec3],
    along: &[f64],
    lifts: &[f64],
    id: u32,
    look: &LineLook,
    (start, end): (RunEnd, RunEnd),
) {
    let lift = |i: usize| lifts.get(i).map_or(0.0, |&l| l as f32);
    let n = pts.len().saturating_sub(1);
    for i in 0..n {
        let mut flags = look.style_bits();
        flags |= if i > 0 {
            line_flags::JOINED_PREV
        } else {
            match start {
                RunEnd::Line => line_flags::START,
                RunEnd::Seam => line_flags::SEAM_PREV,
                RunEnd::Break => 0,
            }
        };
        flags |= if i + 1 < n {
            line_flags::JOINED_NEXT
        } else {
            match end {
                RunEnd::Line => line_flags::END,
                RunEnd::Seam => line_flags::SEAM_NEXT,
                RunEnd::Break => 0,
            }
        };
        let a = along[i].rem_euclid(ALONG_PERIOD_M);
        let b = a + (along[i + 1] - along[i]);
        out.push(LineInstance {
            icon_flags: flags,
            along: [a as f32, b as f32],
            dash: look.dash,
            lift: [lift(i), lift(i + 1)],
            ..LineInstance::segment(pts[i], pts[i + 1], id, look.colour, look.width_px)
        });
    }
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
            icon_flags: 0,
            along: [0.0; 2],
            dash: 0,
            lift: [0.0; 2],
            pad: [0.0; 2],
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
            icon_flags: 0,
            along: [0.0; 2],
            dash: 0,
            lift: [0.0; 2],
            pad: [0.0; 2],
        }
    }

    /// The point lifted by `lift_m` with the terrain under it (see [`LineInstance::lift`]).
    pub(crate) fn lifted(self, lift_m: f64) -> Self {
        Self {
            lift: [lift_m as f32; 2],
            ..self
        }
    }

    /// The point drawn with icon `icon` (layer plus one; 0 keeps the symbol).
    pub(crate) fn with_icon(self, icon: u32) -> Self {
        Self {
            icon_flags: icon & 0xffff,
            ..self
        }
    }
}

/// Side of an icon in the icon array, texels.
pub(crate) const ICON_SIZE: u32 = 64;

/// One fill vertex (28 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub(crate) struct FillVertex {
    pub position: [f32; 3],
    pub anchor: u32,
    pub colour: u32,
    pub id: u32,
    /// Morph height (see [`LineInstance::lift`]).
    pub lift: f32,
}

impl FillVertex {
    pub(crate) fn new(p: DVec3, anchor: u32, colour: Rgba, id: u32, draped: bool) -> Self {
        // The draped flag rides in the anchor's top bit (anchors stay far below 2^31).
        Self {
            position: f32x3(p),
            anchor: anchor | if draped { DRAPED_BIT } else { 0 },
            colour: colour.packed(),
            id,
            lift: 0.0,
        }
    }

    /// The vertex lifted by `lift_m` with the terrain under it.
    pub(crate) fn lifted(self, lift_m: f64) -> Self {
        Self {
            lift: lift_m as f32,
            ..self
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
    /// The eye in ECEF (f32: for directions only) and the body's squared eccentricity.
    eye: [f32; 4],
}

/// What an entry of the pool is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum EntryKey {
    /// A drawn tile's draped pieces.
    Tile(TileKey),
    /// Chunk `1` of feature `0`'s geometry at altitude.
    Chunk(u32, u32),
}

/// An entry on the GPU.
#[derive(Clone, Debug)]
struct Resident {
    slot: u32,
    lines: Range<u32>,
    fills: Range<u32>,
    /// Where each quadrant's line instances and fill vertices end, counted from the start
    /// of the entry's ranges ([`QuadrantEnds`]).
    ends: QuadrantEnds,
}

/// Where each of an entry's four quadrants ends in its line instances and in its fill
/// vertices (quadrant `q` spans from the end of `q - 1`, or 0, to the end of `q`): an entry
/// whose pieces are not split by quadrant (a chunk at altitude) ends every quadrant at its
/// last piece.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct QuadrantEnds {
    pub lines: [u32; 4],
    pub fills: [u32; 4],
}

impl QuadrantEnds {
    /// All pieces in one block.
    pub(crate) fn whole(lines: usize, fills: usize) -> Self {
        Self {
            lines: [lines as u32; 4],
            fills: [fills as u32; 4],
        }
    }

    /// The ranges (relative to the entry's start) that draw `parts`, touching ones merged
    /// (at most two per kind) and empty ones left out.
    fn ranges(ends: &[u32; 4], parts: Quadrants, f: impl FnMut(Range<u32>)) {
        let quadrant = |q: usize| if q == 0 { 0 } else { ends[q - 1] }..ends[q];
        globus_tiling::merge_touching((0..4).filter(|&q| parts.contains(q)).map(quadrant), f);
    }
}

/// The layout `multi_draw_indirect` reads.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct DrawArgs {
    vertex_count: u32,
    instance_count: u32,
    first_vertex: u32,
    first_instance: u32,
}

/// First capacities: lines (instances) and fill vertices.
const FIRST_LINES: u32 = 1 << 14;
const FIRST_FILLS: u32 = 1 << 16;

/// Pipelines and the pool.
pub(crate) struct Gpu {
    fill: wgpu::RenderPipeline,
    line: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    uniforms: wgpu::Buffer,
    anchors: Growing,
    lines: Growing,
    fills: Growing,
    line_ranges: RangeAllocator,
    fill_ranges: RangeAllocator,
    entries: FxHashMap<EntryKey, Resident>,
    free_slots: Vec<u32>,
    slot_origins: Vec<DVec3>,
    drawn: Vec<EntryKey>,
    line_draws: Growing,
    fill_draws: Growing,
    line_draw_count: u32,
    fill_draw_count: u32,
    oit_draws: Growing,
    oit_draw_count: u32,
    volume_ids: wgpu::RenderPipeline,
    oit: Oit,
    bind_group: Option<(wgpu::BindGroup, [u64; 3], wgpu::TextureView)>,
    icons: wgpu::TextureView,
    icon_sampler: wgpu::Sampler,
    icon_count: u32,
    pub line_count: u32,
    pub fill_vertices: u32,
    /// Most line instances and fill vertices the buffers may hold (powers of two).
    line_limit: u32,
    fill_limit: u32,
}

/// The largest power of two at most `x` (0 for 0), as a `u32`.
fn pow2_at_most(x: u64) -> u32 {
    let x = x.min(u64::from(u32::MAX));
    if x == 0 {
        0
    } else {
        1 << (63 - x.leading_zeros())
    }
}

/// The shader.
pub const SHADER: &str = concat!(
    include_str!("../overlay_common.wgsl"),
    include_str!("vector.wgsl")
);

impl Gpu {
    pub(crate) fn new(frame: &FrameContext<'_>) -> Self {
        let device = frame.device();
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("vector"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        use wgpu::ShaderStages as Stage;
        let storage = wgpu::BufferBindingType::Storage { read_only: true };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vector"),
            entries: &[
                buffer_entry(0, Stage::VERTEX_FRAGMENT, wgpu::BufferBindingType::Uniform),
                buffer_entry(1, Stage::VERTEX, storage),
                texture_entry(2, false, wgpu::TextureViewDimension::D2),
                buffer_entry(3, Stage::VERTEX, storage),
                texture_entry(4, true, wgpu::TextureViewDimension::D2Array),
                wgpu::BindGroupLayoutEntry {
                    binding: 5,
                    visibility: Stage::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
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
        // Ids only (colour untouched): volumes' faces, so picking finds them.
        let mut id_targets = formats.colour_targets(None, true);
        if let Some(c) = id_targets[0].as_mut() {
            c.write_mask = wgpu::ColorWrites::empty();
        }
        let kit = Pipelines {
            device,
            layout: &pipeline_layout,
            module: &module,
        };
        let fill_attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32, 2 => Uint32, 3 => Uint32, 4 => Float32];
        let fill_buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: size_of::<FillVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &fill_attrs,
        })];
        let fill = kit.make(
            "vector fills",
            "fill_vs",
            "fill_fs",
            &fill_buffers,
            formats.depth_test(false),
            &targets,
        );
        let volume_ids = kit.make(
            "vector volume ids",
            "fill_vs",
            "fill_fs",
            &fill_buffers,
            formats.depth_test(false),
            &id_targets,
        );
        let mut no_depth_test = formats.depth_test(false);
        no_depth_test.depth_compare = Some(wgpu::CompareFunction::Always);
        let line = kit.make(
            "vector lines",
            "line_vs",
            "line_fs",
            &[],
            no_depth_test,
            &targets,
        );
        let uniforms = buffer(
            device,
            "vector uniforms",
            size_of::<Uniforms>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        let oit = Oit::new(device, &module, &layout, formats, &fill_attrs);
        let line_bytes = size_of::<LineInstance>() as u64;
        let fill_bytes = size_of::<FillVertex>() as u64;
        let icon_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("vector icons"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        Self {
            icons: icon_array(device, frame.queue(), &[]),
            icon_sampler,
            icon_count: 0,
            volume_ids,
            oit,
            oit_draws: Growing::new(
                device,
                "vector volume draws",
                wgpu::BufferUsages::INDIRECT,
                256,
            ),
            oit_draw_count: 0,
            fill,
            line,
            layout,
            uniforms,
            anchors: Growing::new(device, "vector anchors", wgpu::BufferUsages::STORAGE, 4096),
            lines: Growing::new(
                device,
                "vector lines",
                wgpu::BufferUsages::STORAGE,
                u64::from(FIRST_LINES) * line_bytes,
            ),
            fills: Growing::new(
                device,
                "vector fills",
                wgpu::BufferUsages::VERTEX,
                u64::from(FIRST_FILLS) * fill_bytes,
            ),
            line_ranges: RangeAllocator::new(FIRST_LINES),
            fill_ranges: RangeAllocator::new(FIRST_FILLS),
            entries: FxHashMap::default(),
            free_slots: Vec::new(),
            slot_origins: Vec::new(),
            drawn: Vec::new(),
            line_draws: Growing::new(
                device,
                "vector line draws",
                wgpu::BufferUsages::INDIRECT,
                256,
            ),
            fill_draws: Growing::new(
                device,
                "vector fill draws",
                wgpu::BufferUsages::INDIRECT,
                256,
            ),
            line_draw_count: 0,
            fill_draw_count: 0,
            bind_group: None,
            line_count: 0,
            fill_vertices: 0,
            line_limit: u32::MAX,
            fill_limit: u32::MAX,
        }
        .with_budget(device, u64::MAX)
    }

    /// Limits the line and fill buffers to half of `bytes` each (and to what the device
    /// allows); buffers already larger keep their size until entries leave.
    pub(crate) fn with_budget(mut self, device: &wgpu::Device, bytes: u64) -> Self {
        let limits = device.limits();
        let storage = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let line_bytes = size_of::<LineInstance>() as u64;
        let fill_bytes = size_of::<FillVertex>() as u64;
        self.line_limit = pow2_at_most(storage.min(bytes / 2) / line_bytes).max(FIRST_LINES);
        self.fill_limit =
            pow2_at_most(limits.max_buffer_size.min(bytes / 2) / fill_bytes).max(FIRST_FILLS);
        self
    }

    /// Replaces the icon array by `icons` (RGBA8, [`ICON_SIZE`] squared each), if their
    /// number changed.
    pub(crate) fn set_icons(&mut self, frame: &FrameContext<'_>, icons: &[Vec<u8>]) {
        if icons.len() as u32 == self.icon_count {
            return;
        }
        self.icons = icon_array(frame.device(), frame.queue(), icons);
        self.icon_count = icons.len() as u32;
    }

    /// Whether an entry is on the GPU.
    pub(crate) fn has(&self, key: EntryKey) -> bool {
        self.entries.contains_key(&key)
    }

    /// Puts an entry on the GPU (its pieces' anchor fields are set to its slot); false,
    /// with nothing changed, if the buffers cannot make room for it within their limits.
    pub(crate) fn insert(
        &mut self,
        frame: &FrameContext<'_>,
        key: EntryKey,
        origin: DVec3,
        lines: &[LineInstance],
        fills: &[FillVertex],
        ends: QuadrantEnds,
    ) -> bool {
        self.remove(key);
        let (device, queue) = (frame.device(), frame.queue());
        let Some(line_range) = allocate(&mut self.line_ranges, lines.len() as u32, self.line_limit)
        else {
            return false;
        };
        let Some(fill_range) = allocate(&mut self.fill_ranges, fills.len() as u32, self.fill_limit)
        else {
            self.line_ranges.free(line_range);
            return false;
        };
        let slot = self
            .free_slots
            .pop()
            .unwrap_or(self.slot_origins.len() as u32);
        if slot as usize >= self.slot_origins.len() {
            self.slot_origins.push(origin);
        } else {
            self.slot_origins[slot as usize] = origin;
        }
        let line_bytes = size_of::<LineInstance>() as u64;
        let fill_bytes = size_of::<FillVertex>() as u64;
        self.lines.reserve(
            device,
            queue,
            u64::from(self.line_ranges.capacity()) * line_bytes,
        );
        self.fills.reserve(
            device,
            queue,
            u64::from(self.fill_ranges.capacity()) * fill_bytes,
        );
        if !lines.is_empty() {
            let l: Vec<LineInstance> = lines
                .iter()
                .map(|l| LineInstance { anchor: slot, ..*l })
                .collect();
            queue.write_buffer(
                &self.lines.buffer,
                u64::from(line_range.start) * line_bytes,
                bytemuck::cast_slice(&l),
            );
        }
        if !fills.is_empty() {
            let f: Vec<FillVertex> = fills
                .iter()
                .map(|f| FillVertex {
                    anchor: (f.anchor & DRAPED_BIT) | slot,
                    ..*f
                })
                .collect();
            queue.write_buffer(
                &self.fills.buffer,
                u64::from(fill_range.start) * fill_bytes,
                bytemuck::cast_slice(&f),
            );
        }
        self.entries.insert(
            key,
            Resident {
                slot,
                lines: line_range,
                fills: fill_range,
                ends,
            },
        );
        true
    }

    /// Most bytes the line and fill buffers may take.
    pub(crate) fn limits_bytes(&self) -> (u64, u64) {
        (
            u64::from(self.line_limit) * size_of::<LineInstance>() as u64,
            u64::from(self.fill_limit) * size_of::<FillVertex>() as u64,
        )
    }

    /// Takes an entry off the GPU.
    pub(crate) fn remove(&mut self, key: EntryKey) {
        if let Some(r) = self.entries.remove(&key) {
            self.line_ranges.free(r.lines);
            self.fill_ranges.free(r.fills);
            self.free_slots.push(r.slot);
        }
    }

    /// Entries on the GPU.
    pub(crate) fn keys(&self) -> impl Iterator<Item = EntryKey> + '_ {
        self.entries.keys().copied()
    }

    /// Sets what is drawn: the indirect records of `drawn` (entries on the GPU, each with
    /// the quadrants it draws).
    pub(crate) fn set_drawn(&mut self, frame: &FrameContext<'_>, drawn: &[(EntryKey, Quadrants)]) {
        let (device, queue) = (frame.device(), frame.queue());
        self.drawn.clear();
        let mut line_args = Vec::new();
        let mut fill_args = Vec::new();
        let mut oit_args = Vec::new();
        let (mut lines, mut fills) = (0u32, 0u32);
        for &(key, parts) in drawn {
            let Some(r) = self.entries.get(&key) else {
                continue;
            };
            self.drawn.push(key);
            QuadrantEnds::ranges(&r.ends.lines, parts, |q| {
                line_args.push(DrawArgs {
                    vertex_count: q.len() as u32 * 6,
                    instance_count: 1,
                    first_vertex: (r.lines.start + q.start) * 6,
                    first_instance: 0,
                });
                lines += q.len() as u32;
            });
            QuadrantEnds::ranges(&r.ends.fills, parts, |q| {
                let args = DrawArgs {
                    vertex_count: q.len() as u32,
                    instance_count: 1,
                    first_vertex: r.fills.start + q.start,
                    first_instance: 0,
                };
                // Geometry at altitude (volumes, fills in the air) is translucent over
                // anything: order-independent; draped fills lie on the terrain, in order.
                match key {
                    EntryKey::Tile(_) => fill_args.push(args),
                    EntryKey::Chunk(..) => oit_args.push(args),
                }
                fills += q.len() as u32;
            });
        }
        self.line_draws
            .write(device, queue, bytemuck::cast_slice(&line_args));
        self.fill_draws
            .write(device, queue, bytemuck::cast_slice(&fill_args));
        self.oit_draws
            .write(device, queue, bytemuck::cast_slice(&oit_args));
        self.oit_draw_count = oit_args.len() as u32;
        self.line_draw_count = line_args.len() as u32;
        self.fill_draw_count = fill_args.len() as u32;
        self.line_count = lines;
        self.fill_vertices = fills;
    }

    /// Writes this frame's uniforms and the drawn entries' anchor offsets (anchor minus eye,
    /// in f64 first).
    pub(crate) fn frame(&mut self, frame: &FrameContext<'_>) {
        let (device, queue) = (frame.device(), frame.queue());
        let camera = frame.camera();
        let (w, h) = camera.viewport_px();
        let (w, h) = (w.max(1) as f32, h.max(1) as f32);
        let eye = camera.view().position.as_vec3();
        let radii = frame.ellipsoid().radii();
        let u = Uniforms {
            clip_from_eye: camera.clip_from_eye().to_cols_array_2d(),
            viewport: [w, h, 1.0 / w, 1.0 / h],
            tolerance: [FILL_TOLERANCE, LINE_TOLERANCE, 0.0, 0.0],
            eye: [
                eye.x,
                eye.y,
                eye.z,
                (1.0 - (radii.z * radii.z) / (radii.x * radii.x)) as f32,
            ],
        };
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&u));
        // Per anchor: its offset from the eye, and how far its tile has grown out of its
        // parent (1 for chunks at altitude: nothing lifts them).
        let morphs: FxHashMap<TileKey, f32> = frame
            .drawn_tiles()
            .iter()
            .map(|d| (d.key, frame.morph_of(d) as f32))
            .collect();
        let mut offsets = vec![[0f32; 4]; self.slot_origins.len().max(1)];
        for key in &self.drawn {
            if let Some(r) = self.entries.get(key) {
                let o = camera.relative(self.slot_origins[r.slot as usize]);
                let grown = match key {
                    EntryKey::Tile(k) => morphs.get(k).copied().unwrap_or(1.0),
                    EntryKey::Chunk(..) => 1.0,
                };
                offsets[r.slot as usize] = [o.x, o.y, o.z, grown];
            }
        }
        self.anchors
            .write(device, queue, bytemuck::cast_slice(&offsets));
        // The bind group follows the anchor buffer and the frame's depth texture.
        let depth = frame.terrain_depth();
        let sizes = [
            self.anchors.buffer.size(),
            self.lines.buffer.size(),
            u64::from(self.icon_count),
        ];
        if self
            .bind_group
            .as_ref()
            .is_none_or(|(_, s, view)| *s != sizes || view != depth)
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
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: self.lines.buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: wgpu::BindingResource::TextureView(&self.icons),
                    },
                    wgpu::BindGroupEntry {
                        binding: 5,
                        resource: wgpu::BindingResource::Sampler(&self.icon_sampler),
                    },
                ],
            });
            self.bind_group = Some((group, sizes, depth.clone()));
        }
    }

    /// Accumulates the translucent geometry at altitude into the OIT targets (a pass of
    /// its own, tested against the terrain's depth).
    pub(crate) fn record(&mut self, frame: &FrameContext<'_>, encoder: &mut wgpu::CommandEncoder) {
        if self.oit_draw_count == 0 {
            return;
        }
        let (w, h) = frame.camera().viewport_px();
        self.oit.targets(frame.device(), (w.max(1), h.max(1)));
        self.oit
            .frame_group(frame.device(), &self.uniforms, &self.anchors.buffer);
        let (Some(t), Some((group, _))) = (&self.oit.textures, &self.oit.group) else {
            return;
        };
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("vector volumes (OIT)"),
            color_attachments: &[
                Some(wgpu::RenderPassColorAttachment {
                    view: &t.accum,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                }),
                Some(wgpu::RenderPassColorAttachment {
                    view: &t.reveal,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::WHITE),
                        store: wgpu::StoreOp::Store,
                    },
                }),
            ],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: frame.terrain_depth(),
                depth_ops: None,
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.oit.accumulate);
        pass.set_bind_group(0, group, &[]);
        pass.set_vertex_buffer(0, self.fills.buffer.slice(..));
        pass.multi_draw_indirect(&self.oit_draws.buffer, 0, self.oit_draw_count);
    }

    /// Draws draped fills, the translucent geometry at altitude composited (and its ids),
    /// then lines and points: at most four draw calls here, five with the accumulation.
    pub(crate) fn draw(&self, pass: &mut wgpu::RenderPass<'_>) -> u32 {
        let Some((group, _, _)) = &self.bind_group else {
            return 0;
        };
        let mut calls = 0;
        pass.set_bind_group(0, group, &[]);
        if self.fill_draw_count > 0 {
            pass.set_pipeline(&self.fill);
            pass.set_vertex_buffer(0, self.fills.buffer.slice(..));
            pass.multi_draw_indirect(&self.fill_draws.buffer, 0, self.fill_draw_count);
            calls += 1;
        }
        if self.oit_draw_count > 0
            && let Some(t) = &self.oit.textures
        {
            pass.set_pipeline(&self.oit.composite);
            pass.set_bind_group(1, &t.group, &[]);
            pass.draw(0..3, 0..1);
            // Their ids (the last face drawn at a pixel wins; colour untouched).
            pass.set_pipeline(&self.volume_ids);
            pass.set_vertex_buffer(0, self.fills.buffer.slice(..));
            pass.multi_draw_indirect(&self.oit_draws.buffer, 0, self.oit_draw_count);
            calls += 2;
        }
        if self.line_draw_count > 0 {
            pass.set_pipeline(&self.line);
            pass.multi_draw_indirect(&self.line_draws.buffer, 0, self.line_draw_count);
            calls += 1;
        }
        calls
    }

    /// Draw calls a frame makes: draped fills, the volumes' accumulation and composite, lines.
    pub(crate) fn draw_calls(&self) -> u32 {
        u32::from(self.fill_draw_count > 0)
            + 3 * u32::from(self.oit_draw_count > 0)
            + u32::from(self.line_draw_count > 0)
    }

    /// GPU bytes held.
    pub(crate) fn bytes(&self) -> u64 {
        [
            &self.anchors,
            &self.lines,
            &self.fills,
            &self.line_draws,
            &self.fill_draws,
            &self.oit_draws,
        ]
        .iter()
        .map(|b| b.buffer.size())
        .sum::<u64>()
            + self.oit.textures.as_ref().map_or(0, |t| {
                u64::from(t.size.0) * u64::from(t.size.1) * (OIT_ACCUM_BYTES + OIT_REVEAL_BYTES)
            })
    }
}

const OIT_ACCUM: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
const OIT_REVEAL: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;
const OIT_ACCUM_BYTES: u64 = 8;
const OIT_REVEAL_BYTES: u64 = 1;

/// Weighted blended order-independent transparency (McGuire and Bavoil, "Weighted Blended
/// Order-Independent Transparency", JCGT 2013): translucent faces add their weighted colour
/// to one target and multiply the revealed background in another, in any order; a
/// full-screen pass composites the weighted average over the frame. Chosen over sorting
/// because volumes intersect each other and the camera goes inside them, where no order of
/// whole faces is right, and because it costs no CPU when the camera moves.
struct Oit {
    accumulate: wgpu::RenderPipeline,
    composite: wgpu::RenderPipeline,
    frame_layout: wgpu::BindGroupLayout,
    texture_layout: wgpu::BindGroupLayout,
    group: Option<(wgpu::BindGroup, [u64; 1])>,
    textures: Option<OitTextures>,
}

struct OitTextures {
    size: (u32, u32),
    accum: wgpu::TextureView,
    reveal: wgpu::TextureView,
    group: wgpu::BindGroup,
}

impl Oit {
    fn new(
        device: &wgpu::Device,
        module: &wgpu::ShaderModule,
        main_layout: &wgpu::BindGroupLayout,
        formats: globus_render::FrameFormats,
        fill_attrs: &[wgpu::VertexAttribute],
    ) -> Self {
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vector oit frame"),
            entries: &[
                buffer_entry(
                    0,
                    wgpu::ShaderStages::VERTEX_FRAGMENT,
                    wgpu::BufferBindingType::Uniform,
                ),
                buffer_entry(
                    1,
                    wgpu::ShaderStages::VERTEX,
                    wgpu::BufferBindingType::Storage { read_only: true },
                ),
            ],
        });
        let texture_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vector oit textures"),
            entries: &[
                texture_entry(0, false, wgpu::TextureViewDimension::D2),
                texture_entry(1, false, wgpu::TextureViewDimension::D2),
            ],
        });
        let accumulate_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("vector oit accumulate"),
            bind_group_layouts: &[Some(&frame_layout)],
            immediate_size: 0,
        });
        let add = wgpu::BlendComponent {
            src_factor: wgpu::BlendFactor::One,
            dst_factor: wgpu::BlendFactor::One,
            operation: wgpu::BlendOperation::Add,
        };
        let reveal = wgpu::BlendComponent {
            src_factor: wgpu::BlendFactor::Zero,
            dst_factor: wgpu::BlendFactor::OneMinusSrc,
            operation: wgpu::BlendOperation::Add,
        };
        let accumulate = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("vector oit accumulate"),
            layout: Some(&accumulate_layout),
            vertex: wgpu::VertexState {
                module,
                entry_point: Some("oit_vs"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: size_of::<FillVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: fill_attrs,
                })],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(formats.depth_test(false)),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module,
                entry_point: Some("oit_fs"),
                compilation_options: Default::default(),
                targets: &[
                    Some(wgpu::ColorTargetState {
                        format: OIT_ACCUM,
                        blend: Some(wgpu::BlendState {
                            color: add,
                            alpha: add,
                        }),
                        write_mask: wgpu::ColorWrites::ALL,
                    }),
                    Some(wgpu::ColorTargetState {
                        format: OIT_REVEAL,
                        blend: Some(wgpu::BlendState {
                            color: reveal,
                            alpha: reveal,
                        }),
                        write_mask: wgpu::ColorWrites::ALL,
                    }),
                ],
            }),
            multiview_mask: None,
            cache: None,
        });
        let composite_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("vector oit composite"),
            bind_group_layouts: &[Some(main_layout), Some(&texture_layout)],
            immediate_size: 0,
        });
        let mut always = formats.depth_test(false);
        always.depth_compare = Some(wgpu::CompareFunction::Always);
        let composite = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("vector oit composite"),
            layout: Some(&composite_layout),
            vertex: wgpu::VertexState {
                module,
                entry_point: Some("composite_vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(always),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module,
                entry_point: Some("composite_fs"),
                compilation_options: Default::default(),
                targets: &formats.colour_targets(Some(wgpu::BlendState::ALPHA_BLENDING), false),
            }),
            multiview_mask: None,
            cache: None,
        });
        Self {
            accumulate,
            composite,
            frame_layout,
            texture_layout,
            group: None,
            textures: None,
        }
    }

    /// The accumulation targets, `size` pixels.
    fn targets(&mut self, device: &wgpu::Device, size: (u32, u32)) {
        if self.textures.as_ref().is_some_and(|t| t.size == size) {
            return;
        }
        let make = |label, format| {
            device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d {
                        width: size.0,
                        height: size.1,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                        | wgpu::TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                })
                .create_view(&wgpu::TextureViewDescriptor::default())
        };
        let accum = make("vector oit accum", OIT_ACCUM);
        let reveal = make("vector oit reveal", OIT_REVEAL);
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vector oit textures"),
            layout: &self.texture_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&accum),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&reveal),
                },
            ],
        });
        self.textures = Some(OitTextures {
            size,
            accum,
            reveal,
            group,
        });
    }

    /// The accumulation pass's bind group (uniforms and anchors).
    fn frame_group(
        &mut self,
        device: &wgpu::Device,
        uniforms: &wgpu::Buffer,
        anchors: &wgpu::Buffer,
    ) {
        let key = [anchors.size()];
        if self.group.as_ref().is_some_and(|(_, k)| *k == key) {
            return;
        }
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vector oit frame"),
            layout: &self.frame_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniforms.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: anchors.as_entire_binding(),
                },
            ],
        });
        self.group = Some((group, key));
    }
}

/// A texture array of icons (at least one layer, transparent when there is none).
fn icon_array(device: &wgpu::Device, queue: &wgpu::Queue, icons: &[Vec<u8>]) -> wgpu::TextureView {
    // At most MAX_ICONS (256, every adapter's least layer limit).
    let layers = globus_render::array_layers(icons.len() as u32, 256);
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("vector icons"),
        size: wgpu::Extent3d {
            width: ICON_SIZE,
            height: ICON_SIZE,
            depth_or_array_layers: layers,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8UnormSrgb,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    for (layer, pixels) in icons.iter().enumerate() {
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: 0,
                    y: 0,
                    z: layer as u32,
                },
                aspect: wgpu::TextureAspect::All,
            },
            pixels,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(ICON_SIZE * 4),
                rows_per_image: Some(ICON_SIZE),
            },
            wgpu::Extent3d {
                width: ICON_SIZE,
                height: ICON_SIZE,
                depth_or_array_layers: 1,
            },
        );
    }
    texture.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    })
}

/// A range of `len`, growing the allocator (doubling, to at most `limit`) when none is
/// free; `None` when even that leaves no room.
fn allocate(ranges: &mut RangeAllocator, len: u32, limit: u32) -> Option<Range<u32>> {
    loop {
        if let Some(r) = ranges.allocate(len) {
            return Some(r);
        }
        let capacity = ranges.capacity();
        let grown = capacity
            .saturating_mul(2)
            .max(capacity.saturating_add(len))
            .min(limit);
        if grown <= capacity {
            return None;
        }
        ranges.grow(grown);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The (start, end) of the ranges drawing quadrants `bits`.
    fn ranges(ends: [u32; 4], bits: u8) -> Vec<(u32, u32)> {
        let mut out = Vec::new();
        QuadrantEnds::ranges(&ends, Quadrants(bits), |r| out.push((r.start, r.end)));
        out
    }

    /// A tile drawn in part draws exactly its drawn quadrants' pieces, in as few records as
    /// their order allows.
    #[test]
    fn quadrant_ranges_draw_the_drawn_quadrants_pieces() {
        // Quadrants of 2, 3, 0 and 4 pieces.
        let ends = [2, 5, 5, 9];
        assert_eq!(ranges(ends, 0b1111), [(0, 9)]);
        assert_eq!(ranges(ends, 0b0011), [(0, 5)]);
        assert_eq!(ranges(ends, 0b1001), [(0, 2), (5, 9)]);
        assert_eq!(ranges(ends, 0b0100), []);
        assert_eq!(ranges(ends, 0b0110), [(2, 5)]);
        // Quadrant 2 is empty, so 1 and 3 touch.
        assert_eq!(ranges(ends, 0b1010), [(2, 9)]);
        assert_eq!(ranges(ends, 0), []);
        // Every set draws each drawn quadrant's pieces once and nothing else.
        for bits in 0..16u8 {
            let mut drawn = [false; 9];
            for (start, end) in ranges(ends, bits) {
                for i in start..end {
                    assert!(!drawn[i as usize], "{bits:04b}: piece {i} twice");
                    drawn[i as usize] = true;
                }
            }
            for (i, d) in drawn.iter().enumerate() {
                let q = ends
                    .iter()
                    .position(|&e| i < e as usize)
                    .expect("in a quadrant");
                assert_eq!(*d, Quadrants(bits).contains(q), "{bits:04b}: piece {i}");
            }
        }
        // An entry not split by quadrant draws whole.
        let whole = QuadrantEnds::whole(7, 3);
        assert_eq!(ranges(whole.lines, 0b1111), [(0, 7)]);
        assert_eq!(ranges(whole.fills, 0b1111), [(0, 3)]);
    }
}
