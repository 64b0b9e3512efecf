//! [`TileKey`]: a quadtree node packed into one `u64`.
//!
//! ```text
//!  63    59 58                          29 28                         0
//! +--------+------------------------------+----------------------------+
//! | level  |            x (30 bits)       |          y (29 bits)       |
//! +--------+------------------------------+----------------------------+
//! ```
//!
//! `x` grows eastwards from the antimeridian (180 W) and `y` grows southwards from the
//! northern edge of the scheme (the XYZ convention), at every level and in both schemes.
//! Levels go up to [`TileKey::MAX_LEVEL`] (29): a geographic tile there is about 4 cm wide.

use std::fmt;

/// A tile: level, column and row, packed. Cheap to copy, hash and compare.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileKey(u64);

/// One of the four edge neighbours of a tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Towards the north (y - 1).
    North,
    /// Towards the south (y + 1).
    South,
    /// Towards the east (x + 1).
    East,
    /// Towards the west (x - 1).
    West,
}

const Y_BITS: u32 = 29;
const X_BITS: u32 = 30;
const Y_MASK: u64 = (1 << Y_BITS) - 1;
const X_MASK: u64 = (1 << X_BITS) - 1;

impl TileKey {
    /// The deepest level a key can hold.
    pub const MAX_LEVEL: u8 = 29;

    /// A key from its parts. `None` if the level is above [`TileKey::MAX_LEVEL`] or `x`/`y` do
    /// not fit in the key at all (the scheme checks the real per-level ranges).
    pub fn try_new(level: u8, x: u32, y: u32) -> Option<Self> {
        let fits = level <= Self::MAX_LEVEL
            && u64::from(x) <= X_MASK.min((2u64 << level) - 1)
            && u64::from(y) <= Y_MASK.min((1u64 << level) - 1);
        fits.then(|| Self::pack(level, x, y))
    }

    /// A key from its parts.
    ///
    /// # Panics
    /// If the parts do not fit (see [`TileKey::try_new`]); use that for untrusted input.
    pub fn new(level: u8, x: u32, y: u32) -> Self {
        match Self::try_new(level, x, y) {
            Some(k) => k,
            None => panic!("tile key out of range: level {level}, x {x}, y {y}"),
        }
    }

    /// A key from parts known to fit (for schemes deriving keys from valid ones).
    pub(crate) const fn pack_unchecked(level: u8, x: u32, y: u32) -> Self {
        Self::pack(level, x, y)
    }

    const fn pack(level: u8, x: u32, y: u32) -> Self {
        Self(((level as u64) << (X_BITS + Y_BITS)) | ((x as u64) << Y_BITS) | y as u64)
    }

    /// A key from its packed value, without checks (for constants).
    pub(crate) const fn from_bits_unchecked(bits: u64) -> Self {
        Self(bits)
    }

    /// A key from a packed value produced by [`TileKey::to_bits`]; `None` if it is not one.
    pub fn from_bits(bits: u64) -> Option<Self> {
        let k = Self(bits);
        Self::try_new(k.level(), k.x(), k.y()).filter(|c| *c == k)
    }

    /// The packed value (stable: usable as a map key or in files).
    pub fn to_bits(self) -> u64 {
        self.0
    }

    /// Quadtree depth, 0 for roots.
    pub fn level(self) -> u8 {
        (self.0 >> (X_BITS + Y_BITS)) as u8
    }

    /// Column, counted eastwards from 180 W.
    pub fn x(self) -> u32 {
        ((self.0 >> Y_BITS) & X_MASK) as u32
    }

    /// Row, counted southwards from the northern edge.
    pub fn y(self) -> u32 {
        (self.0 & Y_MASK) as u32
    }

    /// The tile one level up that contains this one; `None` for a root.
    pub fn parent(self) -> Option<Self> {
        let level = self.level();
        (level > 0).then(|| Self::pack(level - 1, self.x() >> 1, self.y() >> 1))
    }

    /// The ancestor at `level` (itself if `level` is its own). `None` if `level` is deeper.
    pub fn ancestor_at(self, level: u8) -> Option<Self> {
        let own = self.level();
        (level <= own).then(|| {
            let shift = own - level;
            Self::pack(level, self.x() >> shift, self.y() >> shift)
        })
    }

    /// Whether `self` is `other` or one of its ancestors.
    pub fn contains(self, other: TileKey) -> bool {
        other.ancestor_at(self.level()) == Some(self)
    }

    /// The four children in the order north-west, north-east, south-west, south-east.
    /// `None` at [`TileKey::MAX_LEVEL`].
    pub fn children(self) -> Option<[Self; 4]> {
        let level = self.level();
        if level >= Self::MAX_LEVEL {
            return None;
        }
        let (x, y) = (self.x() << 1, self.y() << 1);
        let l = level + 1;
        Some([
            Self::pack(l, x, y),
            Self::pack(l, x + 1, y),
            Self::pack(l, x, y + 1),
            Self::pack(l, x + 1, y + 1),
        ])
    }

    /// Which child of its parent this is (0 NW, 1 NE, 2 SW, 3 SE); 0 for roots.
    pub fn child_index(self) -> usize {
        ((self.x() & 1) | ((self.y() & 1) << 1)) as usize
    }
}

impl fmt::Debug for TileKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}/{}", self.level(), self.x(), self.y())
    }
}

impl fmt::Display for TileKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self, f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn fields_round_trip_at_extremes() {
        let k = TileKey::new(29, (1 << 30) - 1, (1 << 29) - 1);
        assert_eq!(
            (k.level(), k.x(), k.y()),
            (29, (1 << 30) - 1, (1 << 29) - 1)
        );
        assert!(k.children().is_none());
        assert!(TileKey::try_new(30, 0, 0).is_none());
        assert!(TileKey::try_new(2, 8, 0).is_none());
        assert!(TileKey::try_new(2, 7, 4).is_none());
    }

    #[test]
    fn children_and_parent() {
        let k = TileKey::new(3, 5, 2);
        let c = k.children().unwrap();
        assert_eq!(format!("{:?}", c), "[4/10/4, 4/11/4, 4/10/5, 4/11/5]");
        for (i, child) in c.iter().enumerate() {
            assert_eq!(child.parent(), Some(k));
            assert_eq!(child.child_index(), i);
            assert!(k.contains(*child));
        }
        assert_eq!(TileKey::new(0, 1, 0).parent(), None);
    }

    proptest! {
        #[test]
        fn ancestor_contains_descendant(level in 0u8..=29, x in any::<u32>(), y in any::<u32>(), up in 0u8..30) {
            let x = x & ((2u32 << level.min(29)) - 1).min((1 << 30) - 1);
            let y = y & ((1u32 << level) - 1);
            let k = TileKey::new(level, x, y);
            let a = k.ancestor_at(level.saturating_sub(up)).unwrap();
            prop_assert!(a.contains(k));
            prop_assert_eq!(TileKey::try_new(k.level(), k.x(), k.y()), Some(k));
        }
    }
}
