//! The layer's per-tile records for selection, stored by family.
//!
//! Selection reads a tile's children together every time it refines it, and each read is a
//! cache miss on a cold table (the rasteriser runs between frames and evicts it): profiling
//! the Alps dive put two thirds of the selection's time in the record lookups. So records
//! live in families, the children of one parent side by side under the parent's key: one
//! hash probe and a few adjacent cache lines serve all of a tile's children, where one probe
//! per child did before. The roots form a family of their own outside the map.
//!
//! A family exists while any of its records does; a record may be missing (the layer then
//! estimates one on demand, see `TerrainLayer::estimate`).

use globus_tiling::{GLOBE_SCHEME, TileKey};
use rustc_hash::FxHashMap;

/// The most children a tile has.
const MAX_CHILDREN: usize = 4;

/// One parent's children's records, in the order of `GLOBE_SCHEME.children(parent)`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Family<N> {
    members: [Option<N>; MAX_CHILDREN],
}

impl<N: Copy> Family<N> {
    const EMPTY: Self = Self {
        members: [None; MAX_CHILDREN],
    };

    /// The records, indexed like the parent's children.
    pub(crate) fn members(&self) -> &[Option<N>; MAX_CHILDREN] {
        &self.members
    }

    fn is_empty(&self) -> bool {
        self.members.iter().all(Option::is_none)
    }
}

/// Records keyed by tile, stored by family.
#[derive(Clone, Debug)]
pub(crate) struct NodeTable<N> {
    roots: Family<N>,
    families: FxHashMap<TileKey, Family<N>>,
}

impl<N: Copy> Default for NodeTable<N> {
    fn default() -> Self {
        Self {
            roots: Family::EMPTY,
            families: FxHashMap::default(),
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
            Some(p) => self.families.get(&p),
        }
    }

    fn family_mut(&mut self, parent: Option<TileKey>) -> &mut Family<N> {
        match parent {
            None => &mut self.roots,
            Some(p) => self.families.entry(p).or_insert(Family::EMPTY),
        }
    }

    /// The record of `key`.
    pub(crate) fn get(&self, key: TileKey) -> Option<&N> {
        let (parent, i) = slot(key)?;
        self.family(parent)?.members[i].as_ref()
    }

    /// Whether `key` has a record.
    #[cfg(test)]
    pub(crate) fn contains_key(&self, key: TileKey) -> bool {
        self.get(key).is_some()
    }

    /// Sets the record of `key` (a key that is not a tile of the scheme is ignored).
    pub(crate) fn insert(&mut self, key: TileKey, node: N) {
        if let Some((parent, i)) = slot(key) {
            self.family_mut(parent).members[i] = Some(node);
        }
    }

    /// Calls `f` on the record of each of `parent`'s children (with its index), creating
    /// the family if needed; `f` may set or clear them.
    pub(crate) fn update_children(
        &mut self,
        parent: TileKey,
        mut f: impl FnMut(usize, &mut Option<N>),
    ) {
        let family = self.family_mut(Some(parent));
        for (i, member) in family.members.iter_mut().enumerate() {
            f(i, member);
        }
        if family.is_empty() {
            self.families.remove(&parent);
        }
    }

    /// Drops the record of `key`.
    pub(crate) fn remove(&mut self, key: TileKey) {
        let Some((parent, i)) = slot(key) else {
            return;
        };
        match parent {
            None => self.roots.members[i] = None,
            Some(p) => {
                if let Some(family) = self.families.get_mut(&p) {
                    family.members[i] = None;
                    if family.is_empty() {
                        self.families.remove(&p);
                    }
                }
            }
        }
    }

    /// How many families the map holds (the roots' not counted).
    #[cfg(test)]
    pub(crate) fn families(&self) -> usize {
        self.families.len()
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
        assert_eq!(GLOBE_SCHEME.children(polar).len(), 3);
        table.insert(TileKey::ROOT_EAST, 99);
        assert_eq!(table.families(), 2);
        for parent in [polar, ordinary] {
            for (i, &child) in GLOBE_SCHEME.children(parent).iter().enumerate() {
                assert_eq!(table.get(child), Some(&(i as u32 + 10)));
                let family = table.family(Some(parent)).expect("family");
                assert_eq!(family.members()[i], Some(i as u32 + 10));
            }
        }
        assert_eq!(table.get(TileKey::ROOT_EAST), Some(&99));
        assert_eq!(table.get(TileKey::ROOT_WEST), None);
        assert_eq!(table.get(polar), None);
        // Removing all but one keeps the family; removing the last drops it.
        let children = GLOBE_SCHEME.children(ordinary);
        for &child in &children[1..] {
            table.remove(child);
        }
        assert!(table.contains_key(children[0]));
        assert_eq!(table.families(), 2);
        table.remove(children[0]);
        assert_eq!(table.families(), 1);
        // Clearing every record through update_children drops the family too.
        table.update_children(polar, |_, m| *m = None);
        assert_eq!(table.families(), 0);
        // Keys that are no tiles of the scheme (inside a merged polar tile) are ignored.
        let inside = TileKey::new(8, 1, 0);
        assert!(!GLOBE_SCHEME.is_valid(inside));
        table.insert(inside, 5);
        assert_eq!(table.get(inside), None);
        assert_eq!(table.families(), 0);
    }
}
