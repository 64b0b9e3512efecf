//! [`VectorLayer`]: the engine's built-in overlay for points, lines, polygons and extruded
//! volumes from GeoJSON or from code, draped on the terrain or at altitude.
//!
//! * Draped geometry (`clamp` ground, the default) is cut along the triangles of every drawn
//!   tile's own mesh ([`globus_vector::drape`], where the choice of technique is argued), so
//!   it lies exactly on the terrain drawn this frame at whatever level; each tile's pieces
//!   are computed once when it is first drawn and kept while it stays cached, by the quadrant
//!   of the tile they lie in: a tile drawn over some quadrants only (beside finer children
//!   while others load) draws those quadrants' pieces, and a line crossing a midline or a
//!   tile's border is cut square on both sides there, so the two runs abut (translucent lines
//!   show no overlap). Fills are
//!   tested a hair nearer than their depth (they share the terrain's planes); lines and
//!   points are screen-space quads (a segment reads its neighbours in the buffer for miter,
//!   bevel or round joins; dashes follow metres along the line) whose visibility is decided
//!   at their centre line
//!   against the terrain's depth ([`crate::FrameContext::terrain_depth`]), so a line keeps its
//!   full pixel width at any pitch and is hidden only by terrain genuinely in front.
//! * Geometry at altitude (absolute heights, extruded volumes) is built once in ECEF f64,
//!   split into chunks of at most 1,000 km, each with its own origin: f32 holds offsets only.
//! * Per frame, when nothing changed, the CPU writes the anchors' offsets from the eye (one
//!   per drawn tile and chunk) and the uniforms: nothing else. When the drawn tiles or the
//!   features change, only new entries (a tile's pieces, a feature's chunks) are uploaded
//!   into the GPU pool and the indirect draw records rewritten ([`gpu`]).
//! * Everything is drawn in two multi-draw calls: fills (draped, then volumes' faces), then
//!   lines and points.
//!
//! Picking: every feature writes its pick id (see [`VectorLayer::pick_id`]) into the id
//! buffer; [`VectorLayer::feature_for_pick`] maps a [`crate::Pick::object`] back to it.

mod build;
pub(crate) mod gpu;
mod labels;

use std::path::Path;
use std::time::Instant;

use globus_geo::{DVec3, Ellipsoid};
use globus_tiling::{Quadrants, TileKey};
use globus_vector::{Feature, Loaded, ReadError, StyleRules};
use rustc_hash::FxHashMap;

use crate::overlay::{FrameContext, Overlay, OverlayPass};
use build::{Bbox, Built, TileDrape};
use gpu::{EntryKey, Gpu, QuadrantEnds};
use labels::PointLabels;

pub use gpu::SHADER;

/// A feature's id in its layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct FeatureId(pub u32);

/// Bytes a position of a feature takes while held and drawn, to plan how many a memory
/// budget holds. Measured: a 950,000-vertex line from a 13.5 MiB file raised the peak of
/// `globus render` by 147 MiB (the parse of its text, the feature, its densified, ranked
/// line and the tiles' pieces), about 160 bytes a position.
pub const BYTES_PER_POSITION: u64 = 160;

/// Positions a layer reads from files by default (about 1.3 GiB held).
pub const DEFAULT_MAX_POSITIONS: usize = 8 << 20;

/// Draped pieces of tiles kept beyond those drawn: at most this many tiles...
const KEPT_TILES: usize = 512;
/// ...and this many bytes of instances.
const KEPT_BYTES: usize = 64 << 20;

