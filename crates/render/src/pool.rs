//! [`TilePool`]: the GPU mirror of the CPU tile cache, in buffers that never grow.
//!
//! * One vertex buffer and one index buffer shared by every tile: each resident tile owns a
//!   range of each (sub-allocated first fit, see [`RangeAllocator`]), so meshes of any size
//!   (adaptive cuts keep 12 to 1221 vertices of a tile) pack together and one
//!   `multi_draw_indexed_indirect` draws them all. Indices are tile-local; the draw's base
//!   vertex points at the tile's range.
//! * A parallel per-vertex buffer ([`VertexExtra`]): the slot number, from which the vertex
//!   shader finds its tile's centre-to-eye offset and colour layer (portable: no
//!   first-instance feature), and the vertex's morph target on its parent's surface.
//! * One 2D texture array with one layer (full mip chain) per slot for colour. A tile may be
//!   resident before its own colour (imagery that loads on its own): it then reads the layer
//!   of its nearest resident ancestor that has its own, cropped and scaled to its rectangle
//!   ([`Residency::colour_source`]), until [`TilePool::upload_colour`] fills its layer.
//!
//! A tile is *resident* when it has a slot and its ranges. Room is made by evicting the least
//! recently drawn tiles, never one used this frame, and at most
//! [`TilePoolOptions::uploads_per_frame`] tiles are uploaded per frame. The bookkeeping is in
//! [`Residency`], plain CPU code tested without a GPU.

use std::mem::size_of;
use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use globus_geo::DVec3;
use globus_terrain::grid::COLOUR_SIZE;
use globus_terrain::{ColourImage, MeshQuadrants, MorphVertex, TerrainVertex, TileMesh};
use globus_tiling::{GLOBE_SCHEME, TileKey};
use rustc_hash::FxHashMap;

use crate::ranges::RangeAllocator;

pub use globus_terrain::grid::{
    MAX_MESH_INDICES as MAX_TILE_INDICES, MAX_MESH_VERTICES as MAX_TILE_VERTICES,
};

/// Size of the pools.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TilePoolOptions {
    /// Number of tile slots (clamped to the adapter's texture array limit, and one more
    /// where it is a multiple of 6: see [`crate::array_layers`]).
    pub slots: u32,
    /// Tiles uploaded per frame at most.
    pub uploads_per_frame: u32,
    /// Vertices the shared vertex buffer holds.
    pub vertices: u32,
    /// Indices the shared index buffer holds.
    pub indices: u32,
}

impl TilePoolOptions {
    /// `slots` slots with vertex and index room for `fill` (0..1] of them at full grid size:
    /// adaptive meshes average well under that, and when a view of rough ground needs more,
    /// uploads fail and the engine lowers detail instead of growing.
    pub fn with_slots(slots: u32, fill: f64) -> Self {
        let per = |max: u32| (f64::from(slots) * f64::from(max) * fill.clamp(0.01, 1.0)) as u32;
        Self {
            slots,
            uploads_per_frame: 24,
            vertices: per(MAX_TILE_VERTICES).max(MAX_TILE_VERTICES),
            indices: per(MAX_TILE_INDICES).max(MAX_TILE_INDICES),
        }
    }
}

impl TilePoolOptions {
    /// GPU bytes of pools of this size: vertex, slot and index buffers and the colour array
    /// with its mip chains.
    pub fn gpu_bytes(&self) -> u64 {
        let colour_layer: u64 = (0..MIP_LEVELS)
            .map(|m| u64::from((COLOUR_SIZE >> m).pow(2)) * 4)
            .sum();
        u64::from(self.vertices) * (VERTEX_BYTES + EXTRA_BYTES)
            + u64::from(self.indices) * 4
            + colour_layer * u64::from(self.slots)
    }
}

impl Default for TilePoolOptions {
    fn default() -> Self {
        Self::with_slots(1024, 0.625)
    }
}

/// Counters of the pool.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PoolStats {
    /// Slots in the pool.
    pub capacity: u32,
    /// Slots holding a tile.
    pub resident: u32,
    /// Tiles uploaded this frame.
    pub uploaded_this_frame: u32,
    /// Tiles uploaded since the start.
    pub uploaded_total: u64,
    /// Tiles evicted since the start.
    pub evicted_total: u64,
    /// Colours uploaded after their tiles (imagery that loads on its own) since the start.
    pub colours_uploaded_total: u64,
    /// Vertices in use / capacity.
    pub vertices_used: u32,
    /// Vertex capacity.
    pub vertex_capacity: u32,
    /// Indices in use.
    pub indices_used: u32,
    /// Index capacity.
    pub index_capacity: u32,
    /// GPU bytes of the pools (fixed).
    pub gpu_bytes: u64,
}

