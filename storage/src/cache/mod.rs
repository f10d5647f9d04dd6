//! The page cache behind every [`PageReader`](crate::PageReader), the one seam through which
//! the query engine reads tree pages and V-pages.
//!
//! A [`PageCache`] keeps page bytes keyed by [`PageKey`] (a caller-chosen file id and a page
//! number), bounded by a page count and a byte count ([`CacheLimits`]), and asks a
//! [`CachePolicy`] which page to drop when a limit is passed. Policies see priorities as plain
//! numbers (the caller passes a node's DoV); this crate never sees geometry.
//!
//! Time is logical: every request advances a counter by one, so a run is deterministic.
//!
//! ```
//! use std::sync::Arc;
//! use hdov_storage::{CacheLimits, PageCache, PageKey, PolicyKind};
//!
//! let mut cache = PageCache::with_kind(CacheLimits::max_pages(2), PolicyKind::Dov);
//! let key = PageKey { file: 0, page: 7 };
//! let page = cache.get_or_load(key, 0.4, || Ok::<_, hdov_storage::Error>(Arc::from(&b"node 7"[..])))?;
//! assert_eq!(&page[..], b"node 7");
//! cache.get_or_load(key, 0.4, || unreachable!("a hit does not load"))?;
//! assert_eq!((cache.stats().hits, cache.stats().misses), (1, 1));
//! # Ok::<(), hdov_storage::Error>(())
//! ```
#![deny(missing_docs)]

use std::collections::HashMap;
use std::fmt;
use std::str::FromStr;
use std::sync::Arc;

mod dov;
mod dov_time;
mod dplru;
mod lru;
mod none;
mod ranked;

pub use dov::Dov;
pub use dov_time::{DEFAULT_KAPPA, DovTime};
pub use dplru::{DEFAULT_GAMMA, Dplru};
pub use lru::Lru;
pub use none::NoCache;

/// Which page: a file's number (a [`PageReader`](crate::PageReader) uses
/// [`PageFile::id`](crate::PageFile::id)) and a page number in that file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct PageKey {
    /// The file's number (its `PageFile::id`, behind a `PageReader`).
    pub file: u32,
    /// The page's number in the file.
    pub page: u64,
}

/// How much a cache may hold. `None` is unlimited; a page is kept only within both limits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheLimits {
    /// Most pages resident at once.
    pub pages: Option<usize>,
    /// Most bytes of page data resident at once.
    pub bytes: Option<u64>,
}

impl CacheLimits {
    /// No limit on either.
    pub const UNLIMITED: CacheLimits = CacheLimits { pages: None, bytes: None };

    /// At most `pages` pages, any bytes.
    pub fn max_pages(pages: usize) -> Self {
        Self { pages: Some(pages), bytes: None }
    }

    /// At most `bytes` bytes, any number of pages.
    pub fn max_bytes(bytes: u64) -> Self {
        Self { pages: None, bytes: Some(bytes) }
    }

    /// Whether a page of `len` bytes fits in an otherwise empty cache.
    fn fits_alone(&self, len: u64) -> bool {
        self.pages.is_none_or(|p| p >= 1) && self.bytes.is_none_or(|b| len <= b)
    }
}

/// What a cache counted since it was made or since [`PageCache::reset_stats`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// Calls of [`PageCache::get_or_load`]; always `hits + misses`.
    pub requests: u64,
    /// Requests answered from the cache.
    pub hits: u64,
    /// Requests that called the loader: pages read from their file (a failed load included).
    pub misses: u64,
    /// Pages dropped to keep within the limits, a just-loaded page that the policy ranked
    /// lowest included. Pages dropped by [`PageCache::remove`] or [`PageCache::clear`], and
    /// pages never kept (larger than the byte limit, or refused by the policy), are not.
    pub evictions: u64,
}

impl CacheStats {
    /// `hits / requests`, 0 when nothing was requested.
    pub fn hit_rate(&self) -> f64 {
        if self.requests == 0 { 0.0 } else { self.hits as f64 / self.requests as f64 }
    }
}

