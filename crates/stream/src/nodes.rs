//! The layer's per-tile records for selection, stored by family.
//!
//! Selection reads a tile's children together every time it refines it, and each read is a
//! cache miss on a cold table (the rasteriser runs between frames and evicts it): profiling
//! the Alps dive put two thirds of the selection's time in the record lookups. So records
//! live in families, the children of one parent side by side: one lookup and a few adjacent
//! cache lines serve all of a tile's children, where one probe per child did before. The
//! roots form a family of their own.
//!
//! Families live in a slab, and each family holds, beside its records, where each of its
//! members' own children live in it (`kids`). Selection gets that index with a tile's record
//! ([`TileInfo::children_at`](globus_tiling::TileInfo::children_at)) and hands it back when
//! it refines the tile: no hash probe on the hot path, only the family's own cache lines.
//! A map from parent to slab index serves the lookups by key (loads, evictions, single
//! tiles). Against one hash map of families, the criterion bench
//! (`benches/select_layer.rs`, 1 km above ground looking down, five alternated runs of each)
//! measured the same warm (38-41 µs) and about a tenth less cold (median 69.5 against
//! 77.2 µs). Touching the families of the children about to be refined ahead of the descent
//! (a prefetch, so their misses would overlap) made no difference cold and cost 10 % warm.
//! Packing the records to 112 bytes instead of 200 (box axes and half-extents in f32, grown
//! to stay conservative, the sphere derived from the box) made no difference cold either and
//! cost a third warm (36 against 49 µs, three alternated runs, 1 km above ground looking
//! down): a family's cache lines are adjacent, so what a cold lookup pays is the first miss
//! of each family, not the number of lines.
//!
//! A family exists while any of its records, or any family below it, does (so every family
//! is linked from the roots'); a record may be missing (the layer then estimates one on
//! demand, see `TerrainLayer::estimate`).

use globus_tiling::{GLOBE_SCHEME, TileInfo, TileKey};
use rustc_hash::FxHashMap;

/// The most children a tile has.
const MAX_CHILDREN: usize = 4;

/// No family: a member without children's records (selection's own "no handle").
pub(crate) const NOWHERE: u32 = TileInfo::NOWHERE;

/// One parent's children's records, in the order of `GLOBE_SCHEME.children(parent)`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Family<N> {
    /// Whose children these are (`None` for the roots' family and free slots).
    parent: Option<TileKey>,
    /// Where each member's own children's family is in the slab, or [`NOWHERE`].
    kids: [u32; MAX_CHILDREN],
    members: [Option<N>; MAX_CHILDREN],
}

impl<N: Copy> Family<N> {
    const EMPTY: Self = Self {
        parent: None,
        kids: [NOWHERE; MAX_CHILDREN],
        members: [None; MAX_CHILDREN],
    };

    /// The records, indexed like the parent's children.
    pub(crate) fn members(&self) -> &[Option<N>; MAX_CHILDREN] {
        &self.members
    }

    /// Where each member's children are ([`NodeTable::family_at`]), indexed like
    /// [`Family::members`].
    pub(crate) fn kids(&self) -> &[u32; MAX_CHILDREN] {
        &self.kids
    }

    fn is_empty(&self) -> bool {
        self.members.iter().all(Option::is_none) && self.kids.iter().all(|&k| k == NOWHERE)
    }
}

/// A family's place: the roots' or a slab index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Place {
    Roots,
    At(u32),
}

/// Records keyed by tile, stored by family.
#[derive(Clone, Debug)]
pub(crate) struct NodeTable<N> {
    roots: Family<N>,
    slab: Vec<Family<N>>,
    /// Free slab slots.
    free: Vec<u32>,
    /// Parent to slab index, for lookups by key.
    index: FxHashMap<TileKey, u32>,
}

impl<N: Copy> Default for NodeTable<N> {
    fn default() -> Self {
        Self {
            roots: Family::EMPTY,
            slab: Vec::new(),
            free: Vec::new(),
            index: FxHashMap::default(),
        }
    }
}

/// Where a tile's record lives: its parent (`None` for a root) and its index there.
fn slot(key: TileKey) -> Option<(Option<TileKey>, usize)> {
    match GLOBE_SCHEME.parent(key) {
        None => {
            let i = GLOBE_SCHEME.roots().iter().position(|r| *r == key)?;
            Some((None, i))
        }
        Some(parent) => {
            let i = GLOBE_SCHEME.children(parent).position(key)?;
            Some((Some(parent), i))
        }
    }
}