/// A resident tile's place in the pools.
#[derive(Clone, Debug, PartialEq)]
pub struct Resident {
    /// The tile.
    pub key: TileKey,
    /// Colour layer and offset entry.
    pub slot: u32,
    /// Its vertices in the shared vertex buffer.
    pub vertices: Range<u32>,
    /// Its indices in the shared index buffer.
    pub indices: Range<u32>,
    /// ECEF origin of its vertices.
    pub centre: DVec3,
    /// Whether its colour layer holds its own colour (else it borrows an ancestor's).
    pub own_colour: bool,
    /// Where its quadrants are among its indices (relative to `indices.start`), once its
    /// mesh is uploaded.
    pub quadrants: Option<MeshQuadrants>,
    last_used: u64,
}

/// Where a tile's fragments read their colour: a layer of the colour pool, and the part of
/// that layer over the tile (`uv * scale + offset`, per axis; v grows southwards, as in
/// tiles).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColourSource {
    /// The tile whose colour is read (the tile itself or an ancestor).
    pub from: TileKey,
    /// Its colour layer.
    pub layer: u32,
    /// Size of the tile in the layer's texture coordinates, u and v (1 for its own colour;
    /// an ancestor in a reduced polar row may be halved in v only).
    pub scale: [f64; 2],
    /// Texture coordinates of the tile's north-west corner in the layer.
    pub offset: [f64; 2],
}

/// Which tile sits where: slots, buffer ranges and recency. No GPU objects.
#[derive(Clone, Debug)]
pub struct Residency {
    slot_of: FxHashMap<TileKey, u32>,
    /// Which of each parent's children are resident, one bit per child in the order of
    /// `GLOBE_SCHEME.children(parent)`: LOD selection asks about a refined tile's children
    /// together, and one probe of this map answers for all of them where four probes of
    /// `slot_of` did (each a cache miss once the rasteriser has run between frames).
    resident_children: FxHashMap<TileKey, u8>,
    slots: Vec<Option<Resident>>,
    free_slots: Vec<u32>,
    vertices: RangeAllocator,
    indices: RangeAllocator,
    frame: u64,
    /// This frame's eviction order, made at its first eviction: the slots not used this
    /// frame, least recently used last (levels 0-2 before them), with the tile and use each
    /// held then. One sort a frame where a scan of every slot per eviction had been a tenth
    /// of the render thread's CPU on `paths/alps-dive.json`.
    eviction_order: Vec<(TileKey, u64, u32)>,
    /// The frame `eviction_order` was made in.
    eviction_order_frame: Option<u64>,
}

impl Residency {
    /// Empty pools of the given sizes.
    pub fn new(slots: u32, vertices: u32, indices: u32) -> Self {
        Self {
            slot_of: FxHashMap::default(),
            resident_children: FxHashMap::default(),
            slots: vec![None; slots as usize],
            free_slots: (0..slots).rev().collect(),
            vertices: RangeAllocator::new(vertices),
            indices: RangeAllocator::new(indices),
            frame: 0,
            eviction_order: Vec::new(),
            eviction_order_frame: None,
        }
    }

    /// Starts a frame: tiles touched from now on are protected from eviction.
    pub fn begin_frame(&mut self) {
        self.frame += 1;
    }

    /// Whether `key` is resident (one lookup in a small map: what LOD selection asks of every
    /// loaded tile it visits).
    pub fn contains(&self, key: TileKey) -> bool {
        self.slot_of.contains_key(&key)
    }

    /// Which of `parent`'s children are resident: bit `i` for the `i`-th of
    /// `GLOBE_SCHEME.children(parent)` (one lookup for all of them).
    pub fn resident_children(&self, parent: TileKey) -> u8 {
        self.resident_children.get(&parent).copied().unwrap_or(0)
    }

    /// Records `key`'s residency in its parent's bits (roots and keys off the engine's
    /// grid have none: [`Residency::contains`] answers for them).
    fn mark_child(&mut self, key: TileKey, resident: bool) {
        let Some(parent) = GLOBE_SCHEME.parent(key) else {
            return;
        };
        let Some(i) = GLOBE_SCHEME.children(parent).position(key) else {
            return;
        };
        let bit = 1u8 << i;
        if resident {
            *self.resident_children.entry(parent).or_insert(0) |= bit;
        } else if let Some(bits) = self.resident_children.get_mut(&parent) {
            *bits &= !bit;
            if *bits == 0 {
                self.resident_children.remove(&parent);
            }
        }
    }

