//! The [`TileSource`] trait: where tiles come from.

use globus_geo::Ellipsoid;
use globus_terrain::grid::MESH_SEGMENTS;
use globus_terrain::{MeshOptions, MorphVertex, TerrainTile, TileMesh};
use globus_tiling::{GLOBE_SCHEME, TileBounds, TileKey, TilingScheme};

use crate::fetch::Cancel;

/// Why a tile could not be loaded. Every error names the tile and the source.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SourceError {
    /// The source failed to produce the tile, and trying again will not help.
    #[error("tile {key} from {source_name}: {message}")]
    Failed {
        /// The tile.
        key: TileKey,
        /// The source's name.
        source_name: String,
        /// What went wrong.
        message: String,
    },
    /// The source failed this time (a timeout, a reset, HTTP 5xx or 429); the scheduler
    /// retries with backoff.
    #[error("tile {key} from {source_name}: {message}")]
    Transient {
        /// The tile.
        key: TileKey,
        /// The source's name.
        source_name: String,
        /// What went wrong.
        message: String,
        /// How long the server asked us to wait.
        retry_after: Option<std::time::Duration>,
    },
    /// The load stopped because nobody wants the tile any more.
    #[error("tile {key}: cancelled")]
    Cancelled {
        /// The tile.
        key: TileKey,
    },
}

/// A provider of tiles, called on worker threads. Loads must not panic; a panic is still
/// caught and reported as a failure of that tile.
pub trait TileSource: Send + Sync + 'static {
    /// What a loaded tile is.
    type Tile: Send + Sync + 'static;
    /// A short name for logs and errors (a path, URL or "procedural seed 1").
    fn name(&self) -> &str;
    /// The tiling scheme of the keys.
    fn scheme(&self) -> TilingScheme;
    /// Loads a tile. `Ok(None)` means the source has no data there (stop refining). Slow
    /// loads check `cancel` between steps and return [`SourceError::Cancelled`] when set.
    fn load(&self, key: TileKey, cancel: &Cancel) -> Result<Option<Self::Tile>, SourceError>;
    /// Bytes a loaded tile holds in memory, for cache budgets.
    fn byte_size(&self, tile: &Self::Tile) -> usize;
}

/// A source of terrain tiles, with what the engine must know before any tile is loaded.
pub trait TerrainSource: TileSource<Tile = TerrainData> {
    /// The body the terrain is on.
    fn ellipsoid(&self) -> &Ellipsoid;
    /// A body guaranteed to be below every drawn terrain point (for horizon culling; with an
    /// elevation exaggeration, below the exaggerated surface).
    fn occluder(&self) -> &Ellipsoid;
    /// The lowest and highest heights of the drawn surface, metres (true heights times the
    /// elevation exaggeration of the source's [`MeshOptions`]).
    fn height_range_m(&self) -> (f64, f64);
    /// The deepest level with data.
    fn max_level(&self) -> u8;
    /// Bytes the source keeps in caches of its own (decoded source tiles, refinement bases),
    /// besides the tiles it hands out: counted against the engine's memory budget.
    fn cached_bytes(&self) -> usize {
        0
    }
    /// Each data layer's tiles that failed for good so far (none for a procedural source).
    fn layer_failures(&self) -> Vec<crate::pyramid::LayerFailures> {
        Vec::new()
    }
    /// The full-resolution surface height at a longitude and latitude (radians), metres, if
    /// the source can answer without loading tiles (a procedural source can; an archive
    /// cannot, and the engine then reads its loaded tiles).
    fn height_at(&self, lon_rad: f64, lat_rad: f64) -> Option<f64> {
        let _ = (lon_rad, lat_rad);
        None
    }
    /// Whether the source has imagery with detail for `key`, a tile it may have no terrain
    /// data for (imagery deeper than its terrain): a wrapper that invents such a tile marks
    /// it [`TerrainData::colour_separate`] and gets its real colour from
    /// [`TerrainSource::load_colour`]. Cheap: no loads.
    fn has_imagery_for(&self, key: TileKey) -> bool {
        let _ = key;
        false
    }
    /// The colour of a tile loaded with [`TerrainData::colour_separate`] set (by this source,
    /// or by a wrapper for a tile it invented where [`TerrainSource::has_imagery_for`]): the
    /// source's imagery for it, over its heights' tint, (fetched and composited now, on a worker thread of its own scheduler, so
    /// a tile's geometry is drawn before its imagery arrives). `None`: the source has no
    /// colour of its own for this tile, and the nearest ancestor's stays.
    fn load_colour(
        &self,
        data: &TerrainData,
        cancel: &Cancel,
    ) -> Result<Option<globus_terrain::ColourImage>, SourceError> {
        let _ = (data, cancel);
        Ok(None)
    }
}