impl<N: Copy> NodeTable<N> {
    /// The family of `parent`'s children (`None` for the roots' family).
    pub(crate) fn family(&self, parent: Option<TileKey>) -> Option<&Family<N>> {
        match parent {
            None => Some(&self.roots),
            Some(p) => self.index.get(&p).map(|&i| &self.slab[i as usize]),
        }
    }

    /// The family of `parent`'s children, found at `at` (a [`Family::kids`] entry read with
    /// `parent`'s record) or, if that is not it, by key.
    pub(crate) fn family_at(&self, parent: TileKey, at: u32) -> Option<&Family<N>> {
        match self.slab.get(at as usize) {
            Some(f) if f.parent == Some(parent) => Some(f),
            _ => self.family(Some(parent)),
        }
    }

    fn place(&self, parent: Option<TileKey>) -> Option<Place> {
        match parent {
            None => Some(Place::Roots),
            Some(p) => self.index.get(&p).map(|&i| Place::At(i)),
        }
    }

    fn at_mut(&mut self, place: Place) -> &mut Family<N> {
        match place {
            Place::Roots => &mut self.roots,
            Place::At(i) => &mut self.slab[i as usize],
        }
    }

    /// The place of `parent`'s family, made (with the families above it) if missing.
    /// `None` for a key that is no tile of the scheme.
    fn make(&mut self, parent: Option<TileKey>) -> Option<Place> {
        if let Some(place) = self.place(parent) {
            return Some(place);
        }
        let p = parent?;
        let (grand, i) = slot(p)?;
        let above = self.make(grand)?;
        let at = match self.free.pop() {
            Some(at) => at,
            None => {
                self.slab.push(Family::EMPTY);
                u32::try_from(self.slab.len() - 1).ok()?
            }
        };
        self.slab[at as usize] = Family {
            parent: Some(p),
            ..Family::EMPTY
        };
        self.index.insert(p, at);
        self.at_mut(above).kids[i] = at;
        Some(Place::At(at))
    }

    /// Drops `parent`'s family if it is empty, and then the families above it that are.
    fn prune(&mut self, mut parent: TileKey) {
        loop {
            let Some(&at) = self.index.get(&parent) else {
                return;
            };
            if !self.slab[at as usize].is_empty() {
                return;
            }
            self.slab[at as usize] = Family::EMPTY;
            self.free.push(at);
            self.index.remove(&parent);
            let Some((grand, i)) = slot(parent) else {
                return;
            };
            let Some(above) = self.place(grand) else {
                return;
            };
            self.at_mut(above).kids[i] = NOWHERE;
            match grand {
                Some(g) => parent = g,
                None => return,
            }
        }
    }

    /// The record of `key`.
    pub(crate) fn get(&self, key: TileKey) -> Option<&N> {
        let (parent, i) = slot(key)?;
        self.family(parent)?.members[i].as_ref()
    }

    /// The record of `key` and where the family of its children is ([`NOWHERE`] if it has
    /// none), from one lookup of its own family.
    pub(crate) fn get_with_children_at(&self, key: TileKey) -> (Option<&N>, u32) {
        match slot(key).and_then(|(parent, i)| Some((self.family(parent)?, i))) {
            Some((family, i)) => (family.members[i].as_ref(), family.kids[i]),
            None => (None, NOWHERE),
        }
    }

    /// Whether `key` has a record.
    #[cfg(test)]
    pub(crate) fn contains_key(&self, key: TileKey) -> bool {
        self.get(key).is_some()
    }

    /// Sets the record of `key` (a key that is not a tile of the scheme is ignored).
    pub(crate) fn insert(&mut self, key: TileKey, node: N) {
        if let Some((parent, i)) = slot(key)
            && let Some(place) = self.make(parent)
        {
            self.at_mut(place).members[i] = Some(node);
        }
    }

    /// Calls `f` on the record of each of `parent`'s children (with its index), creating
    /// the family if needed; `f` may set or clear them.
    pub(crate) fn update_children(
        &mut self,
        parent: TileKey,
        mut f: impl FnMut(usize, &mut Option<N>),
    ) {
        let Some(place) = self.make(Some(parent)) else {
            return;
        };
        for (i, member) in self.at_mut(place).members.iter_mut().enumerate() {
            f(i, member);
        }
        self.prune(parent);
    }

    /// Drops the record of `key`.
    pub(crate) fn remove(&mut self, key: TileKey) {
        let Some((parent, i)) = slot(key) else {
            return;
        };
        let Some(place) = self.place(parent) else {
            return;
        };
        self.at_mut(place).members[i] = None;
        if let Some(p) = parent {
            self.prune(p);
        }
    }