    /// The resident tile `key`.
    pub fn get(&self, key: TileKey) -> Option<&Resident> {
        let slot = *self.slot_of.get(&key)?;
        self.slots[slot as usize].as_ref()
    }

    /// Where `key` reads its colour: its own layer once it has its colour, else the nearest
    /// resident ancestor's that has, cropped and scaled to `key`'s rectangle. `None` if
    /// neither exists. Keys of the engine's tiles ([`GLOBE_SCHEME`]): the part is the tile's
    /// rectangle in its ancestor's, which in a reduced polar row may keep its whole width.
    pub fn colour_source(&self, key: TileKey) -> Option<ColourSource> {
        self.colour_source_from(key, key)
    }

    /// The colour `key`'s parent shows, cropped and scaled to `key`'s rectangle: what a tile
    /// growing out of its parent fades from. `None` for roots and where no ancestor has its
    /// colour.
    pub fn parent_colour_source(&self, key: TileKey) -> Option<ColourSource> {
        self.colour_source_from(key, GLOBE_SCHEME.parent(key)?)
    }

    /// The nearest of `start` and its ancestors with its own colour, cropped to `key`.
    fn colour_source_from(&self, key: TileKey, start: TileKey) -> Option<ColourSource> {
        let mut from = start;
        loop {
            if let Some(r) = self.get(from)
                && r.own_colour
            {
                if from == key {
                    return Some(ColourSource {
                        from,
                        layer: r.slot,
                        scale: [1.0, 1.0],
                        offset: [0.0, 0.0],
                    });
                }
                let (own, of) = (GLOBE_SCHEME.rect(key), GLOBE_SCHEME.rect(from));
                return Some(ColourSource {
                    from,
                    layer: r.slot,
                    scale: [own.width() / of.width(), own.height() / of.height()],
                    offset: [
                        (own.west - of.west) / of.width(),
                        (of.north - own.north) / of.height(),
                    ],
                });
            }
            from = GLOBE_SCHEME.parent(from)?;
        }
    }

    /// Records that `key`'s layer now holds its own colour.
    pub fn set_own_colour(&mut self, key: TileKey) {
        if let Some(&s) = self.slot_of.get(&key)
            && let Some(r) = self.slots[s as usize].as_mut()
        {
            r.own_colour = true;
        }
    }

    /// Records where a resident tile's quadrants are among its indices.
    pub fn set_quadrants(&mut self, key: TileKey, quadrants: MeshQuadrants) {
        if let Some(&s) = self.slot_of.get(&key)
            && let Some(r) = self.slots[s as usize].as_mut()
        {
            r.quadrants = Some(quadrants);
        }
    }

    /// Marks a resident tile as used this frame.
    pub fn touch(&mut self, key: TileKey) {
        if let Some(&s) = self.slot_of.get(&key)
            && let Some(r) = self.slots[s as usize].as_mut()
        {
            r.last_used = self.frame;
        }
    }

    /// Makes room for a tile of `vertices` and `indices` and records it (used this frame,
    /// without its own colour until [`Residency::set_own_colour`]).
    /// Returns its place, or `None` if it cannot fit without evicting a tile used this frame.
    /// Every tile evicted on the way is pushed to `evicted`, whether or not the call succeeds.
    pub fn place(
        &mut self,
        key: TileKey,
        vertices: u32,
        indices: u32,
        centre: DVec3,
        evicted: &mut Vec<TileKey>,
    ) -> Option<Resident> {
        if let Some(r) = self.get(key) {
            return Some(r.clone());
        }
        if vertices > self.vertices.capacity() || indices > self.indices.capacity() {
            return None;
        }
        let slot = loop {
            if let Some(s) = self.free_slots.pop() {
                break s;
            }
            evicted.push(self.evict_oldest()?);
        };
        let v = loop {
            if let Some(r) = self.vertices.allocate(vertices) {
                break r;
            }
            match self.evict_oldest() {
                Some(k) => evicted.push(k),
                None => {
                    self.free_slots.push(slot);
                    return None;
                }
            }
        };
        let i = loop {
            if let Some(r) = self.indices.allocate(indices) {
                break r;
            }
            match self.evict_oldest() {
                Some(k) => evicted.push(k),
                None => {
                    self.free_slots.push(slot);
                    self.vertices.free(v);
                    return None;
                }
            }
        };
        let resident = Resident {
            key,
            slot,
            vertices: v,
            indices: i,
            centre,
            own_colour: false,
            quadrants: None,
            last_used: self.frame,
        };
        self.slots[slot as usize] = Some(resident.clone());
        self.slot_of.insert(key, slot);
        self.mark_child(key, true);
        Some(resident)
    }

