//! What selection asks about each tile.

use crate::{TileBounds, TileKey, TilingScheme};

/// The load state of a tile, as the data side reports it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TileState {
    /// Not loaded (never asked for, queued, or in flight).
    Unloaded,
    /// Loaded and ready to draw.
    Loaded,
    /// The source has no data here (404, empty tile, past its coverage): do not refine.
    NoData,
    /// Loading failed; the ancestor keeps covering this area.
    Failed,
}

/// What the oracle knows about one tile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileInfo {
    /// Bounds: exact for loaded tiles, conservative estimates for the others.
    pub bounds: TileBounds,
    /// How far (metres) this tile's surface may be from the full-resolution surface it stands
    /// for; an estimate for unloaded tiles.
    pub geometric_error_m: f64,
    /// Load state.
    pub state: TileState,
    /// Whether finer tiles exist below this one.
    pub has_children: bool,
    /// The oracle's own handle to where it keeps this tile's children's records
    /// ([`TileInfo::NOWHERE`] if it has none), handed back to [`TileOracle::child_tiles`]
    /// so it need not search for them.
    pub children_at: u32,
}

impl TileInfo {
    /// No handle to the tile's children's records.
    pub const NOWHERE: u32 = u32::MAX;
}

/// Answers selection's questions about tiles. Implementations must be cheap: selection asks
/// once per visited tile per frame. It must answer for any valid key, loaded or not (bounds
/// of unloaded tiles can come from the parent's data or the rectangle and a height range).
pub trait TileOracle {
    /// The tiling scheme of the keys.
    fn scheme(&self) -> TilingScheme;
    /// What is known about `key`.
    fn tile(&self, key: TileKey) -> TileInfo;

    /// What is known about each of `parent`'s children, in order, into `out` (one entry per
    /// child, the rest `None`); `children` is `self.scheme().children(parent)` and `info`
    /// what the oracle said about `parent`. Selection asks this whenever it refines a tile,
    /// so oracles that keep siblings together should answer it with one lookup (through
    /// [`TileInfo::children_at`]); the default asks [`TileOracle::tile`] for each child.
    fn child_tiles(
        &self,
        parent: TileKey,
        info: &TileInfo,
        children: &[TileKey],
        out: &mut [Option<TileInfo>; 4],
    ) {
        let _ = (parent, info);
        *out = [None; 4];
        for (slot, &child) in out.iter_mut().zip(children) {
            *slot = Some(self.tile(child));
        }
    }
}