/// What the layer holds and what its last frame did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VectorStats {
    /// Features held.
    pub features: usize,
    /// Line segments and point symbols drawn.
    pub line_instances: u32,
    /// Fill vertices drawn.
    pub fill_vertices: u32,
    /// Draw calls of the last frame.
    pub draw_calls: u32,
    /// GPU bytes of its buffers.
    pub gpu_bytes: u64,
    /// Tiles whose draped pieces the last frame computed.
    pub tiles_draped: u32,
    /// Features (re)built the last frame.
    pub features_built: u32,
    /// Whether the last frame rebuilt the instance buffers.
    pub rebuilt: bool,
    /// CPU seconds the last frame's prepare took.
    pub prepare_s: f64,
    /// Points with a label (style `label`).
    pub labels: usize,
    /// Labels drawn in the last frame (the rest had no room, or were out of sight).
    pub labels_drawn: u32,
    /// Tiles' pieces and chunks at altitude the last rebuild left out: the GPU buffers
    /// were at their limit ([`VectorLayer::set_gpu_budget`], or the device's).
    pub left_out: u32,
}

struct Entry {
    feature: Feature,
    built: Option<Built>,
}

/// Points, lines, polygons and volumes over the globe. See the module documentation.
pub struct VectorLayer {
    pick_base: u32,
    next_id: u32,
    entries: FxHashMap<u32, Entry>,
    pending: Vec<u32>,
    /// Features whose draped pieces changed, with the bounds they had and have: the cached
    /// tiles under them redrape those features alone.
    changed: Vec<(u32, Bbox)>,
    built_for: Option<(Ellipsoid, f64)>,
    tiles: FxHashMap<TileKey, CachedTile>,
    frame: u64,
    last_drawn: Vec<TileKey>,
    geometry_changed: bool,
    gpu: Option<Gpu>,
    /// Icons by file, decoded once.
    icons: Icons,
    /// GPU entries to drop (features changed or removed, tiles invalidated).
    released: Vec<EntryKey>,
    /// Names beside points.
    labels: PointLabels,
    /// The labels are to be laid out again (features added, changed or removed).
    labels_stale: bool,
    stats: VectorStats,
    /// Positions of the features held, and the most its files may bring.
    positions: usize,
    max_positions: usize,
    gpu_budget: u64,
}

impl Default for VectorLayer {
    fn default() -> Self {
        Self::new()
    }
}

impl VectorLayer {
    /// An empty layer whose features write pick ids from 1 up.
    pub fn new() -> Self {
        Self::with_pick_base(1)
    }

    /// An empty layer whose features write pick ids from `base` up (to share the id buffer
    /// with other overlays).
    pub fn with_pick_base(base: u32) -> Self {
        Self {
            pick_base: base.max(1),
            next_id: 0,
            entries: FxHashMap::default(),
            pending: Vec::new(),
            changed: Vec::new(),
            built_for: None,
            tiles: FxHashMap::default(),
            frame: 0,
            last_drawn: Vec::new(),
            geometry_changed: false,
            gpu: None,
            released: Vec::new(),
            icons: Icons::default(),
            labels: PointLabels::default(),
            labels_stale: false,
            stats: VectorStats::default(),
            positions: 0,
            max_positions: DEFAULT_MAX_POSITIONS,
            gpu_budget: u64::MAX,
        }
    }

    /// The most positions the features read from files may hold together (default
    /// [`DEFAULT_MAX_POSITIONS`]; [`BYTES_PER_POSITION`] each): a file that would bring
    /// more is read up to the feature that would pass it, with a warning.
    pub fn set_max_positions(&mut self, max: usize) -> &mut Self {
        self.max_positions = max;
        self
    }

    /// Limits the GPU buffers of the pieces drawn (lines and fills, half each) to about
    /// `bytes` (default: only the device's limits). Pieces not drawn in the current frame
    /// make room first; what still does not fit is left out ([`VectorStats::left_out`]).
    pub fn set_gpu_budget(&mut self, bytes: u64) -> &mut Self {
        self.gpu_budget = bytes;
        self.gpu = None;
        self.released.clear();
        self.geometry_changed = true;
        self
    }

    /// The positions a share of a memory budget holds (`bytes` / [`BYTES_PER_POSITION`]).
    pub fn positions_for_bytes(bytes: u64) -> usize {
        usize::try_from(bytes / BYTES_PER_POSITION).unwrap_or(usize::MAX)
    }