    /// Evicts the least recently used tile not used this frame; tiles of the coarsest levels
    /// only when no finer one is left ([`globus_tiling::keeps_longer`]).
    fn evict_oldest(&mut self) -> Option<TileKey> {
        if self.eviction_order_frame != Some(self.frame) {
            self.eviction_order_frame = Some(self.frame);
            let frame = self.frame;
            self.eviction_order.clear();
            self.eviction_order.extend(
                self.slots
                    .iter()
                    .enumerate()
                    .filter_map(|(i, s)| s.as_ref().map(|s| (s.key, s.last_used, i as u32)))
                    .filter(|&(_, used, _)| used < frame),
            );
            // Popped from the end: the coarsest levels' tiles last, then the longest unused,
            // then the lowest slot (the order a scan for the least would find them in).
            self.eviction_order.sort_unstable_by(|a, b| {
                let rank = |(key, used, slot): (TileKey, u64, u32)| {
                    (globus_tiling::keeps_longer(key), used, slot)
                };
                rank(*b).cmp(&rank(*a))
            });
        }
        // A tile touched since the order was made is in use this frame; one evicted (or
        // replaced) is gone from its slot.
        while let Some((key, used, index)) = self.eviction_order.pop() {
            let slot = &mut self.slots[index as usize];
            if slot
                .as_ref()
                .is_none_or(|r| r.key != key || r.last_used != used)
            {
                continue;
            }
            let victim = slot.take()?;
            self.slot_of.remove(&victim.key);
            self.mark_child(victim.key, false);
            self.free_slots.push(victim.slot);
            self.vertices.free(victim.vertices);
            self.indices.free(victim.indices);
            return Some(victim.key);
        }
        None
    }

    /// Number of resident tiles.
    pub fn len(&self) -> usize {
        self.slot_of.len()
    }

    /// Whether no tile is resident.
    pub fn is_empty(&self) -> bool {
        self.slot_of.is_empty()
    }

    /// Number of slots.
    pub fn slot_capacity(&self) -> u32 {
        self.slots.len() as u32
    }

    /// The vertex and index allocators.
    pub fn ranges(&self) -> (&RangeAllocator, &RangeAllocator) {
        (&self.vertices, &self.indices)
    }
}

/// Fixed-size GPU pools for terrain tiles.
pub struct TilePool {
    vertex_buffer: wgpu::Buffer,
    extra_buffer: wgpu::Buffer,
    index_buffer: wgpu::Buffer,
    colour_texture: wgpu::Texture,
    colour_view: wgpu::TextureView,
    residency: Residency,
    options: TilePoolOptions,
    stats: PoolStats,
    /// Uploads this frame may make ([`TilePool::begin_frame_of`]).
    upload_allowance: u32,
}

const MIP_LEVELS: u32 = COLOUR_SIZE.ilog2() + 1;

/// Whether an image fills a colour layer: full size, every mip level complete.
fn colour_fits(c: &ColourImage) -> bool {
    c.size == COLOUR_SIZE
        && c.mips.len() >= MIP_LEVELS as usize
        && (0..MIP_LEVELS)
            .all(|m| c.mips[m as usize].len() == ((COLOUR_SIZE >> m).pow(2) * 4) as usize)
}
const VERTEX_BYTES: u64 = size_of::<TerrainVertex>() as u64;
const EXTRA_BYTES: u64 = size_of::<VertexExtra>() as u64;

/// What the pool keeps per vertex beside the mesh's own [`TerrainVertex`] (12 bytes): the
/// tile's slot and the vertex's morph target.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct VertexExtra {
    /// The tile's slot.
    pub slot: u32,
    /// Where the vertex lies on its parent's surface.
    pub morph: MorphVertex,
}

