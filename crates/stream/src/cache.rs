//! A least-recently-used cache with a byte budget (Zeitler 2015, section 4.8), keyed by tile.
//!
//! "Recently used" is a frame stamp set with [`LruCache::touch`]; eviction removes the oldest
//! entries that the caller does not protect until the cache fits its budget. Entries in use
//! this frame are never evicted, so the cache may stay over budget while the view needs more
//! than it holds: [`LruCache::is_over_budget`] tells the engine to lower detail.

use globus_tiling::TileKey;
use rustc_hash::FxHashMap;

struct Entry<V> {
    value: V,
    bytes: usize,
    last_used: u64,
}

/// A byte-budgeted LRU map from tile keys to values.
pub struct LruCache<V> {
    map: FxHashMap<TileKey, Entry<V>>,
    bytes: usize,
    budget: usize,
    /// The latest frame stamp any entry was used at, and the bytes of the entries used then
    /// (what the view needs now: the budget must hold at least that).
    latest: u64,
    latest_bytes: usize,
}

impl<V> LruCache<V> {
    /// An empty cache that tries to hold at most `budget_bytes`.
    pub fn new(budget_bytes: usize) -> Self {
        Self {
            map: FxHashMap::default(),
            bytes: 0,
            budget: budget_bytes,
            latest: 0,
            latest_bytes: 0,
        }
    }

    /// Counts `bytes` as used at frame `now` (after any use at an earlier stamp was taken
    /// back with [`LruCache::unnote`]).
    fn note(&mut self, now: u64, bytes: usize) {
        if now > self.latest {
            self.latest = now;
            self.latest_bytes = 0;
        }
        if now == self.latest {
            self.latest_bytes += bytes;
        }
    }

    /// Takes back an entry's bytes from the latest frame's use, if it was used then.
    fn unnote(&mut self, last_used: u64, bytes: usize) {
        if last_used == self.latest {
            self.latest_bytes -= bytes;
        }
    }

    /// Inserts (or replaces) a value of `bytes` bytes, used at frame `now`.
    pub fn insert(&mut self, key: TileKey, value: V, bytes: usize, now: u64) {
        if let Some(old) = self.map.insert(
            key,
            Entry {
                value,
                bytes,
                last_used: now,
            },
        ) {
            self.bytes -= old.bytes;
            self.unnote(old.last_used, old.bytes);
        }
        self.bytes += bytes;
        self.note(now, bytes);
    }

    /// The value for `key`.
    pub fn get(&self, key: TileKey) -> Option<&V> {
        self.map.get(&key).map(|e| &e.value)
    }

    /// The value for `key`, to change in place (its recency stays).
    pub fn get_mut(&mut self, key: TileKey) -> Option<&mut V> {
        self.map.get_mut(&key).map(|e| &mut e.value)
    }

    /// Sets the size of `key`'s value to `bytes` (after it grew or shrank in place).
    pub fn resize(&mut self, key: TileKey, bytes: usize) {
        if let Some(e) = self.map.get_mut(&key) {
            self.bytes = self.bytes - e.bytes + bytes;
            let (old, last_used) = (e.bytes, e.last_used);
            e.bytes = bytes;
            self.unnote(last_used, old);
            self.note(last_used, bytes);
        }
    }

    /// Whether `key` is cached.
    pub fn contains(&self, key: TileKey) -> bool {
        self.map.contains_key(&key)
    }

    /// Marks `key` used at frame `now`; returns false if it is not cached or was already
    /// touched at `now`.
    pub fn touch(&mut self, key: TileKey, now: u64) -> bool {
        match self.map.get_mut(&key) {
            Some(e) if e.last_used != now => {
                let (before, bytes) = (e.last_used, e.bytes);
                e.last_used = now;
                self.unnote(before, bytes);
                self.note(now, bytes);
                true
            }
            _ => false,
        }
    }

