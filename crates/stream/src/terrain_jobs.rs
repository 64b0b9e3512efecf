//! The terrain loads: a source's tiles, each with its morph targets on its parent's surface
//! ([`TerrainData::morph`]) computed on the loader thread.
//!
//! A tile's morph targets need its parent's mesh, and finding them is a rasterisation of
//! the parent's triangles over the tile's grid plus a ray per vertex: about a quarter of a
//! millisecond a tile. Done at upload on the render thread they took half its CPU time on
//! `paths/alps-dive.json` (24 uploads in a frame cost some 6 ms of a 16 ms frame). The layer
//! hands the jobs the loaded parents of the tiles it asks for (a tile is asked for only
//! when selection refines its loaded parent), so the worker that loads a tile finds its
//! parent there; when it does not (the parent left the wanted list's parents meanwhile), the
//! targets stay empty and the engine computes them when it uploads the tile.

use std::sync::{Arc, Mutex};

use globus_terrain::MorphVertex;
use globus_tiling::{GLOBE_SCHEME, TileKey, TilingScheme};
use rustc_hash::FxHashMap;

use crate::fetch::Cancel;
use crate::{SourceError, TerrainData, TerrainSource, TileSource};

/// A terrain source's loads with the parents their morph targets need.
pub(crate) struct TerrainJobs {
    source: Arc<dyn TerrainSource>,
    /// The loaded parents of the tiles wanted now, by key.
    parents: Mutex<FxHashMap<TileKey, Arc<TerrainData>>>,
}

impl TerrainJobs {
    pub(crate) fn new(source: Arc<dyn TerrainSource>) -> Self {
        Self {
            source,
            parents: Mutex::new(FxHashMap::default()),
        }
    }

    /// The source.
    pub(crate) fn source(&self) -> &Arc<dyn TerrainSource> {
        &self.source
    }

    /// Replaces the parents the loads may find (those of the tiles wanted now).
    pub(crate) fn set_parents(
        &self,
        parents: impl IntoIterator<Item = (TileKey, Arc<TerrainData>)>,
    ) {
        let mut map = self.parents.lock().unwrap_or_else(|p| p.into_inner());
        map.clear();
        map.extend(parents);
    }

    fn parent_of(&self, key: TileKey) -> Option<Arc<TerrainData>> {
        let parent = GLOBE_SCHEME.parent(key)?;
        self.parents
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get(&parent)
            .cloned()
    }
}

impl TileSource for TerrainJobs {
    type Tile = TerrainData;

    fn name(&self) -> &str {
        self.source.name()
    }

    fn scheme(&self) -> TilingScheme {
        self.source.scheme()
    }

    fn load(&self, key: TileKey, cancel: &Cancel) -> Result<Option<TerrainData>, SourceError> {
        let mut data = self.source.load(key, cancel)?;
        if let Some(data) = &mut data
            && let Some(parent) = self.parent_of(key)
        {
            data.morph = MorphVertex::towards_parent(
                &data.tile,
                &data.mesh,
                &parent.tile,
                &parent.mesh,
                self.source.ellipsoid(),
            );
        }
        Ok(data)
    }

    fn byte_size(&self, tile: &TerrainData) -> usize {
        self.source.byte_size(tile)
    }
}
