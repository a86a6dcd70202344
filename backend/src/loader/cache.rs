//! The two brick caches of G08 §4: the CPU level-2 cache of decoded bricks
//! (LRU, fixed byte budget) and the GPU brick pool (a fixed number of slots,
//! LRU, with the slots of the current cut pinned).

use crate::store::{Brick, NodeKey};
use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::Arc;

/// Bytes a decoded brick takes in the CPU cache.
pub(crate) fn brick_bytes(data: &Brick) -> u64 {
    data.bytes()
}

/// CPU level-2 cache of decoded bricks, least recently used first out, never
/// above its byte budget (G08 §4 "the CPU cache being used as a larger
/// level-2 cache … managed using a LRU policy").
#[derive(Debug)]
pub(crate) struct ByteLru {
    map: HashMap<NodeKey, (Arc<Brick>, u64)>,
    order: BTreeMap<u64, NodeKey>,
    bytes: u64,
    budget: u64,
    clock: u64,
}

impl ByteLru {
    pub fn new(budget: u64) -> Self {
        ByteLru {
            map: HashMap::new(),
            order: BTreeMap::new(),
            bytes: 0,
            budget,
            clock: 0,
        }
    }

    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn contains(&self, key: NodeKey) -> bool {
        self.map.contains_key(&key)
    }

    /// The brick without touching its recency.
    pub fn peek(&self, key: NodeKey) -> Option<&Arc<Brick>> {
        self.map.get(&key).map(|(d, _)| d)
    }

    /// The brick, marked most recently used.
    pub fn get(&mut self, key: NodeKey) -> Option<Arc<Brick>> {
        self.touch(key);
        self.peek(key).cloned()
    }

    /// Marks a brick most recently used (no-op when absent).
    pub fn touch(&mut self, key: NodeKey) {
        if let Some((_, stamp)) = self.map.get_mut(&key) {
            self.order.remove(stamp);
            self.clock += 1;
            *stamp = self.clock;
            self.order.insert(self.clock, key);
        }
    }

    /// Inserts a brick as most recently used, evicting the least recently
    /// used ones until the budget holds. A brick larger than the whole budget
    /// is not kept (returns false).
    pub fn insert(&mut self, key: NodeKey, data: Arc<Brick>) -> bool {
        self.remove(key);
        let size = brick_bytes(&data);
        if size > self.budget {
            return false;
        }
        self.evict_for(size);
        self.clock += 1;
        self.order.insert(self.clock, key);
        self.map.insert(key, (data, self.clock));
        self.bytes += size;
        true
    }

    /// A new byte budget, evicting the least recently used bricks until
    /// it holds.
    pub fn set_budget(&mut self, budget: u64) {
        self.budget = budget;
        self.evict_for(0);
    }

    /// Evicts the least recently used bricks until `room` more bytes fit
    /// the budget (`room` at most the budget).
    fn evict_for(&mut self, room: u64) {
        while self.bytes + room > self.budget {
            let (&stamp, &victim) = self.order.iter().next().expect("bytes > 0 means entries");
            self.order.remove(&stamp);
            let (d, _) = self.map.remove(&victim).unwrap();
            self.bytes -= brick_bytes(&d);
        }
    }

    pub fn remove(&mut self, key: NodeKey) {
        if let Some((d, stamp)) = self.map.remove(&key) {
            self.order.remove(&stamp);
            self.bytes -= brick_bytes(&d);
        }
    }
}

/// The GPU brick pool as the loader sees it: which node owns which slot.
/// Slots stay assigned while their brick is resident; slots of nodes pinned
/// this frame (the current cut) are never evicted; others go least recently
/// used first (G08 §4 "GPU texture cache … managed as a pool of blocks …
/// LRU").
#[derive(Debug)]
pub(crate) struct SlotPool {
    resident: HashMap<NodeKey, (u32, u64)>,
    order: BTreeMap<u64, NodeKey>,
    free: Vec<u32>,
    pinned: HashSet<NodeKey>,
    clock: u64,
}

impl SlotPool {
    pub fn new(capacity: u32) -> Self {
        SlotPool {
            resident: HashMap::new(),
            order: BTreeMap::new(),
            free: (0..capacity).rev().collect(),
            pinned: HashSet::new(),
            clock: 0,
        }
    }

    /// Unpins everything: a new cut is about to be built.
    pub fn begin_frame(&mut self) {
        self.pinned.clear();
    }

    pub fn in_use(&self) -> usize {
        self.resident.len()
    }

    #[cfg(test)]
    pub fn pinned(&self) -> usize {
        self.pinned.len()
    }

