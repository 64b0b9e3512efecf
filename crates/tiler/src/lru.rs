//! A small least-recently-used map of shared values, for sources that load pieces of their
//! files on demand under a memory budget.

use std::hash::Hash;
use std::sync::Arc;

use rustc_hash::FxHashMap;

/// At most `capacity` values; the least recently used goes first. Lookups are O(1);
/// an insertion that evicts scans the entries once (insertions are rare next to lookups).
pub struct Lru<K, V> {
    map: FxHashMap<K, (Arc<V>, u64)>,
    tick: u64,
    capacity: usize,
}

impl<K: Copy + Eq + Hash, V> Lru<K, V> {
    /// An empty map holding at most `capacity` (at least 1) values.
    pub fn new(capacity: usize) -> Self {
        Self {
            map: FxHashMap::default(),
            tick: 0,
            capacity: capacity.max(1),
        }
    }

    /// The value for `key`, marked as just used.
    pub fn get(&mut self, key: K) -> Option<Arc<V>> {
        self.tick += 1;
        let tick = self.tick;
        let entry = self.map.get_mut(&key)?;
        entry.1 = tick;
        Some(entry.0.clone())
    }

    /// Stores `value`, evicting the least recently used values beyond the capacity.
    pub fn insert(&mut self, key: K, value: Arc<V>) {
        self.tick += 1;
        self.map.insert(key, (value, self.tick));
        while self.map.len() > self.capacity {
            let oldest = self.map.iter().min_by_key(|(_, v)| v.1).map(|(k, _)| *k);
            if let Some(k) = oldest {
                self.map.remove(&k);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evicts_the_least_recently_used() {
        let mut lru = Lru::new(2);
        lru.insert(1, Arc::new("a"));
        lru.insert(2, Arc::new("b"));
        assert!(lru.get(1).is_some());
        lru.insert(3, Arc::new("c"));
        assert!(lru.get(2).is_none(), "2 was used least recently");
        assert!(lru.get(1).is_some() && lru.get(3).is_some());
    }
}
