//! Stage 1, select: LOD selection over the data side's answers, with "loaded" meaning
//! "resident on the GPU", from the engine's own record of what is resident.

use globus_render::Residency;
use globus_stream::TerrainLayer;
#[cfg(test)]
use globus_tiling::GLOBE_SCHEME;
use globus_tiling::{TileInfo, TileKey, TileOracle, TileState, TilingScheme};

/// The oracle selection walks: the layer's bounds, errors and load states, where a tile
/// counts as loaded only if it is also resident in the GPU pools. Everything selection then
/// draws can be drawn this very frame: no holes while data streams in, only coarser
/// ancestors. Nothing is copied from the pools into the layer.
pub(crate) struct ResidentOracle<'a> {
    pub layer: &'a TerrainLayer,
    pub residency: &'a Residency,
}

impl TileOracle for ResidentOracle<'_> {
    fn scheme(&self) -> TilingScheme {
        self.layer.scheme()
    }

    fn tile(&self, key: TileKey) -> TileInfo {
        let mut info = self.layer.tile(key);
        self.resident_or_unloaded(key, &mut info);
        info
    }

    fn child_tiles(
        &self,
        parent: TileKey,
        info: &TileInfo,
        children: &[TileKey],
        out: &mut [Option<TileInfo>; 4],
    ) {
        self.layer.child_tiles(parent, info, children, out);
        // The layer's children are the engine grid's, in its order: one lookup for all.
        let resident = self.residency.resident_children(parent);
        for (i, info) in out.iter_mut().enumerate() {
            if let Some(info) = info
                && info.state == TileState::Loaded
                && resident & (1 << i) == 0
            {
                info.state = TileState::Unloaded;
            }
        }
    }
}

impl ResidentOracle<'_> {
    /// A loaded tile counts as loaded only once it is resident.
    fn resident_or_unloaded(&self, key: TileKey, info: &mut TileInfo) {
        if info.state == TileState::Loaded && !self.residency.contains(key) {
            info.state = TileState::Unloaded;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::time::Duration;

    use globus_geo::DVec3;
    use globus_stream::{ProceduralSource, TerrainLayerOptions};

    #[test]
    fn a_cached_tile_is_drawable_only_once_it_is_resident() {
        let mut layer = TerrainLayer::new(
            Arc::new(ProceduralSource::new(24, 4)),
            TerrainLayerOptions {
                cache_bytes: 64 << 20,
                workers: 1,
            },
        );
        let root = TileKey::new(0, 0, 0);
        let request = globus_tiling::TileRequest {
            key: root,
            priority: 1.0,
        };
        layer.update(&[], &[], &[request]);
        while layer.get(root).is_none() {
            layer.wait_for_tiles(Duration::from_millis(100));
        }
        let mut residency = Residency::new(4, 10_000, 10_000);
        let oracle = ResidentOracle {
            layer: &layer,
            residency: &residency,
        };
        assert_eq!(layer.tile(root).state, TileState::Loaded);
        assert_eq!(oracle.tile(root).state, TileState::Unloaded);
        residency.begin_frame();
        let mut evicted = Vec::new();
        residency.place(root, 10, 30, DVec3::ZERO, &mut evicted);
        let oracle = ResidentOracle {
            layer: &layer,
            residency: &residency,
        };
        assert_eq!(oracle.tile(root).state, TileState::Loaded);
        // Bounds and errors are the layer's.
        assert_eq!(oracle.tile(root).bounds, layer.tile(root).bounds);
        // Children read together answer as they do one by one: not resident, not loaded.
        let children = GLOBE_SCHEME.children(root);
        let mut together = [None; 4];
        oracle.child_tiles(root, &oracle.tile(root), &children, &mut together);
        for (i, &child) in children.iter().enumerate() {
            assert_eq!(together[i], Some(oracle.tile(child)));
            assert_eq!(oracle.tile(child).bounds, layer.tile(child).bounds);
        }
        let child = children[0];
        let request = globus_tiling::TileRequest {
            key: child,
            priority: 1.0,
        };
        layer.update(&[], &[root], &[request]);
        while layer.get(child).is_none() {
            layer.wait_for_tiles(Duration::from_millis(100));
        }
        for resident in [false, true] {
            if resident {
                residency.place(child, 10, 30, DVec3::ZERO, &mut evicted);
            }
            let oracle = ResidentOracle {
                layer: &layer,
                residency: &residency,
            };
            let mut together = [None; 4];
            oracle.child_tiles(root, &oracle.tile(root), &children, &mut together);
            let expected = if resident {
                TileState::Loaded
            } else {
                TileState::Unloaded
            };
            assert_eq!(together[0].map(|t| t.state), Some(expected));
            assert_eq!(together[0], Some(oracle.tile(child)));
            assert_eq!(layer.tile(child).state, TileState::Loaded);
        }
    }
}
