//! Resident keys ordered by (score, last access, key): the one structure behind the LRU, DoV
//! and DoV-Time policies. Every operation is O(log n); the victim is the first element.

use std::cmp::Ordering;
use std::collections::{BTreeSet, HashMap};

use super::PageKey;

/// An f64 ordered by `total_cmp`, so that scores can key a `BTreeSet` (a total order; NaNs
/// go to the ends).
#[derive(Clone, Copy, Debug)]
struct Score(f64);

impl PartialEq for Score {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Score {}
impl PartialOrd for Score {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Score {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0)
    }
}

#[derive(Debug, Default)]
pub(crate) struct Ranked {
    order: BTreeSet<(Score, u64, PageKey)>,
    place: HashMap<PageKey, (Score, u64)>,
}

impl Ranked {
    /// Sets `key`'s score and last access, inserting it if new.
    pub fn put(&mut self, key: PageKey, score: f64, last: u64) {
        if let Some((s, l)) = self.place.insert(key, (Score(score), last)) {
            self.order.remove(&(s, l, key));
        }
        self.order.insert((Score(score), last, key));
    }

    pub fn remove(&mut self, key: PageKey) {
        if let Some((s, l)) = self.place.remove(&key) {
            self.order.remove(&(s, l, key));
        }
    }

    /// Removes and returns the key of smallest score, the least recent among equal scores.
    pub fn pop_min(&mut self) -> Option<PageKey> {
        let (_, _, key) = self.order.pop_first()?;
        self.place.remove(&key);
        Some(key)
    }

    pub fn clear(&mut self) {
        self.order.clear();
        self.place.clear();
    }
}