impl TilePool {
    /// Allocates the pools.
    pub fn new(device: &wgpu::Device, options: TilePoolOptions) -> Self {
        let limits = device.limits();
        // The colour array has a layer per slot: a count the GL backend takes for an array.
        let slots = crate::array_layers(options.slots, limits.max_texture_array_layers);
        let max_buffer = limits.max_buffer_size;
        let vertices = (u64::from(options.vertices).min(max_buffer / VERTEX_BYTES) as u32)
            .max(MAX_TILE_VERTICES);
        let indices = (u64::from(options.indices).min(max_buffer / 4) as u32).max(MAX_TILE_INDICES);
        let buffer = |label, size: u64, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: usage | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let vertex_buffer = buffer(
            "terrain vertex pool",
            u64::from(vertices) * VERTEX_BYTES,
            wgpu::BufferUsages::VERTEX,
        );
        let extra_buffer = buffer(
            "terrain vertex slots and morph targets",
            u64::from(vertices) * EXTRA_BYTES,
            wgpu::BufferUsages::VERTEX,
        );
        let index_buffer = buffer(
            "terrain index pool",
            u64::from(indices) * 4,
            wgpu::BufferUsages::INDEX,
        );
        let colour_texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("terrain colour pool"),
            size: wgpu::Extent3d {
                width: COLOUR_SIZE,
                height: COLOUR_SIZE,
                depth_or_array_layers: slots,
            },
            mip_level_count: MIP_LEVELS,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8UnormSrgb,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let colour_view = colour_texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some("terrain colour pool view"),
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let options = TilePoolOptions {
            slots,
            vertices,
            indices,
            ..options
        };
        let gpu_bytes = options.gpu_bytes();
        Self {
            vertex_buffer,
            extra_buffer,
            index_buffer,
            colour_texture,
            colour_view,
            residency: Residency::new(slots, vertices, indices),
            upload_allowance: options.uploads_per_frame,
            options,
            stats: PoolStats {
                capacity: slots,
                vertex_capacity: vertices,
                index_capacity: indices,
                gpu_bytes,
                ..PoolStats::default()
            },
        }
    }

    /// Starts a frame: resets the upload budget.
    pub fn begin_frame(&mut self) {
        self.begin_frame_of(1.0);
    }

    /// Starts a frame that stands for `frames` frames' time (at least 1): it may upload as
    /// many tiles as they would have together. A frame ten times longer than the ones the
    /// limit was set for pays the same share of its time for uploads, instead of leaving
    /// tiles that arrived meanwhile waiting until the view has left them.
    pub fn begin_frame_of(&mut self, frames: f64) {
        self.residency.begin_frame();
        self.stats.uploaded_this_frame = 0;
        let allowance = f64::from(self.options.uploads_per_frame) * frames.max(1.0);
        // `as` saturates: u32::MAX (no limit) stays so.
        self.upload_allowance = allowance as u32;
    }

    /// How many tiles may be uploaded per frame.
    pub fn uploads_per_frame(&self) -> u32 {
        self.options.uploads_per_frame
    }

    /// Sets how many tiles may be uploaded per frame (offline rendering lifts the limit).
    pub fn set_uploads_per_frame(&mut self, n: u32) {
        self.options.uploads_per_frame = n;
    }

    /// Where a resident tile is.
    pub fn resident(&self, key: TileKey) -> Option<&Resident> {
        self.residency.get(key)
    }

    /// Which tiles are resident where (plain CPU bookkeeping).
    pub fn residency(&self) -> &Residency {
        &self.residency
    }

    /// Whether the tile is resident.
    pub fn is_resident(&self, key: TileKey) -> bool {
        self.residency.get(key).is_some()
    }

    /// Marks a resident tile as used this frame (it will not be evicted this frame).
    pub fn touch(&mut self, key: TileKey) {
        self.residency.touch(key);
    }

    /// Whether another upload fits in this frame's budget.
    pub fn can_upload(&self) -> bool {
        self.stats.uploaded_this_frame < self.upload_allowance
    }

    /// Where `key` reads its colour (see [`Residency::colour_source`]).
    pub fn colour_source(&self, key: TileKey) -> Option<ColourSource> {
        self.residency.colour_source(key)
    }

    /// The colour `key`'s parent shows (see [`Residency::parent_colour_source`]).
    pub fn parent_colour_source(&self, key: TileKey) -> Option<ColourSource> {
        self.residency.parent_colour_source(key)
    }

