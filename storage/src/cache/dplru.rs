//! The distance-priority-LRU policy of REVIEW (thesis §4.2.4): evict the page of smallest
//! `f = α·pp + β·pd + γ·pl`, with α = β = γ = 1/3.
//!
//! The thesis ranks the other way round (it replaces the *largest* f, built from a level
//! number that grows downwards, a distance and an age); here every term is a *keep* term in
//! [0, 1], so the cache's convention holds (the smallest number goes):
//!
//! - `pp` = the node's normalised level priority, 1 for the root, 0 for a leaf;
//! - `pd` = 1 − the normalised block distance from the node's box to the query cell
//!   (1 for a node that meets the cell);
//! - `pl` = 1 − the normalised age: `age = now − T` (T = the page's last access, in the cache's
//!   logical time), normalised by the largest age among the resident pages when a victim is
//!   chosen (the least recent resident has `pl` = 0, the most recent 1).
//!
//! The storage crate knows no geometry: the caller passes `priority = α·pp + β·pd` (one
//! number, in [0, 2/3] with the thesis's weights) and updates it with
//! [`PageCache::set_priority`](super::PageCache::set_priority) when the query cell moves; the
//! policy adds `γ·pl`. Ties go to the least recent, then the smaller key.
//!
//! Cost: the age term's normaliser changes with every request, so the order of the residents
//! is not fixed between requests; choosing a victim scans them, O(n). Insert, access, priority
//! change and removal are O(1).

use std::collections::HashMap;

use super::{CachePolicy, PageKey};

/// The thesis's weight of the age term, γ = 1/3 (α = β = 1/3 are the caller's).
pub const DEFAULT_GAMMA: f64 = 1.0 / 3.0;

/// Evicts the page of smallest `priority + γ·pl` (module docs).
#[derive(Debug)]
pub struct Dplru {
    gamma: f64,
    /// Priority and last access of every resident page.
    pages: HashMap<PageKey, (f64, u64)>,
}

impl Dplru {
    /// A DPLRU policy weighing the age term by `gamma`.
    pub fn new(gamma: f64) -> Self {
        Self { gamma, pages: HashMap::new() }
    }

    /// The weight of the age term.
    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// The key `f` of a page of `priority` last accessed at `last`, when the most recent
    /// resident was accessed at `newest` and the least recent at `oldest`.
    pub fn f(&self, priority: f64, last: u64, oldest: u64, newest: u64) -> f64 {
        let span = newest.saturating_sub(oldest);
        let pl = if span == 0 { 1.0 } else { 1.0 - newest.saturating_sub(last) as f64 / span as f64 };
        priority + self.gamma * pl
    }
}

impl Default for Dplru {
    fn default() -> Self {
        Self::new(DEFAULT_GAMMA)
    }
}

impl CachePolicy for Dplru {
    fn insert(&mut self, key: PageKey, priority: f64, now: u64) {
        self.pages.insert(key, (priority, now));
    }
    fn access(&mut self, key: PageKey, priority: f64, now: u64) {
        self.pages.insert(key, (priority, now));
    }
    fn set_priority(&mut self, key: PageKey, priority: f64, last: u64) {
        self.pages.insert(key, (priority, last));
    }
    fn remove(&mut self, key: PageKey) {
        self.pages.remove(&key);
    }
    fn victim(&mut self) -> Option<PageKey> {
        let oldest = self.pages.values().map(|p| p.1).min()?;
        let newest = self.pages.values().map(|p| p.1).max()?;
        let (&key, _) = self.pages.iter().min_by(|(ka, a), (kb, b)| {
            let (fa, fb) = (self.f(a.0, a.1, oldest, newest), self.f(b.0, b.1, oldest, newest));
            fa.total_cmp(&fb).then(a.1.cmp(&b.1)).then(ka.cmp(kb))
        })?;
        self.pages.remove(&key);
        Some(key)
    }
    fn clear(&mut self) {
        self.pages.clear();
    }
}
