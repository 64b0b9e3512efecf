//! [`Quadrants`]: which quarters of a tile are drawn.

use std::ops::Range;

use crate::{TileKey, TilingScheme};

/// A set of a tile's quadrants, as the bits of a byte: bit 0 the north-west quarter, 1 the
/// north-east, 2 the south-west, 3 the south-east (row-major in the tile's texture
/// coordinates, u eastwards and v southwards). Selection draws a tile in part while some of
/// its children load (the loaded ones are drawn over the rest); meshes keep each quadrant's
/// triangles apart so a renderer can draw just those.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Quadrants(pub u8);

impl Quadrants {
    /// The whole tile.
    pub const ALL: Self = Self(0b1111);
    /// Nothing.
    pub const NONE: Self = Self(0);

    /// The quadrant holding tile texture coordinates (`u`, `v`), both 0 to 1: its index, 0
    /// to 3 (a coordinate of exactly 1/2 belongs to the east or south half).
    pub fn index_of(u: f64, v: f64) -> usize {
        usize::from(v >= 0.5) * 2 + usize::from(u >= 0.5)
    }

    /// Whether quadrant `index` (0 to 3) is in the set.
    pub fn contains(self, index: usize) -> bool {
        index < 4 && self.0 & (1 << index) != 0
    }

    /// Whether all four are.
    pub fn is_all(self) -> bool {
        self.0 & 0b1111 == 0b1111
    }

    /// Whether none is.
    pub fn is_empty(self) -> bool {
        self.0 & 0b1111 == 0
    }

    /// How many are in the set.
    pub fn count(self) -> u32 {
        (self.0 & 0b1111).count_ones()
    }

    /// Both sets.
    pub fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }

    /// The quadrants of `parent` that its child `child` covers (in `scheme`), or `None`
    /// when the child is not a union of whole quadrants (never with this crate's schemes:
    /// a child of a reduced polar tile spans one or two quadrants, 1 or 2 columns of its
    /// row) or not a child of `parent`.
    pub fn of_child(scheme: TilingScheme, parent: TileKey, child: TileKey) -> Option<Self> {
        if scheme.parent(child) != Some(parent) {
            return None;
        }
        // The parent spans columns 2x .. 2x + 2m of the child's level, the west half the
        // first m; rows 2y (north) and 2y + 1.
        let m = scheme.columns(parent.level(), parent.y());
        let (x0, mid) = (2 * parent.x(), 2 * parent.x() + m);
        let width = scheme.columns(child.level(), child.y()).min(2 * m);
        if width < m && m > 1 {
            // Narrower than a quadrant: not a union of them.
            return None;
        }
        let (west, east) = (child.x() < mid, child.x() + width > mid);
        debug_assert!(child.x() >= x0);
        let row = if child.y() == 2 * parent.y() { 0 } else { 2 };
        let mut bits = 0u8;
        if west {
            bits |= 1 << row;
        }
        if east {
            bits |= 1 << (row + 1);
        }
        Some(Self(bits))
    }
}

/// Calls `f` with `ranges` in order, each run of ranges that touch (one's end the next's
/// start) merged into one and empty ones left out: the draw records of a tile drawn in part,
/// whose quadrants' pieces lie in order in one buffer.
pub fn merge_touching(ranges: impl IntoIterator<Item = Range<u32>>, mut f: impl FnMut(Range<u32>)) {
    let mut run: Option<Range<u32>> = None;
    for r in ranges.into_iter().filter(|r| !r.is_empty()) {
        match &mut run {
            Some(open) if open.end == r.start => open.end = r.end,
            _ => {
                if let Some(done) = run.replace(r) {
                    f(done);
                }
            }
        }
    }
    if let Some(done) = run {
        f(done);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::GLOBE_SCHEME;

    #[test]
    fn children_cover_their_quadrants_exactly_once() {
        // Every level-0..8 tile of every scheme near the equator, the poles and between: its
        // children's quadrants partition the tile, and match where the children lie.
        for scheme in [
            TilingScheme::Geographic,
            TilingScheme::WebMercator,
            GLOBE_SCHEME,
        ] {
            for level in 0..9u8 {
                let rows = scheme.tiles_y(level) as u32;
                for y in [0, 1, rows / 3, rows / 2, rows.saturating_sub(1)] {
                    let Some(parent) = scheme.key(level, 0, y.min(rows - 1)) else {
                        continue;
                    };
                    let rect = scheme.rect(parent);
                    let mut seen = Quadrants::NONE;
                    for child in scheme.children(parent).as_slice() {
                        let q = Quadrants::of_child(scheme, parent, *child)
                            .unwrap_or_else(|| panic!("{scheme:?} {parent:?} {child:?}"));
                        assert!(!q.is_empty());
                        assert_eq!(seen.0 & q.0, 0, "{parent:?}: quadrants covered twice");
                        seen = seen.union(q);
                        // The child's centre lies in one of its quadrants.
                        let c = scheme.rect(*child);
                        let (u, v) = rect.uv((c.west + c.east) / 2.0, (c.north + c.south) / 2.0);
                        assert!(q.contains(Quadrants::index_of(u, v)), "{child:?} {q:?}");
                    }
                    assert!(seen.is_all(), "{scheme:?} {parent:?}: {seen:?}");
                }
            }
        }
        // Not a child.
        let p = TileKey::new(3, 4, 3);
        assert_eq!(
            Quadrants::of_child(TilingScheme::Geographic, p, TileKey::new(5, 0, 0)),
            None
        );
    }

    #[test]
    fn quadrant_of_texture_coordinates() {
        assert_eq!(Quadrants::index_of(0.1, 0.1), 0);
        assert_eq!(Quadrants::index_of(0.9, 0.1), 1);
        assert_eq!(Quadrants::index_of(0.1, 0.9), 2);
        assert_eq!(Quadrants::index_of(0.5, 0.5), 3);
        assert!(Quadrants(0b0101).contains(2) && !Quadrants(0b0101).contains(1));
        assert_eq!(Quadrants(0b0110).count(), 2);
        assert!(!Quadrants::ALL.contains(4));
    }
}
