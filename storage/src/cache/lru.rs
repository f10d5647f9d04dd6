//! Least recently used: evict the page whose last access is oldest. Priorities are ignored.
//!
//! The recency list is the `lru` crate's (O(1) per access and eviction); the policies that rank
//! by a priority share [`super::ranked::Ranked`] (O(log n)). With every access at its own
//! logical time the two give the same victims; docs/cache.md ("The lru crate") has the speeds.

use lru::LruCache;

use super::{CachePolicy, PageKey};

/// Evicts the least recently used page.
#[derive(Debug)]
pub struct Lru {
    // Unbounded: the page cache, not the list, decides when to evict (its limits are in pages
    // and bytes); the list only orders the resident keys.
    order: LruCache<PageKey, ()>,
}

impl Default for Lru {
    fn default() -> Self {
        Lru { order: LruCache::unbounded() }
    }
}

impl CachePolicy for Lru {
    fn insert(&mut self, key: PageKey, _priority: f64, _now: u64) {
        self.order.put(key, ());
    }
    fn access(&mut self, key: PageKey, _priority: f64, _now: u64) {
        // A key the policy does not hold yet (the cache's first sight of it) is added.
        if self.order.get(&key).is_none() {
            self.order.put(key, ());
        }
    }
    fn set_priority(&mut self, _key: PageKey, _priority: f64, _last: u64) {}
    fn remove(&mut self, key: PageKey) {
        self.order.pop(&key);
    }
    fn victim(&mut self) -> Option<PageKey> {
        self.order.pop_lru().map(|(key, ())| key)
    }
    fn clear(&mut self) {
        self.order.clear();
    }
}
