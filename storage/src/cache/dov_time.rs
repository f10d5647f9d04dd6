//! The DoV-Time policy (thesis §5.7.2): evict the page of smallest `f = DoV + κ·T`, T = the
//! logical time of its last access. A page of high DoV that is no longer requested ages out
//! once recent pages' κ·T has grown past its lead (the DoV policy's "dead entries").

use super::ranked::Ranked;
use super::{CachePolicy, PageKey};

/// The thesis's κ: 0.001 per request.
pub const DEFAULT_KAPPA: f64 = 0.001;

/// Evicts the page of smallest `priority + kappa · T`, the least recent among equals.
#[derive(Debug)]
pub struct DovTime {
    kappa: f64,
    ranked: Ranked,
}

impl DovTime {
    /// A DoV-Time policy weighing one request of recency as `kappa` of priority.
    pub fn new(kappa: f64) -> Self {
        Self { kappa, ranked: Ranked::default() }
    }

    /// The weight of recency.
    pub fn kappa(&self) -> f64 {
        self.kappa
    }

    /// The key `f` that a page of `priority` last accessed at `last` is ranked by.
    pub fn f(&self, priority: f64, last: u64) -> f64 {
        priority + self.kappa * last as f64
    }
}

impl Default for DovTime {
    fn default() -> Self {
        Self::new(DEFAULT_KAPPA)
    }
}

impl CachePolicy for DovTime {
    fn insert(&mut self, key: PageKey, priority: f64, now: u64) {
        self.ranked.put(key, self.f(priority, now), now);
    }
    fn access(&mut self, key: PageKey, priority: f64, now: u64) {
        self.ranked.put(key, self.f(priority, now), now);
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