    /// Reads a GeoJSON file (or sequence, or airspace) styled by `rules` and adds its
    /// features; bad features are warned about (see [`Loaded::warnings`]) and left out, and
    /// the read stops ([`Loaded::stopped`]) where the layer would hold more positions than
    /// [`Self::set_max_positions`] allows.
    pub fn add_file(
        &mut self,
        path: &Path,
        rules: &StyleRules,
    ) -> Result<(Loaded, Vec<FeatureId>), ReadError> {
        let room = self.max_positions.saturating_sub(self.positions);
        let mut loaded = globus_vector::load_file(path, rules, room)?;
        let ids = self.add_batch(std::mem::take(&mut loaded.features));
        Ok((loaded, ids))
    }

    /// Adds features; their ids in order.
    pub fn add_batch(&mut self, features: impl IntoIterator<Item = Feature>) -> Vec<FeatureId> {
        features.into_iter().map(|f| self.add(f)).collect()
    }

    /// Adds a feature.
    pub fn add(&mut self, feature: Feature) -> FeatureId {
        let id = self.next_id;
        self.next_id += 1;
        self.positions += feature.position_count();
        self.entries.insert(
            id,
            Entry {
                feature,
                built: None,
            },
        );
        self.pending.push(id);
        self.labels_stale = true;
        FeatureId(id)
    }

    /// Replaces a feature; false if there is none with this id.
    pub fn update(&mut self, id: FeatureId, feature: Feature) -> bool {
        let Some(e) = self.entries.get_mut(&id.0) else {
            return false;
        };
        if let Some(b) = e.built.take() {
            self.changed.extend(b.bbox.map(|bb| (id.0, bb)));
            self.geometry_changed |= !b.chunks.is_empty();
            self.released
                .extend((0..b.chunks.len() as u32).map(|i| EntryKey::Chunk(id.0, i)));
        }
        self.positions = self.positions - e.feature.position_count() + feature.position_count();
        e.feature = feature;
        self.pending.push(id.0);
        self.labels_stale = true;
        true
    }

    /// Removes a feature; false if there is none with this id.
    pub fn remove(&mut self, id: FeatureId) -> bool {
        let Some(e) = self.entries.remove(&id.0) else {
            return false;
        };
        self.positions -= e.feature.position_count();
        self.labels_stale = true;
        if let Some(b) = e.built {
            self.changed.extend(b.bbox.map(|bb| (id.0, bb)));
            self.geometry_changed |= !b.chunks.is_empty();
            self.released
                .extend((0..b.chunks.len() as u32).map(|i| EntryKey::Chunk(id.0, i)));
        }
        true
    }

    /// A feature.
    pub fn feature(&self, id: FeatureId) -> Option<&Feature> {
        self.entries.get(&id.0).map(|e| &e.feature)
    }

    /// Features held.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether it holds no feature.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The id a feature writes into the id buffer.
    pub fn pick_id(&self, id: FeatureId) -> u32 {
        self.pick_base.saturating_add(id.0)
    }

    /// The feature that wrote `object` into the id buffer, if it is one of this layer's.
    pub fn feature_for_pick(&self, object: u32) -> Option<(FeatureId, &Feature)> {
        let id = object.checked_sub(self.pick_base)?;
        self.entries.get(&id).map(|e| (FeatureId(id), &e.feature))
    }

    /// What the layer holds and what its last frame did.
    pub fn stats(&self) -> VectorStats {
        self.stats
    }