/// An eviction policy: it tracks the resident keys and chooses which one goes.
///
/// The cache calls the hooks in step with its contents: every key the policy tracks is
/// resident and every resident key is tracked. `now` is the cache's logical clock: the number
/// of requests so far, so each request has a distinct time.
pub trait CachePolicy: fmt::Debug {
    /// Whether a freshly loaded page may be kept at all (the `none` policy keeps nothing).
    fn admits(&self, _key: PageKey, _priority: f64) -> bool {
        true
    }
    /// `key` became resident, loaded at time `now` with `priority`.
    fn insert(&mut self, key: PageKey, priority: f64, now: u64);
    /// Resident `key` was requested again at `now`; `priority` is its current priority.
    fn access(&mut self, key: PageKey, priority: f64, now: u64);
    /// The caller changed resident `key`'s priority; `last` is its last access, unchanged.
    fn set_priority(&mut self, key: PageKey, priority: f64, last: u64) {
        self.remove(key);
        self.insert(key, priority, last);
    }
    /// `key` left the cache other than as a victim (the caller removed it).
    fn remove(&mut self, key: PageKey);
    /// Chooses the key to evict, forgets it and returns it; `None` when tracking nothing.
    fn victim(&mut self) -> Option<PageKey>;
    /// Forgets every key.
    fn clear(&mut self);
}

/// The policies by name, for command lines and configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PolicyKind {
    /// Keep nothing: every request reads its page.
    None,
    /// Evict the least recently used page.
    Lru,
    /// Evict the page of smallest priority (DoV), the least recent among equals.
    Dov,
    /// Evict the page of smallest `priority + kappa · T`, T = time of its last access.
    DovTime {
        /// Weight of recency against priority (thesis: 0.001 per request).
        kappa: f64,
    },
    /// REVIEW's distance-priority-LRU: evict the page of smallest `priority + γ·pl`, the
    /// caller's `α·pp + β·pd` plus the normalised recency (γ = 1/3; [`Dplru`]).
    Dplru,
}

crate::named!(PolicyKind, "cache policy");

impl PolicyKind {
    /// Every kind, `dov-time` with the default κ ([`FromStr`] also takes `dov-time:KAPPA`).
    pub const ALL: [PolicyKind; 5] =
        [PolicyKind::None, PolicyKind::Lru, PolicyKind::Dov, PolicyKind::DOV_TIME, PolicyKind::Dplru];

    /// The name used on the command line (without κ).
    pub fn name(self) -> &'static str {
        match self {
            PolicyKind::None => "none",
            PolicyKind::Lru => "lru",
            PolicyKind::Dov => "dov",
            PolicyKind::DovTime { .. } => "dov-time",
            PolicyKind::Dplru => "dplru",
        }
    }

    /// DoV-Time with the thesis's κ = 0.001.
    pub const DOV_TIME: PolicyKind = PolicyKind::DovTime { kappa: DEFAULT_KAPPA };

    /// A fresh policy of this kind.
    pub fn build(self) -> Box<dyn CachePolicy + Send> {
        match self {
            PolicyKind::None => Box::new(NoCache),
            PolicyKind::Lru => Box::<Lru>::default(),
            PolicyKind::Dov => Box::<Dov>::default(),
            PolicyKind::DovTime { kappa } => Box::new(DovTime::new(kappa)),
            PolicyKind::Dplru => Box::<Dplru>::default(),
        }
    }
}

impl fmt::Display for PolicyKind {
    /// The name; `dov-time:KAPPA` when κ is not the default, so that `FromStr` reads it back.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            PolicyKind::DovTime { kappa } if kappa != DEFAULT_KAPPA => write!(f, "dov-time:{kappa}"),
            kind => crate::names::write_name(kind, f),
        }
    }
}

impl FromStr for PolicyKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.strip_prefix("dov-time:") {
            Some(k) => match k.parse::<f64>() {
                Ok(kappa) if kappa.is_finite() && kappa >= 0.0 => Ok(PolicyKind::DovTime { kappa }),
                _ => Err(format!("cache policy {s:?}: kappa must be a finite number >= 0")),
            },
            None => crate::names::parse_name(s),
        }
    }
}

/// A resident page.
struct Resident {
    data: Arc<[u8]>,
    /// Time of the last request for it (needed again when its priority changes).
    last: u64,
}

/// Page bytes kept in memory under [`CacheLimits`], evicted by a [`CachePolicy`].
///
/// Every operation costs O(1) expected for the hash map plus the policy's cost (O(log n) for
/// the policies of this module) per page inserted, accessed or evicted.
pub struct PageCache {
    limits: CacheLimits,
    policy: Box<dyn CachePolicy + Send>,
    pages: HashMap<PageKey, Resident>,
    bytes: u64,
    now: u64,
    stats: CacheStats,
}

impl fmt::Debug for PageCache {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("PageCache")
            .field("limits", &self.limits)
            .field("policy", &self.policy)
            .field("pages", &self.pages.len())
            .field("bytes", &self.bytes)
            .field("now", &self.now)
            .field("stats", &self.stats)
            .finish()
    }
}