/// A terrain tile ready for selection and rendering: its data, its mesh, and conservative
/// bounds for its four children (so they can be culled before they are loaded).
#[derive(Debug)]
pub struct TerrainData {
    /// Heights, colour and errors.
    pub tile: TerrainTile,
    /// Vertices and exact bounds.
    pub mesh: TileMesh,
    /// Bounds of the children in [`GLOBE_SCHEME`]'s order, from this tile's heights over
    /// each child's part widened by this tile's geometric error ([`child_bounds`]).
    pub child_bounds: [TileBounds; 4],
    /// Made here (procedural planet, refinement below the data) rather than from data
    /// fetched for it: no request was sent for this tile.
    pub generated: bool,
    /// The tile's imagery loads on its own ([`TerrainSource::load_colour`]), after its
    /// geometry: `tile.colour` is only a one-texel stand-in (never drawn), and the renderer
    /// shows the nearest ancestor's colour, cropped and scaled, until the tile's own arrives.
    pub colour_separate: bool,
    /// Where each of the mesh's vertices lies on the parent's surface (geomorphing), one per
    /// vertex: filled by the layer's loader thread when the parent was loaded
    /// (`MorphVertex::towards_parent`), empty otherwise. Sources leave it empty.
    pub morph: Vec<MorphVertex>,
}

impl TerrainData {
    /// Cuts the tile's mesh with `options`, folds the error the cut adds into the tile's
    /// geometric error (so LOD selection sees the mesh that is drawn), and bounds the
    /// children. Every terrain source builds its tiles through here.
    pub fn build(
        mut tile: TerrainTile,
        ellipsoid: &Ellipsoid,
        occluder: &Ellipsoid,
        options: &MeshOptions,
    ) -> Self {
        let mesh = TileMesh::build(&tile, ellipsoid, occluder, options);
        tile.geometric_error_m = mesh.geometric_error_m;
        let child_bounds = child_bounds(&tile, ellipsoid, occluder, options.exaggeration);
        Self {
            tile,
            mesh,
            child_bounds,
            generated: false,
            colour_separate: false,
            morph: Vec::new(),
        }
    }

    /// Bytes held.
    pub fn byte_size(&self) -> usize {
        self.tile.byte_size()
            + self.mesh.byte_size()
            + std::mem::size_of_val(self.morph.as_slice())
            + std::mem::size_of::<Self>()
    }

    /// The error LOD selection should use, in drawn metres: the tile's
    /// [`TerrainTile::lod_error_m`] with its geometric part raised by the mesh's elevation
    /// exaggeration (never lowered: an exaggeration below 1 flattens the heights but not the
    /// curvature of the body the error also covers).
    pub fn lod_error_m(&self) -> f64 {
        let scale = self.mesh.exaggeration.max(1.0);
        (self.tile.geometric_error_m * scale).max(self.tile.lod_error_m())
    }
}

/// Conservative bounds of the children (in [`GLOBE_SCHEME`]'s order: four, or three where
/// a polar row stays whole) from the parent's heights over each child's part of its grid:
/// children stay within the parent's geometric error of its mesh, and their skirts hang a
/// few errors lower. Heights and errors are raised by `exaggeration`, as the meshes are.
/// Unused entries repeat the parent's own bounds.
pub fn child_bounds(
    tile: &TerrainTile,
    ellipsoid: &Ellipsoid,
    occluder: &Ellipsoid,
    exaggeration: f64,
) -> [TileBounds; 4] {
    let e = exaggeration;
    let own = TileBounds::from_rect(
        ellipsoid,
        occluder,
        &tile.rect,
        tile.min_height_m * e,
        tile.max_height_m * e,
    );
    let mut out = [own; 4];
    let spacing_m = tile.rect.height() / f64::from(MESH_SEGMENTS) * ellipsoid.mean_radius();
    let cells = f64::from(MESH_SEGMENTS);
    for (slot, &child) in out.iter_mut().zip(GLOBE_SCHEME.children(tile.key).iter()) {
        let rect = GLOBE_SCHEME.rect(child);
        // The child's rectangle in the parent's grid (a half or the whole of each axis),
        // widened to whole cells.
        let (u0, v0) = tile.rect.uv(rect.west, rect.north);
        let (u1, v1) = tile.rect.uv(rect.east, rect.south);
        let index = |f: f64, round: fn(f64) -> f64| (round(f * cells).clamp(0.0, cells)) as i32;
        let (i0, i1) = (index(u0, f64::floor), index(u1, f64::ceil));
        let (j0, j1) = (index(v0, f64::floor), index(v1, f64::ceil));
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for j in j0..=j1 {
            for i in i0..=i1 {
                let h = f64::from(tile.height_at(i, j));
                lo = lo.min(h);
                hi = hi.max(h);
            }
        }
        let margin = tile.geometric_error_m * e.max(1.0);
        let skirt = 4.0 * margin + 0.02 * spacing_m;
        *slot = TileBounds::from_rect(
            ellipsoid,
            occluder,
            &rect,
            lo * e - margin - skirt,
            hi * e + margin,
        );
    }
    out
}