    pub fn slot(&self, key: NodeKey) -> Option<u32> {
        self.resident.get(&key).map(|&(s, _)| s)
    }

    /// Slots a new brick could take now: free ones and unpinned residents.
    pub fn available(&self) -> usize {
        self.free.len() + self.resident.len() - self.pinned.len()
    }

    /// Pins a resident brick for this frame and marks it most recently used.
    pub fn pin(&mut self, key: NodeKey) -> Option<u32> {
        let (slot, stamp) = self.resident.get_mut(&key)?;
        self.order.remove(stamp);
        self.clock += 1;
        *stamp = self.clock;
        self.order.insert(self.clock, key);
        self.pinned.insert(key);
        Some(*slot)
    }

    /// Gives `key` a slot (free, or the least recently used unpinned one) and
    /// pins it. Returns the slot and the node evicted from it, if any; `None`
    /// when every slot is pinned.
    pub fn allocate(&mut self, key: NodeKey) -> Option<(u32, Option<NodeKey>)> {
        debug_assert!(!self.resident.contains_key(&key));
        let (slot, evicted) = match self.free.pop() {
            Some(s) => (s, None),
            None => {
                let (&stamp, &victim) =
                    self.order.iter().find(|(_, k)| !self.pinned.contains(*k))?;
                self.order.remove(&stamp);
                let (s, _) = self.resident.remove(&victim).unwrap();
                (s, Some(victim))
            }
        };
        self.clock += 1;
        self.order.insert(self.clock, key);
        self.resident.insert(key, (slot, self.clock));
        self.pinned.insert(key);
        Some((slot, evicted))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k(x: u32) -> NodeKey {
        NodeKey::new(3, x, 0, 0)
    }

    fn brick(n: usize, v: f32) -> Arc<Brick> {
        Arc::new(Brick {
            values: vec![v; n],
            cells: None,
            layered: None,
        })
    }

    #[test]
    fn byte_lru_evicts_least_recent_and_keeps_the_budget() {
        let mut c = ByteLru::new(3 * 400);
        for x in 0..3 {
            assert!(c.insert(k(x), brick(100, 0.0)));
        }
        assert_eq!(c.bytes(), 1200);
        c.touch(k(0));
        c.insert(k(3), brick(100, 0.0));
        assert!(c.contains(k(0)) && !c.contains(k(1)) && c.contains(k(2)) && c.contains(k(3)));
        // a bigger brick evicts two
        c.insert(k(4), brick(200, 0.0));
        assert_eq!(c.len(), 2);
        assert!(c.contains(k(3)) && c.contains(k(4)));
        assert_eq!(c.bytes(), 1200);
        // too big for the budget: not kept, nothing evicted
        assert!(!c.insert(k(5), brick(301, 0.0)));
        assert_eq!(c.len(), 2);
        // re-inserting replaces
        c.insert(k(4), brick(50, 1.0));
        assert_eq!(c.bytes(), 600);
        assert_eq!(c.peek(k(4)).unwrap().values[0], 1.0);
        // a smaller budget evicts the least recent until it holds
        c.insert(k(6), brick(100, 0.0));
        c.touch(k(3));
        c.set_budget(500);
        assert!(c.contains(k(3)) && !c.contains(k(4)) && !c.contains(k(6)));
        assert_eq!(c.bytes(), 400);
        assert!(c.insert(k(7), brick(25, 0.0)) && c.contains(k(3)));
        assert!(c.bytes() <= 500);
    }

    #[test]
    fn slot_pool_pins_and_evicts_lru() {
        let mut p = SlotPool::new(3);
        p.begin_frame();
        assert_eq!(p.allocate(k(0)), Some((0, None)));
        assert_eq!(p.allocate(k(1)), Some((1, None)));
        assert_eq!(p.allocate(k(2)), Some((2, None)));
        assert_eq!(p.available(), 0);
        assert_eq!(p.allocate(k(3)), None, "everything pinned");
        p.begin_frame();
        assert_eq!(p.available(), 3);
        assert_eq!(p.pin(k(0)), Some(0));
        // k(1) is the least recently used unpinned brick
        assert_eq!(p.allocate(k(3)), Some((1, Some(k(1)))));
        assert_eq!(p.slot(k(1)), None);
        assert_eq!(p.allocate(k(4)), Some((2, Some(k(2)))));
        assert_eq!(p.allocate(k(5)), None);
        assert_eq!(p.in_use(), 3);
        assert_eq!(p.pinned(), 3);
    }
}
