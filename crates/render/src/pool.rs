//! [`TilePool`]: the GPU mirror of the CPU tile cache, in fixed slot arrays.
//!
//! One storage buffer holds every slot's vertices (slot `s` at `s * VERTICES_PER_TILE`) and
//! one 2D texture array holds every slot's colour image (layer `s`, full mip chain). Both are
//! allocated once at their full size, so GPU memory never grows. A tile is *resident* when it
//! has a slot; slots are reused least-recently-drawn first, never while in use this frame, and
//! at most [`TilePoolOptions::uploads_per_frame`] tiles are uploaded per frame.

use std::mem::size_of;

use globus_geo::DVec3;
use globus_terrain::grid::{COLOUR_SIZE, VERTICES_PER_TILE};
use globus_terrain::{ColourImage, TileMesh};
use globus_tiling::TileKey;
use rustc_hash::FxHashMap;

/// Size of the pools.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TilePoolOptions {
    /// Number of tile slots (clamped to the adapter's texture array limit).
    pub slots: u32,
    /// Tiles uploaded per frame at most.
    pub uploads_per_frame: u32,
}

impl Default for TilePoolOptions {
    fn default() -> Self {
        Self {
            slots: 1024,
            uploads_per_frame: 24,
        }
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
    /// GPU bytes of the pools (fixed).
    pub gpu_bytes: u64,
}

/// Where an upload went.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Upload {
    /// The slot now holding the tile.
    pub slot: u32,
    /// The tile that was evicted to make room, if any.
    pub evicted: Option<TileKey>,
}

#[derive(Clone, Copy, Debug)]
struct Slot {
    key: TileKey,
    centre: DVec3,
    last_used: u64,
}

/// Fixed-size GPU pools for terrain tiles.
pub struct TilePool {
    vertex_buffer: wgpu::Buffer,
    colour_texture: wgpu::Texture,
    colour_view: wgpu::TextureView,
    slot_of: FxHashMap<TileKey, u32>,
    slots: Vec<Option<Slot>>,
    free: Vec<u32>,
    frame: u64,
    options: TilePoolOptions,
    stats: PoolStats,
}

const MIP_LEVELS: u32 = COLOUR_SIZE.ilog2() + 1;
const VERTEX_BYTES: u64 = VERTICES_PER_TILE as u64 * 16;

impl TilePool {
    /// Allocates the pools.
    pub fn new(device: &wgpu::Device, options: TilePoolOptions) -> Self {
        let limits = device.limits();
        let by_buffer =
            (limits.max_storage_buffer_binding_size / VERTEX_BYTES).min(u64::from(u32::MAX)) as u32;
        let slots = options
            .slots
            .min(limits.max_texture_array_layers)
            .min(by_buffer)
            .max(1);
        let vertex_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("terrain vertex pool"),
            size: u64::from(slots) * VERTEX_BYTES,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
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
        let colour_bytes: u64 = (0..MIP_LEVELS)
            .map(|m| u64::from((COLOUR_SIZE >> m).pow(2)) * 4)
            .sum::<u64>()
            * u64::from(slots);
        Self {
            vertex_buffer,
            colour_texture,
            colour_view,
            slot_of: FxHashMap::default(),
            slots: vec![None; slots as usize],
            free: (0..slots).rev().collect(),
            frame: 0,
            options: TilePoolOptions { slots, ..options },
            stats: PoolStats {
                capacity: slots,
                gpu_bytes: u64::from(slots) * VERTEX_BYTES + colour_bytes,
                ..PoolStats::default()
            },
        }
    }

    /// Starts a frame: resets the upload budget.
    pub fn begin_frame(&mut self) {
        self.frame += 1;
        self.stats.uploaded_this_frame = 0;
    }

    /// Sets how many tiles may be uploaded per frame (offline rendering lifts the limit).
    pub fn set_uploads_per_frame(&mut self, n: u32) {
        self.options.uploads_per_frame = n;
    }

    /// The slot of a resident tile.
    pub fn slot(&self, key: TileKey) -> Option<u32> {
        self.slot_of.get(&key).copied()
    }

    /// The ECEF centre of a resident tile's vertices.
    pub fn centre(&self, slot: u32) -> Option<DVec3> {
        self.slots.get(slot as usize)?.map(|s| s.centre)
    }

    /// Whether the tile has a slot.
    pub fn is_resident(&self, key: TileKey) -> bool {
        self.slot_of.contains_key(&key)
    }

    /// Marks a resident tile as used this frame (it will not be evicted this frame).
    pub fn touch(&mut self, key: TileKey) {
        if let Some(&s) = self.slot_of.get(&key)
            && let Some(slot) = self.slots[s as usize].as_mut()
        {
            slot.last_used = self.frame;
        }
    }

    /// Whether another upload fits in this frame's budget.
    pub fn can_upload(&self) -> bool {
        self.stats.uploaded_this_frame < self.options.uploads_per_frame
    }

    /// Uploads a tile into a free or least-recently-used slot. Returns the slot and the tile
    /// evicted to make room, or `None` if the frame's budget is spent or every slot is in use
    /// this frame (the pool is too small for the view: the caller should lower detail).
    pub fn upload(
        &mut self,
        queue: &wgpu::Queue,
        key: TileKey,
        mesh: &TileMesh,
        colour: &ColourImage,
    ) -> Option<Upload> {
        if let Some(slot) = self.slot(key) {
            return Some(Upload {
                slot,
                evicted: None,
            });
        }
        if !self.can_upload()
            || colour.size != COLOUR_SIZE
            || mesh.vertices.len() != VERTICES_PER_TILE as usize
        {
            return None;
        }
        let (slot, evicted) = self.take_slot()?;
        queue.write_buffer(
            &self.vertex_buffer,
            u64::from(slot) * VERTEX_BYTES,
            bytemuck::cast_slice(&mesh.vertices),
        );
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
        self.slots[slot as usize] = Some(Slot {
            key,
            centre: mesh.centre,
            last_used: self.frame,
        });
        self.slot_of.insert(key, slot);
        self.stats.uploaded_this_frame += 1;
        self.stats.uploaded_total += 1;
        Some(Upload { slot, evicted })
    }

    /// A free slot, or the least recently used one not used this frame (with its old tile).
    fn take_slot(&mut self) -> Option<(u32, Option<TileKey>)> {
        if let Some(s) = self.free.pop() {
            return Some((s, None));
        }
        let (index, victim) = self
            .slots
            .iter()
            .enumerate()
            .filter_map(|(i, s)| s.map(|s| (i, s)))
            .filter(|(_, s)| s.last_used < self.frame)
            .min_by_key(|(_, s)| s.last_used)?;
        self.slot_of.remove(&victim.key);
        self.slots[index] = None;
        self.stats.evicted_total += 1;
        Some((index as u32, Some(victim.key)))
    }

    /// Counters.
    pub fn stats(&self) -> PoolStats {
        PoolStats {
            resident: self.slot_of.len() as u32,
            ..self.stats
        }
    }

    /// Number of slots.
    pub fn capacity(&self) -> u32 {
        self.options.slots
    }

    pub(crate) fn vertex_buffer(&self) -> &wgpu::Buffer {
        &self.vertex_buffer
    }

    pub(crate) fn colour_view(&self) -> &wgpu::TextureView {
        &self.colour_view
    }
}

// The shader's `TerrainVertex` is 16 bytes: vec3<f32> then u32.
const _: () = assert!(
    size_of::<globus_terrain::TerrainVertex>() as u64 * VERTICES_PER_TILE as u64 == VERTEX_BYTES
);