    /// Checks the links: every family is non-empty, linked from its parent's family at its
    /// parent's slot, and every link leads to the family of that member's children.
    #[cfg(test)]
    pub(crate) fn check_links(&self) {
        for (&p, &at) in &self.index {
            let f = &self.slab[at as usize];
            assert_eq!(f.parent, Some(p));
            assert!(!f.is_empty(), "{p}: an empty family is kept");
            let (grand, i) = slot(p).expect("a tile of the scheme");
            assert_eq!(self.family(grand).expect("the family above").kids[i], at);
        }
        let families = std::iter::once((None, &self.roots)).chain(
            self.index
                .iter()
                .map(|(&p, &at)| (Some(p), &self.slab[at as usize])),
        );
        for (parent, f) in families {
            let children: Vec<TileKey> = match parent {
                None => GLOBE_SCHEME.roots().to_vec(),
                Some(p) => GLOBE_SCHEME.children(p).to_vec(),
            };
            for (i, &kid) in f.kids.iter().enumerate() {
                if kid != NOWHERE {
                    assert_eq!(self.slab[kid as usize].parent, Some(children[i]));
                    assert_eq!(self.index.get(&children[i]), Some(&kid));
                }
            }
        }
        for &at in &self.free {
            assert_eq!(self.slab[at as usize].parent, None);
        }
    }

    /// How many families the slab holds (the roots' not counted).
    #[cfg(test)]
    pub(crate) fn families(&self) -> usize {
        self.index.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_are_found_where_they_were_put_and_families_go_with_their_last_record() {
        let mut table = NodeTable::<u32>::default();
        // A polar tile with three children, an ordinary one with four, and a root.
        let polar = (0..64)
            .filter_map(|y| GLOBE_SCHEME.key(6, 0, y))
            .find(|&k| GLOBE_SCHEME.children(k).len() == 3)
            .expect("a tile with three children");
        let ordinary = TileKey::new(6, 20, 20);
        for parent in [polar, ordinary] {
            for (i, &child) in GLOBE_SCHEME.children(parent).iter().enumerate() {
                table.insert(child, i as u32 + 10);
            }
        }
        table.check_links();
        assert_eq!(GLOBE_SCHEME.children(polar).len(), 3);
        table.insert(TileKey::ROOT_EAST, 99);
        for parent in [polar, ordinary] {
            for (i, &child) in GLOBE_SCHEME.children(parent).iter().enumerate() {
                assert_eq!(table.get(child), Some(&(i as u32 + 10)));
                let family = table.family(Some(parent)).expect("family");
                assert_eq!(family.members()[i], Some(i as u32 + 10));
            }
            // The family is found from the link its parent's record carries, and a wrong
            // link falls back to the lookup by key.
            let (grand, i) = slot(parent).expect("a tile");
            let at = table.family(grand).expect("family above").kids()[i];
            assert_ne!(at, NOWHERE);
            assert_eq!(table.get_with_children_at(parent), (table.get(parent), at));
            let by_link = table.family_at(parent, at).expect("family");
            assert_eq!(
                by_link.members(),
                table.family(Some(parent)).expect("family").members()
            );
            let other = if parent == polar { ordinary } else { polar };
            let wrong = table.family_at(other, at).expect("family");
            assert_eq!(
                wrong.members(),
                table.family(Some(other)).expect("family").members()
            );
        }
        assert_eq!(table.get(TileKey::ROOT_EAST), Some(&99));
        assert_eq!(table.get(TileKey::ROOT_WEST), None);
        assert_eq!(table.get(polar), None);
        // Removing all but one keeps the family; removing the last drops it, and the
        // families above it that held only the way to it.
        let before = table.families();
        let children = GLOBE_SCHEME.children(ordinary);
        for &child in &children[1..] {
            table.remove(child);
        }
        assert!(table.contains_key(children[0]));
        assert_eq!(table.families(), before);
        table.check_links();
        table.remove(children[0]);
        assert!(table.families() < before);
        assert!(table.family(Some(ordinary)).is_none());
        table.check_links();
        // Clearing every record through update_children drops the family too, and with it
        // the last of the chain to the roots.
        table.update_children(polar, |_, m| *m = None);
        assert_eq!(table.families(), 0);
        table.check_links();
        // Freed slots are used again.
        table.insert(children[2], 7);
        table.check_links();
        assert_eq!(table.slab.len(), before);
        // Keys that are no tiles of the scheme (inside a merged polar tile) are ignored.
        let inside = TileKey::new(8, 1, 0);
        assert!(!GLOBE_SCHEME.is_valid(inside));
        table.insert(inside, 5);
        assert_eq!(table.get(inside), None);
        table.check_links();
    }
}
