//! [`RangeAllocator`]: sub-allocation of one fixed buffer into variable-sized ranges.
//!
//! Free space is a sorted list of disjoint ranges, merged with their neighbours when freed;
//! allocation takes the first free range that fits (first fit keeps the low end of the buffer
//! packed, which suits tiles of similar sizes coming and going). Pure CPU bookkeeping: the
//! GPU buffer it describes never grows.

use std::ops::Range;

/// First-fit allocator of ranges in `0..capacity`.
#[derive(Clone, Debug)]
pub struct RangeAllocator {
    capacity: u32,
    /// Free ranges, sorted by start, disjoint and never adjacent.
    free: Vec<Range<u32>>,
    used: u32,
}

impl RangeAllocator {
    /// Everything free.
    pub fn new(capacity: u32) -> Self {
        Self {
            capacity,
            free: std::iter::once(0..capacity)
                .filter(|r| !r.is_empty())
                .collect(),
            used: 0,
        }
    }

    /// A range of `len` units, or `None` if no free range is that long. `len` 0 gets an
    /// empty range.
    pub fn allocate(&mut self, len: u32) -> Option<Range<u32>> {
        if len == 0 {
            return Some(0..0);
        }
        let at = self.free.iter().position(|r| r.len() as u32 >= len)?;
        let start = self.free[at].start;
        self.free[at].start += len;
        if self.free[at].is_empty() {
            self.free.remove(at);
        }
        self.used += len;
        Some(start..start + len)
    }

    /// Raises the capacity to `capacity` (never lowers it): the new units are free.
    pub fn grow(&mut self, capacity: u32) {
        if capacity <= self.capacity {
            return;
        }
        let added = self.capacity..capacity;
        match self.free.last_mut() {
            Some(last) if last.end == added.start => last.end = added.end,
            _ => self.free.push(added),
        }
        self.capacity = capacity;
    }

    /// Returns a range from [`RangeAllocator::allocate`].
    pub fn free(&mut self, range: Range<u32>) {
        if range.is_empty() {
            return;
        }
        debug_assert!(range.end <= self.capacity);
        let at = self.free.partition_point(|r| r.start < range.start);
        debug_assert!(
            at == 0 || self.free[at - 1].end <= range.start,
            "double free"
        );
        debug_assert!(
            at == self.free.len() || range.end <= self.free[at].start,
            "double free"
        );
        self.used -= range.len() as u32;
        let joins_prev = at > 0 && self.free[at - 1].end == range.start;
        let joins_next = at < self.free.len() && self.free[at].start == range.end;
        match (joins_prev, joins_next) {
            (true, true) => {
                self.free[at - 1].end = self.free[at].end;
                self.free.remove(at);
            }
            (true, false) => self.free[at - 1].end = range.end,
            (false, true) => self.free[at].start = range.start,
            (false, false) => self.free.insert(at, range),
        }
    }

    /// Units in use.
    pub fn used(&self) -> u32 {
        self.used
    }

    /// Total units.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// The longest free range (what the next allocation can get at most).
    pub fn largest_free(&self) -> u32 {
        self.free.iter().map(|r| r.len() as u32).max().unwrap_or(0)
    }

    /// Number of separate free ranges (1 when nothing is fragmented).
    pub fn free_ranges(&self) -> usize {
        self.free.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn growing_adds_free_room_at_the_end() {
        let mut a = RangeAllocator::new(10);
        assert_eq!(a.allocate(8), Some(0..8));
        assert_eq!(a.allocate(5), None);
        a.grow(20);
        assert_eq!(a.allocate(5), Some(8..13));
        assert_eq!(a.allocate(7), Some(13..20));
        assert_eq!(a.allocate(1), None);
        a.grow(5);
        assert_eq!(a.capacity(), 20);
        let mut b = RangeAllocator::new(4);
        assert_eq!(b.allocate(4), Some(0..4));
        b.grow(6);
        assert_eq!(b.allocate(2), Some(4..6));
    }

    #[test]
    fn first_fit_and_merging() {
        let mut a = RangeAllocator::new(100);
        let x = a.allocate(30).expect("x");
        let y = a.allocate(30).expect("y");
        let z = a.allocate(30).expect("z");
        assert_eq!((x.clone(), y.clone(), z.clone()), (0..30, 30..60, 60..90));
        assert!(a.allocate(11).is_none(), "only 10 left");
        a.free(y);
        assert_eq!(a.allocate(20), Some(30..50), "first fit reuses the hole");
        a.free(30..50);
        a.free(x);
        a.free(z);
        assert_eq!((a.used(), a.free_ranges(), a.largest_free()), (0, 1, 100));
        assert_eq!(a.allocate(100), Some(0..100));
        assert_eq!(a.allocate(0), Some(0..0));
    }

    /// Random allocations and frees against a unit-by-unit model: ranges never overlap, the
    /// free list stays sorted and merged, and an allocation fails only when no gap is long
    /// enough.
    #[test]
    fn random_workload_matches_a_bitmap_model() {
        let capacity = 1000u32;
        let mut a = RangeAllocator::new(capacity);
        let mut owner = vec![false; capacity as usize];
        let mut live: Vec<Range<u32>> = Vec::new();
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = |n: u32| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((state >> 33) % u64::from(n)) as u32
        };
        for _ in 0..20_000 {
            if live.is_empty() || next(3) > 0 {
                let len = 1 + next(120);
                let longest_gap = owner
                    .split(|&o| o)
                    .map(|g| g.len() as u32)
                    .max()
                    .unwrap_or(0);
                match a.allocate(len) {
                    Some(r) => {
                        assert_eq!(r.len() as u32, len);
                        for u in r.clone() {
                            assert!(!owner[u as usize], "overlap at {u}");
                            owner[u as usize] = true;
                        }
                        live.push(r);
                    }
                    None => assert!(
                        longest_gap < len,
                        "refused {len} with a gap of {longest_gap}"
                    ),
                }
            } else {
                let r = live.swap_remove(next(live.len() as u32) as usize);
                for u in r.clone() {
                    owner[u as usize] = false;
                }
                a.free(r);
            }
            let used = owner.iter().filter(|&&o| o).count() as u32;
            assert_eq!(a.used(), used);
            let gaps = owner.split(|&o| o).filter(|g| !g.is_empty()).count();
            assert_eq!(a.free_ranges(), gaps, "free list not merged");
        }
    }
}