    /// Uploads a tile with its morph targets (one per vertex, else none: the tile has no
    /// parent to grow out of) and its colour, or without (`None`: it borrows its nearest
    /// resident ancestor's until [`TilePool::upload_colour`]), evicting least recently used
    /// tiles to make room (pushed to `evicted`, also when the upload then fails). Returns its
    /// slot, or `None` if the frame's budget is spent, the data is malformed, or everything
    /// that could make room is in use this frame (the pool is too small for the view: the
    /// caller should lower detail).
    pub fn upload(
        &mut self,
        queue: &wgpu::Queue,
        key: TileKey,
        mesh: &TileMesh,
        morph: &[MorphVertex],
        colour: Option<&ColourImage>,
        evicted: &mut Vec<TileKey>,
    ) -> Option<u32> {
        if let Some(r) = self.residency.get(key) {
            return Some(r.slot);
        }
        let n_vertices = mesh.vertices.len() as u32;
        if !self.can_upload()
            || colour.is_some_and(|c| !colour_fits(c))
            || mesh.indices.iter().any(|&i| i >= n_vertices)
        {
            return None;
        }
        let before = evicted.len();
        let placed = self.residency.place(
            key,
            n_vertices,
            mesh.indices.len() as u32,
            mesh.centre,
            evicted,
        );
        self.stats.evicted_total += (evicted.len() - before) as u64;
        let r = placed?;
        queue.write_buffer(
            &self.vertex_buffer,
            u64::from(r.vertices.start) * VERTEX_BYTES,
            bytemuck::cast_slice(&mesh.vertices),
        );
        let own;
        let morph = if morph.len() == mesh.vertices.len() {
            morph
        } else {
            own = MorphVertex::none(mesh);
            &own
        };
        let extras: Vec<VertexExtra> = morph
            .iter()
            .map(|&morph| VertexExtra {
                slot: r.slot,
                morph,
            })
            .collect();
        queue.write_buffer(
            &self.extra_buffer,
            u64::from(r.vertices.start) * EXTRA_BYTES,
            bytemuck::cast_slice(&extras),
        );
        queue.write_buffer(
            &self.index_buffer,
            u64::from(r.indices.start) * 4,
            bytemuck::cast_slice(&mesh.indices),
        );
        self.residency.set_quadrants(key, mesh.quadrants);
        if let Some(colour) = colour {
            self.write_colour(queue, r.slot, colour);
            self.residency.set_own_colour(key);
        }
        self.stats.uploaded_this_frame += 1;
        self.stats.uploaded_total += 1;
        Some(r.slot)
    }

    /// Fills a resident tile's colour layer with its own colour (it stops borrowing its
    /// ancestor's). Counts against the frame's upload budget; false if that is spent, the
    /// tile is not resident, or the image is not a full tile colour.
    pub fn upload_colour(
        &mut self,
        queue: &wgpu::Queue,
        key: TileKey,
        colour: &ColourImage,
    ) -> bool {
        let Some(r) = self.residency.get(key) else {
            return false;
        };
        if r.own_colour {
            return true;
        }
        if !self.can_upload() || !colour_fits(colour) {
            return false;
        }
        let slot = r.slot;
        self.write_colour(queue, slot, colour);
        self.residency.set_own_colour(key);
        self.stats.uploaded_this_frame += 1;
        self.stats.colours_uploaded_total += 1;
        true
    }