    /// Evicts least recently used entries, skipping those for which `protect(key, last_used)`
    /// is true, until the cache fits its budget; tiles of the coarsest levels go only after
    /// every finer one ([`globus_tiling::keeps_longer`]). Returns the evicted keys.
    pub fn evict_to_budget(&mut self, protect: impl Fn(TileKey, u64) -> bool) -> Vec<TileKey> {
        if self.bytes <= self.budget {
            return Vec::new();
        }
        let mut candidates: Vec<(bool, u64, TileKey)> = self
            .map
            .iter()
            .filter(|(k, e)| !protect(**k, e.last_used))
            .map(|(k, e)| (globus_tiling::keeps_longer(*k), e.last_used, *k))
            .collect();
        candidates.sort_unstable();
        let mut evicted = Vec::new();
        for (_, _, key) in candidates {
            if self.bytes <= self.budget {
                break;
            }
            if let Some(e) = self.map.remove(&key) {
                self.bytes -= e.bytes;
                self.unnote(e.last_used, e.bytes);
                evicted.push(key);
            }
        }
        evicted
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// Bytes of the entries used (touched or inserted) at frame `now`: 0 unless `now` is the
    /// latest stamp given.
    pub fn bytes_used_at(&self, now: u64) -> usize {
        if now == self.latest {
            self.latest_bytes
        } else {
            0
        }
    }

    /// The budget, bytes.
    pub fn budget(&self) -> usize {
        self.budget
    }

    /// Whether the cache holds more than its budget.
    pub fn is_over_budget(&self) -> bool {
        self.bytes > self.budget
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// Whether the cache is empty.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k(x: u32) -> TileKey {
        TileKey::new(10, x, 0)
    }

    #[test]
    fn evicts_oldest_first_and_respects_protection() {
        let mut c = LruCache::new(30);
        for x in 0..5 {
            c.insert(k(x), x, 10, u64::from(x));
        }
        assert_eq!(c.bytes(), 50);
        c.touch(k(0), 9);
        let evicted = c.evict_to_budget(|key, _| key == k(1));
        assert_eq!(evicted, vec![k(2), k(3)]);
        assert!(c.contains(k(0)) && c.contains(k(1)) && c.contains(k(4)));
        assert_eq!(c.bytes(), 30);
    }

    #[test]
    fn the_coarsest_levels_go_last() {
        // A level-1 tile unused for longest, then deeper ones: the deeper ones go first,
        // oldest first, and the coarse tile only when nothing else is left.
        let mut c = LruCache::new(20);
        c.insert(TileKey::new(1, 0, 0), 0, 10, 0);
        for x in 0..3 {
            c.insert(k(x), x, 10, u64::from(x) + 1);
        }
        assert_eq!(c.evict_to_budget(|_, _| false), vec![k(0), k(1)]);
        assert!(c.contains(TileKey::new(1, 0, 0)));
        c.resize(k(2), 15);
        assert_eq!(
            c.evict_to_budget(|_, _| false),
            vec![k(2)],
            "a deeper tile goes even when it alone brings the cache under"
        );
        c.insert(k(3), 3, 15, 5);
        assert_eq!(
            c.evict_to_budget(|key, _| key == k(3)),
            vec![TileKey::new(1, 0, 0)]
        );
    }

    #[test]
    fn stays_over_budget_when_everything_is_protected() {
        let mut c = LruCache::new(5);
        c.insert(k(1), (), 10, 1);
        assert!(c.evict_to_budget(|_, _| true).is_empty());
        assert!(c.is_over_budget());
        c.insert(k(1), (), 4, 2);
        assert_eq!(c.bytes(), 4);
        assert!(!c.is_over_budget());
    }

    #[test]
    fn values_changed_in_place_keep_their_recency_and_count_their_new_size() {
        let mut c = LruCache::new(25);
        c.insert(k(1), vec![1u8], 10, 1);
        c.insert(k(2), vec![2u8], 10, 2);
        if let Some(v) = c.get_mut(k(1)) {
            v.push(9);
        }
        c.resize(k(1), 12);
        c.resize(k(7), 99);
        assert_eq!(c.bytes(), 22);
        assert_eq!(c.get(k(1)), Some(&vec![1, 9]));
        // Still the oldest: it goes first once the budget binds.
        c.insert(k(3), vec![3u8], 10, 3);
        assert_eq!(c.evict_to_budget(|_, _| false), vec![k(1)]);
        assert_eq!(c.bytes(), 20);
    }

    #[test]
    fn the_bytes_used_in_the_latest_frame_are_counted_as_entries_come_go_and_change() {
        let mut c = LruCache::new(100);
        // A fixed pseudo-random sequence of inserts, touches, resizes and evictions over
        // advancing frames, checked against a scan after every step.
        let mut state = 12345u64;
        let mut next = |n: u64| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) % n
        };
        let mut now = 1;
        for step in 0..5000 {
            let key = k(next(40) as u32);
            match next(6) {
                0 => c.insert(key, (), 1 + next(20) as usize, now),
                1 | 2 => {
                    c.touch(key, now);
                }
                3 => c.resize(key, 1 + next(20) as usize),
                4 => {
                    let protect = next(3);
                    c.evict_to_budget(|k, last| last == now || k.x() % 3 == protect as u32);
                }
                _ => now += 1,
            }
            let scan: usize = c
                .map
                .values()
                .filter(|e| e.last_used == now)
                .map(|e| e.bytes)
                .sum();
            assert_eq!(c.bytes_used_at(now), scan, "step {step}");
        }
        assert_eq!(c.bytes_used_at(now + 1), 0);
    }
}