    /// The point labels drawn in the last frame: the feature, the point's index in it, the
    /// label's box on screen (min x, min y, max x, max y, pixels) and its opacity.
    pub fn drawn_labels(&self) -> impl Iterator<Item = (FeatureId, usize, [f32; 4], f32)> + '_ {
        self.labels
            .drawn_boxes()
            .map(|((f, k), b, o)| (FeatureId(f), k as usize, b, o))
    }

    /// Builds pending features; invalidates the draped pieces of tiles they touch.
    fn build_pending(&mut self, frame: &FrameContext<'_>) -> u32 {
        let (ellipsoid, exaggeration) = (frame.ellipsoid(), frame.exaggeration());
        let ground = |lon: f64, lat: f64| frame.ground_height_m(lon.to_radians(), lat.to_radians());
        if self.built_for != Some((*ellipsoid, exaggeration)) {
            self.built_for = Some((*ellipsoid, exaggeration));
            self.pending = self.entries.keys().copied().collect();
            self.pending.sort_unstable();
            for (&id, e) in &mut self.entries {
                if let Some(b) = e.built.take() {
                    self.released
                        .extend((0..b.chunks.len() as u32).map(|i| EntryKey::Chunk(id, i)));
                }
            }
            self.released
                .extend(self.tiles.keys().map(|&k| EntryKey::Tile(k)));
            self.tiles.clear();
            self.geometry_changed = true;
        }
        let mut built = 0;
        for id in std::mem::take(&mut self.pending) {
            let pick = self.pick_base.saturating_add(id);
            let Some(e) = self.entries.get_mut(&id) else {
                continue;
            };
            if e.built.is_some() {
                continue;
            }
            let icons = &mut self.icons;
            let mut icon_of = |path: &str| icons.layer_of(path);
            let b = build::build(
                &e.feature,
                pick,
                ellipsoid,
                exaggeration,
                &ground,
                &mut icon_of,
            );
            self.changed.extend(b.bbox.map(|bb| (id, bb)));
            self.geometry_changed |= !b.chunks.is_empty();
            e.built = Some(b);
            built += 1;
        }
        if !self.changed.is_empty() {
            self.redrape_changed(frame);
        }
        built
    }

    /// Redrapes, in the drawn tiles under them, only the features that changed (their old
    /// pieces dropped, their new ones added); other cached tiles under them are dropped
    /// whole (draped again if drawn again).
    fn redrape_changed(&mut self, frame: &FrameContext<'_>) {
        let mut boxes: FxHashMap<u32, Vec<Bbox>> = FxHashMap::default();
        for (id, b) in self.changed.drain(..) {
            boxes.entry(id).or_default().push(b);
        }
        let drawn: rustc_hash::FxHashSet<TileKey> =
            frame.drawn_tiles().iter().map(|d| d.key).collect();
        let mut dropped = Vec::new();
        for (&key, tile) in &mut self.tiles {
            let touching: Vec<u32> = boxes
                .iter()
                .filter(|(_, bs)| bs.iter().any(|b| b.overlaps(tile.rect)))
                .map(|(&id, _)| id)
                .collect();
            if touching.is_empty() {
                continue;
            }
            let Some(mesh) = frame.tile_mesh(key).filter(|_| drawn.contains(&key)) else {
                dropped.push(key);
                continue;
            };
            let picks: Vec<u32> = touching
                .iter()
                .map(|&id| self.pick_base.saturating_add(id))
                .collect();
            tile.drape.retain_not(&picks);
            let surface = build::surface(mesh, tile.rect, &frame.tile_morph_targets(key));
            for &id in &touching {
                if let Some(b) = self.entries.get(&id).and_then(|e| e.built.as_ref())
                    && b.bbox.is_some_and(|bb| bb.overlaps(tile.rect))
                {
                    tile.drape
                        .add(&surface, self.pick_base.saturating_add(id), &b.draped);
                }
            }
            self.released.push(EntryKey::Tile(key));
        }
        for key in dropped {
            self.tiles.remove(&key);
            self.released.push(EntryKey::Tile(key));
        }
    }

    /// Drapes every drawn tile that has no pieces yet; whether any was draped.
    fn drape_drawn(&mut self, frame: &FrameContext<'_>) -> u32 {
        let mut draped = 0;
        for d in frame.drawn_tiles() {
            if let Some(t) = self.tiles.get_mut(&d.key) {
                t.last_used = self.frame;
                continue;
            }
            let (Some(mesh), Some(rect)) = (frame.tile_mesh(d.key), frame.tile_rect(d.key)) else {
                continue;
            };
            let rect = rect.to_degrees();
            let surface = build::surface(mesh, rect, &frame.tile_morph_targets(d.key));
            let mut drape = TileDrape::default();
            for (&id, e) in &self.entries {
                let Some(b) = &e.built else {
                    continue;
                };
                if b.bbox.is_some_and(|bb| bb.overlaps(rect)) {
                    drape.add(&surface, self.pick_base.saturating_add(id), &b.draped);
                }
            }
            self.tiles.insert(
                d.key,
                CachedTile {
                    drape,
                    rect,
                    origin: mesh.centre,
                    last_used: self.frame,
                },
            );
            draped += 1;
        }
        if self.tiles.len() > KEPT_TILES + frame.drawn_tiles().len() {
            let mut ages: Vec<u64> = self.tiles.values().map(|t| t.last_used).collect();
            ages.sort_unstable();
            let cut = ages[ages.len() - KEPT_TILES];
            let now = self.frame;
            self.tiles
                .retain(|_, t| t.last_used >= cut || t.last_used == now);
        }
        // The kept pieces grow only when a tile is draped.
        let now = self.frame;
        let kept: usize = if draped == 0 {
            0
        } else {
            self.tiles
                .values()
                .filter(|t| t.last_used != now)
                .map(|t| t.drape.bytes())
                .sum()
        };
        if kept > KEPT_BYTES {
            let mut old: Vec<(u64, TileKey, usize)> = self
                .tiles
                .iter()
                .filter(|(_, t)| t.last_used != now)
                .map(|(&k, t)| (t.last_used, k, t.drape.bytes()))
                .collect();
            old.sort_unstable_by_key(|&(used, key, _)| (used, key));
            let mut over = kept - KEPT_BYTES;
            for (_, key, bytes) in old {
                if over == 0 {
                    break;
                }
                self.tiles.remove(&key);
                over = over.saturating_sub(bytes);
            }
        }
        draped
    }

    /// Puts what this frame draws on the GPU (uploading only entries not there yet), drops
    /// tiles' entries not drawn for a while, and sets the draw records.
    fn sync_gpu(&mut self, frame: &FrameContext<'_>) {
        let Some(gpu) = self.gpu.as_mut() else {
            return;
        };
        for key in self.released.drain(..) {
            gpu.remove(key);
        }
        // What this frame draws: the drawn tiles with pieces, then every chunk at altitude.
        // (A tile drawn in part draws its drawn quadrants' pieces.)
        let mut wanted = Vec::new();
        for d in frame.drawn_tiles() {
            if self.tiles.get(&d.key).is_some_and(|t| !t.drape.is_empty()) {
                wanted.push((EntryKey::Tile(d.key), d.parts));
            }
        }
        let mut ids: Vec<u32> = self.entries.keys().copied().collect();
        ids.sort_unstable();
        for id in ids {
            if let Some(b) = self.entries.get(&id).and_then(|e| e.built.as_ref()) {
                wanted.extend(
                    (0..b.chunks.len() as u32).map(|i| (EntryKey::Chunk(id, i), Quadrants::ALL)),
                );
            }
        }
        let mut drawn = Vec::with_capacity(wanted.len());
        let (mut made_room, mut left_out) = (false, 0u32);
        for &(key, parts) in &wanted {
            if gpu.has(key) {
                drawn.push((key, parts));
                continue;
            }
            let insert = |gpu: &mut Gpu| match key {
                EntryKey::Tile(k) => {
                    let t = &self.tiles[&k];
                    let mut ends = QuadrantEnds::default();
                    let (mut lines, mut fills) = (Vec::new(), Vec::new());
                    for (q, piece) in t.drape.quadrants.iter().enumerate() {
                        lines.extend(piece.line_instances().copied());
                        fills.extend_from_slice(&piece.fills);
                        ends.lines[q] = lines.len() as u32;
                        ends.fills[q] = fills.len() as u32;
                    }
                    gpu.insert(frame, key, t.origin, &lines, &fills, ends)
                }
                EntryKey::Chunk(id, i) => {
                    let c = &self.entries[&id]
                        .built
                        .as_ref()
                        .expect("a built feature")
                        .chunks[i as usize];
                    let ends = QuadrantEnds::whole(c.lines.len(), c.fills.len());
                    gpu.insert(frame, key, c.origin, &c.lines, &c.fills, ends)
                }
            };
            let mut fitted = insert(gpu);
            if !fitted && !made_room {
                // Entries kept from earlier frames make room before anything drawn is left out.
                made_room = true;
                let wanted_set: rustc_hash::FxHashSet<EntryKey> =
                    wanted.iter().map(|&(k, _)| k).collect();
                let idle: Vec<EntryKey> = gpu.keys().filter(|k| !wanted_set.contains(k)).collect();
                for k in idle {
                    gpu.remove(k);
                }
                fitted = insert(gpu);
            }
            if fitted {
                drawn.push((key, parts));
            } else {
                left_out += 1;
            }
        }
        if left_out > 0 && self.stats.left_out == 0 {
            tracing::warn!(
                "vector layer: {left_out} tiles' or chunks' pieces left out of the frame: the GPU \
                 buffers are at their limit (lines {} MiB, fills {} MiB)",
                gpu.limits_bytes().0 >> 20,
                gpu.limits_bytes().1 >> 20
            );
        }
        self.stats.left_out = left_out;
        // Tiles not drawn for a while leave the GPU (their pieces stay on the CPU).
        let now = self.frame;
        let stale: Vec<EntryKey> = gpu
            .keys()
            .filter(|k| match k {
                EntryKey::Tile(t) => self
                    .tiles
                    .get(t)
                    .is_none_or(|c| now.saturating_sub(c.last_used) > GPU_KEEP_FRAMES),
                EntryKey::Chunk(..) => false,
            })
            .collect();
        for k in stale {
            gpu.remove(k);
        }
        gpu.set_drawn(frame, &drawn);
    }
}