impl PageCache {
    /// An empty cache with the given limits and policy.
    pub fn new(limits: CacheLimits, policy: Box<dyn CachePolicy + Send>) -> Self {
        Self { limits, policy, pages: HashMap::new(), bytes: 0, now: 0, stats: CacheStats::default() }
    }

    /// An empty cache with a fresh policy of `kind`.
    pub fn with_kind(limits: CacheLimits, kind: PolicyKind) -> Self {
        Self::new(limits, kind.build())
    }

    /// The page at `key`: from the cache (a hit), or from `load` (a miss, one page read), then
    /// kept if the limits and the policy allow, evicting until both limits hold. `priority` is
    /// the page's current priority (for the DoV policies, the DoV of its node); a hit updates
    /// the policy's record of it. A failed load is counted as a miss and changes nothing else.
    pub fn get_or_load<E>(
        &mut self,
        key: PageKey,
        priority: f64,
        load: impl FnOnce() -> Result<Arc<[u8]>, E>,
    ) -> Result<Arc<[u8]>, E> {
        self.now += 1;
        self.stats.requests += 1;
        if let Some(r) = self.pages.get_mut(&key) {
            r.last = self.now;
            self.stats.hits += 1;
            self.policy.access(key, priority, self.now);
            return Ok(Arc::clone(&r.data));
        }
        self.stats.misses += 1;
        let data = load()?;
        self.keep(key, priority, Arc::clone(&data));
        Ok(data)
    }

    fn keep(&mut self, key: PageKey, priority: f64, data: Arc<[u8]>) {
        let len = data.len() as u64;
        // A page that cannot fit even alone would first flush everything else out.
        if !self.limits.fits_alone(len) || !self.policy.admits(key, priority) {
            return;
        }
        // The newcomer is ranked with the residents: a DoV cache never drops a page for one
        // of lower DoV.
        self.policy.insert(key, priority, self.now);
        self.pages.insert(key, Resident { data, last: self.now });
        self.bytes += len;
        while self.over_limits() {
            let Some(victim) = self.policy.victim() else {
                debug_assert!(false, "policy tracks fewer pages than the cache holds");
                break;
            };
            if let Some(r) = self.pages.remove(&victim) {
                self.bytes -= r.data.len() as u64;
                self.stats.evictions += 1;
            }
        }
    }

    fn over_limits(&self) -> bool {
        self.limits.pages.is_some_and(|p| self.pages.len() > p) || self.limits.bytes.is_some_and(|b| self.bytes > b)
    }

    /// Changes a resident page's priority (e.g. its node's DoV in the viewer's new cell)
    /// without counting a request or advancing the clock. Returns whether `key` is resident.
    pub fn set_priority(&mut self, key: PageKey, priority: f64) -> bool {
        match self.pages.get(&key) {
            Some(r) => {
                self.policy.set_priority(key, priority, r.last);
                true
            }
            None => false,
        }
    }

    /// Whether `key` is resident (not a request: no count, no clock tick).
    pub fn contains(&self, key: PageKey) -> bool {
        self.pages.contains_key(&key)
    }

    /// Drops `key` if resident (not counted as an eviction). Returns whether it was.
    pub fn remove(&mut self, key: PageKey) -> bool {
        match self.pages.remove(&key) {
            Some(r) => {
                self.bytes -= r.data.len() as u64;
                self.policy.remove(key);
                true
            }
            None => false,
        }
    }

    /// Drops every page. Statistics and the clock are kept.
    pub fn clear(&mut self) {
        self.pages.clear();
        self.policy.clear();
        self.bytes = 0;
    }

    /// Resident pages.
    pub fn len(&self) -> usize {
        self.pages.len()
    }

    /// Whether no page is resident.
    pub fn is_empty(&self) -> bool {
        self.pages.is_empty()
    }

    /// Bytes of resident page data.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// The limits the cache keeps within.
    pub fn limits(&self) -> CacheLimits {
        self.limits
    }

    /// The logical clock: requests made since the cache was created (not reset by
    /// [`reset_stats`](Self::reset_stats)); the last request happened at this time.
    pub fn now(&self) -> u64 {
        self.now
    }

    /// Counts since creation or the last [`reset_stats`](Self::reset_stats).
    pub fn stats(&self) -> CacheStats {
        self.stats
    }

    /// Zeroes the counts; contents and clock are kept (e.g. to measure a warm cache).
    pub fn reset_stats(&mut self) {
        self.stats = CacheStats::default();
    }
}
