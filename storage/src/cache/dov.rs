//! The DoV policy (thesis §5.7.1): evict the page of smallest priority, the caller's DoV of
//! the page's node, so visually important nodes stay resident; ties go to the least recent.

use super::ranked::Ranked;
use super::{CachePolicy, PageKey};

/// Evicts the page of smallest priority (DoV), the least recently used among equals.
#[derive(Debug, Default)]
pub struct Dov {
    ranked: Ranked,
}

impl CachePolicy for Dov {
    fn insert(&mut self, key: PageKey, priority: f64, now: u64) {
        self.ranked.put(key, priority, now);
    }
    fn access(&mut self, key: PageKey, priority: f64, now: u64) {
        self.ranked.put(key, priority, now);
    }
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