/// Frames a tile's pieces stay on the GPU after it was last drawn.
const GPU_KEEP_FRAMES: u64 = 30;

/// Point icons: PNG files decoded and scaled to [`gpu::ICON_SIZE`] squared, each a layer.
#[derive(Default)]
struct Icons {
    layers: FxHashMap<String, u32>,
    pixels: Vec<Vec<u8>>,
}

/// Why an icon cannot be drawn.
#[derive(Debug, thiserror::Error)]
enum IconError {
    #[error(transparent)]
    Read(#[from] std::io::Error),
    /// (The message quotes the cause, which is not also its `source()`.)
    #[error("not a PNG we can read: {0}")]
    Decode(image::ImageError),
}

impl From<image::ImageError> for IconError {
    fn from(e: image::ImageError) -> Self {
        Self::Decode(e)
    }
}

/// Most icons a layer holds.
const MAX_ICONS: usize = 256;

impl Icons {
    /// The layer plus one of the icon at `path` (read, decoded and scaled the first time);
    /// 0, with a warning, if it cannot be read.
    fn layer_of(&mut self, path: &str) -> u32 {
        if let Some(&l) = self.layers.get(path) {
            return l;
        }
        let layer = match self.load(path) {
            Ok(pixels) if self.pixels.len() < MAX_ICONS => {
                self.pixels.push(pixels);
                self.pixels.len() as u32
            }
            Ok(_) => {
                tracing::warn!("icon {path}: more than {MAX_ICONS} icons; drawn as a symbol");
                0
            }
            Err(e) => {
                tracing::warn!("icon {path}: {e}; drawn as a symbol");
                0
            }
        };
        self.layers.insert(path.to_owned(), layer);
        layer
    }