    fn write_colour(&self, queue: &wgpu::Queue, slot: u32, colour: &ColourImage) {
        for (level, pixels) in colour.mips.iter().enumerate().take(MIP_LEVELS as usize) {
            let size = COLOUR_SIZE >> level;
            queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &self.colour_texture,
                    mip_level: level as u32,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: 0,
                        z: slot,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                pixels,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(size * 4),
                    rows_per_image: Some(size),
                },
                wgpu::Extent3d {
                    width: size,
                    height: size,
                    depth_or_array_layers: 1,
                },
            );
        }
    }

    /// Counters.
    pub fn stats(&self) -> PoolStats {
        let (v, i) = self.residency.ranges();
        PoolStats {
            resident: self.residency.len() as u32,
            vertices_used: v.used(),
            indices_used: i.used(),
            ..self.stats
        }
    }

    /// Number of slots.
    pub fn capacity(&self) -> u32 {
        self.options.slots
    }

    pub(crate) fn vertex_buffers(&self) -> (&wgpu::Buffer, &wgpu::Buffer) {
        (&self.vertex_buffer, &self.extra_buffer)
    }

    pub(crate) fn index_buffer(&self) -> &wgpu::Buffer {
        &self.index_buffer
    }

    pub(crate) fn colour_view(&self) -> &wgpu::TextureView {
        &self.colour_view
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(x: u32) -> TileKey {
        TileKey::new(10, x, 7)
    }

    #[test]
    fn slots_are_reused_least_recently_used_first() {
        let mut r = Residency::new(3, 10_000, 10_000);
        let mut evicted = Vec::new();
        for x in 0..3 {
            r.begin_frame();
            assert!(
                r.place(key(x), 100, 300, DVec3::ZERO, &mut evicted)
                    .is_some()
            );
        }
        r.begin_frame();
        r.touch(key(0));
        // Full: the new tile takes the slot of key(1), the oldest not drawn this frame.
        let placed = r.place(key(9), 100, 300, DVec3::ZERO, &mut evicted);
        assert!(placed.is_some());
        assert_eq!(evicted, vec![key(1)]);
        assert!(r.get(key(1)).is_none() && r.get(key(0)).is_some());
        assert_eq!(r.len(), 3);
    }

    /// A fixed pseudo-random sequence from `seed`: each call gives a number below its
    /// argument.
    fn below(seed: u64) -> impl FnMut(u64) -> u64 {
        let mut state = seed;
        move |n| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) % n
        }
    }

    #[test]
    fn a_parents_resident_children_follow_placements_and_evictions() {
        // Every child of a few parents (wide polar ones with two children among them), in
        // pools too small to hold them all: the bits must agree with `contains` throughout.
        // A parent whose children span its row in fewer than four tiles.
        let narrow = (1..8)
            .flat_map(|level| (0..1u32 << level).map(move |y| (level, y)))
            .filter_map(|(level, y)| GLOBE_SCHEME.key(level, 0, y))
            .find(|&k| GLOBE_SCHEME.children(k).len() < 4)
            .expect("a polar parent with fewer children");
        let parents = [
            TileKey::new(0, 0, 0),
            TileKey::new(3, 5, 2),
            GLOBE_SCHEME.tile_at(-2.0, -1.54, 7).expect("a tile"),
            narrow,
        ];
        let children: Vec<TileKey> = parents
            .iter()
            .flat_map(|&p| GLOBE_SCHEME.children(p).to_vec())
            .collect();
        assert!(
            children.len() < 4 * parents.len(),
            "no polar parent: {children:?}"
        );
        let mut r = Residency::new(5, 10_000, 10_000);
        let mut evicted = Vec::new();
        let mut next = below(7);
        for round in 0..200 {
            r.begin_frame();
            let child = children[next(children.len() as u64) as usize];
            if round % 3 == 0 {
                r.touch(child);
            } else {
                r.place(child, 100, 300, DVec3::ZERO, &mut evicted);
            }
            for &p in &parents {
                let bits = r.resident_children(p);
                for (i, &c) in GLOBE_SCHEME.children(p).iter().enumerate() {
                    assert_eq!(bits & (1 << i) != 0, r.contains(c), "round {round}: {c:?}");
                }
                assert_eq!(bits >> GLOBE_SCHEME.children(p).len(), 0);
            }
        }
        assert!(!evicted.is_empty());
        // Roots have no parent's bits; `contains` answers for them.
        r.place(TileKey::new(0, 1, 0), 100, 300, DVec3::ZERO, &mut evicted);
        assert!(r.contains(TileKey::new(0, 1, 0)));
    }

    #[test]
    fn evictions_take_the_least_recently_used_in_order_whatever_the_frame_did() {
        // Tiles of several sizes in small pools, touched and placed at random over many
        // frames: each placement's evictions are, in order, the tiles a scan for the least
        // recently used would pick one by one (levels 0-2 last, ties by slot).
        let mut r = Residency::new(24, 6_000, 18_000);
        let mut evicted = Vec::new();
        let mut next = below(11);
        let mut evictions = 0;
        for frame in 0..300 {
            r.begin_frame();
            for _ in 0..next(6) {
                let level = [1, 2, 5, 9][next(4) as usize] as u8;
                let key = TileKey::new(level, next(2 << level) as u32, next(1 << level) as u32);
                if next(3) == 0 {
                    r.touch(key);
                    continue;
                }
                let mut expected: Vec<(bool, u64, usize, TileKey)> = r
                    .slots
                    .iter()
                    .enumerate()
                    .filter_map(|(i, s)| s.as_ref().map(|s| (s, i)))
                    .filter(|(s, _)| s.last_used < r.frame)
                    .map(|(s, i)| (globus_tiling::keeps_longer(s.key), s.last_used, i, s.key))
                    .collect();
                expected.sort();
                evicted.clear();
                let size = 200 + 400 * next(4) as u32;
                r.place(key, size, 3 * size, DVec3::ZERO, &mut evicted);
                let expected: Vec<TileKey> =
                    expected.iter().take(evicted.len()).map(|e| e.3).collect();
                assert_eq!(evicted, expected, "frame {frame}");
                evictions += evicted.len();
                assert_eq!(r.slot_of.len(), r.slots.iter().flatten().count());
            }
        }
        assert!(evictions > 100, "{evictions} evictions");
    }

    #[test]
    fn tiles_without_their_colour_read_the_nearest_ancestors_cropped() {
        let mut r = Residency::new(8, 10_000, 10_000);
        let mut evicted = Vec::new();
        r.begin_frame();
        let root = TileKey::new(0, 1, 0);
        let parent = TileKey::new(3, 13, 5);
        // Three levels below the parent: x = 8 * 13 + 5, y = 8 * 5 + 2.
        let tile = TileKey::new(6, 109, 42);
        for k in [root, parent, tile] {
            assert!(r.place(k, 10, 30, DVec3::ZERO, &mut evicted).is_some());
        }
        // Nobody has colour yet.
        assert_eq!(r.colour_source(tile), None);
        r.set_own_colour(root);
        let s = r.colour_source(tile).expect("the root's");
        assert_eq!(s.from, root);
        // Level 6 tile 109 of the root's 64 columns 64..128, row 42 of 64.
        let near = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() + (a[1] - b[1]).abs() < 1e-12;
        assert!(near(s.scale, [1.0 / 64.0; 2]), "{s:?}");
        assert!(near(s.offset, [45.0 / 64.0, 42.0 / 64.0]), "{s:?}");
        r.set_own_colour(parent);
        let s = r.colour_source(tile).expect("the parent's");
        assert_eq!(
            (s.from, s.layer),
            (parent, r.get(parent).expect("resident").slot)
        );
        assert!(near(s.scale, [0.125; 2]), "{s:?}");
        assert!(near(s.offset, [5.0 / 8.0, 2.0 / 8.0]), "{s:?}");
        // The tile's own colour wins; a tile reads its own layer unscaled.
        r.set_own_colour(tile);
        let s = r.colour_source(tile).expect("its own");
        assert_eq!((s.from, s.scale, s.offset), (tile, [1.0; 2], [0.0, 0.0]));
        // A tile not resident at all borrows too (the renderer never draws it, but the
        // answer is still right).
        let cousin = TileKey::new(4, 27, 11);
        let s = r.colour_source(cousin).expect("the parent's");
        assert_eq!(s.from, parent);
        assert!(
            near(s.scale, [0.5; 2]) && near(s.offset, [0.5, 0.5]),
            "{s:?}"
        );
        // A polar tile whose row stays whole below its parent borrows the parent's whole
        // width and half its height.
        let polar = TileKey::new(8, 0, 0);
        let whole = TileKey::new(9, 0, 0);
        assert_eq!(GLOBE_SCHEME.parent(whole), Some(polar));
        assert!(r.place(polar, 10, 30, DVec3::ZERO, &mut evicted).is_some());
        r.set_own_colour(polar);
        let s = r.colour_source(whole).expect("the polar parent's");
        assert!(
            near(s.scale, [1.0, 0.5]) && near(s.offset, [0.0, 0.0]),
            "{s:?}"
        );
    }

    #[test]
    fn a_large_mesh_evicts_small_ones_until_it_fits_but_never_this_frames() {
        let mut r = Residency::new(16, 1_000, 10_000);
        let mut evicted = Vec::new();
        r.begin_frame();
        for x in 0..10 {
            assert!(
                r.place(key(x), 100, 10, DVec3::ZERO, &mut evicted)
                    .is_some()
            );
        }
        assert_eq!(r.ranges().0.used(), 1_000);
        r.begin_frame();
        for x in 5..10 {
            r.touch(key(x));
        }
        // 450 vertices: five old tiles must go (4 would leave 400 free).
        let placed = r
            .place(key(20), 450, 10, DVec3::ZERO, &mut evicted)
            .expect("fits after evicting the old tiles");
        assert_eq!(placed.vertices.len(), 450);
        assert_eq!(evicted.len(), 5);
        assert!(evicted.iter().all(|k| k.x() < 5), "{evicted:?}");
        // Nothing left to evict: the next large one fails and leaves the books balanced.
        evicted.clear();
        assert!(
            r.place(key(21), 200, 10, DVec3::ZERO, &mut evicted)
                .is_none()
        );
        assert!(evicted.is_empty());
        assert_eq!(r.len(), 6);
        assert_eq!(r.ranges().0.used(), 950);
        assert_eq!(r.ranges().1.used(), 60);
        // A mesh larger than the whole buffer is refused without evicting anything.
        r.begin_frame();
        assert!(
            r.place(key(22), 1_001, 10, DVec3::ZERO, &mut evicted)
                .is_none()
        );
        assert!(evicted.is_empty());
    }
}
