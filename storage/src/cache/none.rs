//! The `none` policy: keeps nothing, so every request reads its page (the baseline).

use super::{CachePolicy, PageKey};

/// Admits no page: every request is a miss.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoCache;

impl CachePolicy for NoCache {
    fn admits(&self, _key: PageKey, _priority: f64) -> bool {
        false
    }
    fn insert(&mut self, _key: PageKey, _priority: f64, _now: u64) {}
    fn access(&mut self, _key: PageKey, _priority: f64, _now: u64) {}
    fn remove(&mut self, _key: PageKey) {}
    fn victim(&mut self) -> Option<PageKey> {
        None
    }
    fn clear(&mut self) {}
}
