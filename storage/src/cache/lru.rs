//! Least recently used: evict the page whose last access is oldest. Priorities are ignored.

use super::ranked::Ranked;
use super::{CachePolicy, PageKey};

/// Evicts the least recently used page.
#[derive(Debug, Default)]
pub struct Lru {
    // One score for all: the order is the last-access time alone.
    ranked: Ranked,
}

impl CachePolicy for Lru {
    fn insert(&mut self, key: PageKey, _priority: f64, now: u64) {
        self.ranked.put(key, 0.0, now);
    }
    fn access(&mut self, key: PageKey, _priority: f64, now: u64) {
        self.ranked.put(key, 0.0, now);
    }
    fn set_priority(&mut self, _key: PageKey, _priority: f64, _last: u64) {}
    fn remove(&mut self, key: PageKey) {
        self.ranked.remove(key);
    }
    fn victim(&mut self) -> Option<PageKey> {
        self.ranked.pop_min()
    }
    fn clear(&mut self) {
        self.ranked.clear();
    }
}