    fn load(&self, path: &str) -> Result<Vec<u8>, IconError> {
        let bytes = globus_tiling::files::read_capped(Path::new(path), 16 << 20)?;
        let image = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)?;
        let size = gpu::ICON_SIZE;
        let scaled = image::imageops::resize(
            &image.to_rgba8(),
            size,
            size,
            image::imageops::FilterType::Triangle,
        );
        Ok(scaled.into_raw())
    }
}

/// A drawn tile's draped pieces.
struct CachedTile {
    drape: TileDrape,
    rect: [f64; 4],
    origin: DVec3,
    last_used: u64,
}

impl Overlay for VectorLayer {
    fn passes(&self) -> &[OverlayPass] {
        &[OverlayPass::World, OverlayPass::ScreenAligned]
    }

    fn wants_terrain_depth(&self) -> bool {
        !self.entries.is_empty()
    }

    fn prepare(&mut self, frame: &FrameContext<'_>) {
        let started = Instant::now();
        self.frame += 1;
        if self.gpu.is_none() {
            self.gpu = Some(Gpu::new(frame).with_budget(frame.device(), self.gpu_budget));
            self.geometry_changed = true;
        }
        let built = self.build_pending(frame);
        let draped = self.drape_drawn(frame);
        let drawn_changed = frame.drawn_tiles().len() != self.last_drawn.len()
            || frame
                .drawn_tiles()
                .iter()
                .zip(&self.last_drawn)
                .any(|(d, k)| d.key != *k);
        let rebuild = drawn_changed
            || draped > 0
            || built > 0
            || self.geometry_changed
            || !self.released.is_empty();
        if rebuild {
            self.last_drawn.clear();
            self.last_drawn
                .extend(frame.drawn_tiles().iter().map(|d| d.key));
            self.geometry_changed = false;
            self.sync_gpu(frame);
        }
        if std::mem::take(&mut self.labels_stale) {
            self.labels
                .rebuild(self.entries.iter().map(|(&id, e)| (id, &e.feature)));
        }
        self.labels.prepare(frame);
        if let Some(gpu) = &mut self.gpu {
            gpu.set_icons(frame, &self.icons.pixels);
            gpu.frame(frame);
            self.stats.line_instances = gpu.line_count;
            self.stats.fill_vertices = gpu.fill_vertices;
            self.stats.gpu_bytes = gpu.bytes() + self.labels.gpu_bytes();
            self.stats.draw_calls = gpu.draw_calls() + self.labels.draw_calls();
        }
        self.stats.labels = self.labels.len();
        self.stats.features = self.entries.len();
        self.stats.tiles_draped = draped;
        self.stats.features_built = built;
        self.stats.rebuilt = rebuild;
        self.stats.prepare_s = started.elapsed().as_secs_f64();
    }

    fn place_labels(&mut self, frame: &FrameContext<'_>) {
        self.labels.place(frame);
        self.stats.labels_drawn = self.labels.drawn();
        if let Some(gpu) = &self.gpu {
            self.stats.gpu_bytes = gpu.bytes() + self.labels.gpu_bytes();
            self.stats.draw_calls = gpu.draw_calls() + self.labels.draw_calls();
        }
    }

    fn record(&mut self, frame: &FrameContext<'_>, encoder: &mut wgpu::CommandEncoder) {
        if let Some(gpu) = &mut self.gpu {
            gpu.record(frame, encoder);
        }
    }

    fn draw(&self, which: OverlayPass, _: &FrameContext<'_>, pass: &mut wgpu::RenderPass<'_>) {
        match which {
            OverlayPass::World => {
                if let Some(gpu) = &self.gpu {
                    gpu.draw(pass);
                }
            }
            OverlayPass::ScreenAligned => self.labels.draw(pass),
            _ => {}
        }
    }
}
