//! The page cache on hand-made access sequences: sequential flooding, who each policy evicts,
//! DoV-Time's ageing, the page and byte limits, and the counts; then random sequences checked
//! against a simple model.

use std::sync::Arc;

use hdov_storage::cache::{DEFAULT_GAMMA, DEFAULT_KAPPA, DovTime, Dplru};
use hdov_storage::{CacheLimits, CachePolicy, CacheStats, Error, Named, PageCache, PageKey, PolicyKind};
use proptest::prelude::*;

const ALL: [PolicyKind; 5] = PolicyKind::ALL;

fn key(page: u64) -> PageKey {
    PageKey { file: 0, page }
}

/// The bytes of a page: `len` bytes that name the key, so a wrong page is noticed.
fn bytes_of(k: PageKey, len: usize) -> Arc<[u8]> {
    (0..len).map(|i| (k.page as usize * 31 + k.file as usize * 7 + i) as u8).collect()
}

/// Requests page `p` of `len` bytes; checks the bytes returned; true on a hit.
fn request_len(cache: &mut PageCache, p: u64, priority: f64, len: usize) -> bool {
    let mut loaded = false;
    let got = cache
        .get_or_load(key(p), priority, || {
            loaded = true;
            Ok::<_, Error>(bytes_of(key(p), len))
        })
        .unwrap();
    assert_eq!(got, bytes_of(key(p), len), "page {p}");
    !loaded
}

fn request(cache: &mut PageCache, p: u64, priority: f64) -> bool {
    request_len(cache, p, priority, 16)
}

fn resident(cache: &PageCache, pages: impl IntoIterator<Item = u64>) -> Vec<u64> {
    pages.into_iter().filter(|&p| cache.contains(key(p))).collect()
}

/// A cyclic scan of `n + 1` pages, page `i` with DoV `1 − i/16`, through an `n`-page cache;
/// returns the hits after the first round.
fn flooding_hits(kind: PolicyKind, n: u64, rounds: u64) -> (u64, CacheStats) {
    let mut cache = PageCache::with_kind(CacheLimits::max_pages(n as usize), kind);
    let mut warm_hits = 0;
    for round in 0..rounds {
        for p in 0..=n {
            let hit = request(&mut cache, p, 1.0 - p as f64 / 16.0);
            if round > 0 && hit {
                warm_hits += 1;
            }
        }
    }
    (warm_hits, cache.stats())
}

#[test]
fn sequential_flooding_defeats_lru_but_not_dov() {
    let (n, rounds) = (8, 20);
    let (lru, stats) = flooding_hits(PolicyKind::Lru, n, rounds);
    assert_eq!(lru, 0, "LRU: each page is evicted just before it is needed again");
    assert_eq!(stats.hits, 0);
    assert_eq!(stats.misses, rounds * (n + 1));
    // DoV ranks the newcomer with the residents: the lowest-DoV page is never kept, the n
    // others hit in every later round.
    let (dov, stats) = flooding_hits(PolicyKind::Dov, n, rounds);
    assert_eq!(dov, (rounds - 1) * n);
    assert_eq!(stats.evictions, rounds, "only page n, each time it is loaded");
    // κ·T moves by 0.001 a request, far less than the DoV steps of 1/16: same as DoV.
    let (dov_time, _) = flooding_hits(PolicyKind::DOV_TIME, n, rounds);
    assert_eq!(dov_time, dov);
}

#[test]
fn lru_evicts_the_least_recently_used_page() {
    let mut cache = PageCache::with_kind(CacheLimits::max_pages(3), PolicyKind::Lru);
    for p in [1, 2, 3] {
        assert!(!request(&mut cache, p, 0.0));
    }
    assert!(request(&mut cache, 1, 0.0)); // order of use now 2, 3, 1
    assert!(cache.set_priority(key(2), 100.0)); // LRU ignores priorities
    assert!(!request(&mut cache, 4, 0.0));
    assert_eq!(resident(&cache, 1..=4), [1, 3, 4]);
    assert!(!request(&mut cache, 5, 9.0));
    assert_eq!(resident(&cache, 1..=5), [1, 4, 5]);
}

#[test]
fn dov_evicts_exactly_the_smallest_priority_page() {
    let mut cache = PageCache::with_kind(CacheLimits::max_pages(4), PolicyKind::Dov);
    for (p, dov) in [(1, 0.5), (2, 0.1), (3, 0.9), (4, 0.3)] {
        request(&mut cache, p, dov);
    }
    request(&mut cache, 5, 0.7);
    assert_eq!(resident(&cache, 1..=5), [1, 3, 4, 5], "0.1 goes");
    // A newcomer of lower DoV than every resident is itself the victim.
    request(&mut cache, 6, 0.2);
    assert_eq!(resident(&cache, 1..=6), [1, 3, 4, 5]);
    assert_eq!(cache.stats().evictions, 2);
    // A hit brings the page's current DoV: page 3 drops from 0.9 to 0.05 and goes next.
    assert!(request(&mut cache, 3, 0.05));
    request(&mut cache, 7, 0.6);
    assert_eq!(resident(&cache, 1..=7), [1, 4, 5, 7]);
    // Equal DoVs: the least recently used goes.
    let mut cache = PageCache::with_kind(CacheLimits::max_pages(2), PolicyKind::Dov);
    request(&mut cache, 1, 0.5);
    request(&mut cache, 2, 0.5);
    assert!(request(&mut cache, 1, 0.5));
    request(&mut cache, 3, 0.5);
    assert_eq!(resident(&cache, 1..=3), [1, 3]);
}

/// Page A (DoV `a`) at time 1, then pages of DoV 0 at times 2, 3, ... through a 2-page cache;
/// returns the time of the request at which A was evicted (None if never within `until`).
fn dov_time_eviction_of_a(kind: PolicyKind, a: f64, until: u64) -> Option<u64> {
    let mut cache = PageCache::with_kind(CacheLimits::max_pages(2), kind);
    request(&mut cache, 0, a);
    assert_eq!(cache.now(), 1);
    for p in 1..until {
        request(&mut cache, p, 0.0);
        if !cache.contains(key(0)) {
            return Some(cache.now());
        }
    }
    None
}

#[test]
fn dov_time_ages_an_old_high_dov_page() {
    // f(A) = 0.5015 + κ·1 = 0.5025. When the request at time t arrives, the residents are A and
    // the DoV-0 page of time t−1 (f = κ·(t−1)), plus the newcomer (f = κ·t). The smallest f
    // goes: the older DoV-0 page while κ·(t−1) < 0.5025, i.e. t − 1 ≤ 502; A at t = 504.
    let a = 0.5015;
    let k = DEFAULT_KAPPA;
    let policy = DovTime::default();
    assert_eq!(policy.kappa(), 0.001);
    assert_eq!(policy.f(a, 1), a + k);
    let t = 504;
    assert!(k * (t - 1) as f64 > a + k && k * (t - 2) as f64 <= a + k, "the arithmetic above");
    assert_eq!(dov_time_eviction_of_a(PolicyKind::DOV_TIME, a, 2000), Some(t));
    // Ten times the κ, about ten times sooner: 0.01·(t−1) > 0.5015 + 0.01 first at t = 53.
    assert_eq!(dov_time_eviction_of_a(PolicyKind::DovTime { kappa: 0.01 }, a, 2000), Some(53));
    // κ = 0 is plain DoV; DoV never lets A go.
    assert_eq!(dov_time_eviction_of_a(PolicyKind::DovTime { kappa: 0.0 }, a, 2000), None);
    assert_eq!(dov_time_eviction_of_a(PolicyKind::Dov, a, 2000), None);
}

#[test]
fn the_page_limit_holds_after_every_request() {
    for kind in ALL {
        let mut cache = PageCache::with_kind(CacheLimits::max_pages(5), kind);
        for i in 0..300u64 {
            request(&mut cache, (i * 7 + i / 3) % 23, ((i * 13) % 10) as f64 / 10.0);
            assert!(cache.len() <= 5, "{kind}");
            assert_eq!(resident(&cache, 0..23).len(), cache.len(), "{kind}");
        }
        if kind != PolicyKind::None {
            assert_eq!(cache.len(), 5, "{kind}: full after many distinct pages");
        }
    }
}

#[test]
fn the_byte_limit_holds_after_every_request() {
    let len_of = |p: u64| 10 + (p as usize * 37) % 90; // 10..100 bytes
    for kind in ALL {
        let mut cache = PageCache::with_kind(CacheLimits::max_bytes(250), kind);
        for i in 0..400u64 {
            let p = (i * 11 + i / 5) % 29;
            request_len(&mut cache, p, (p % 7) as f64 / 7.0, len_of(p));
            let held: u64 = resident(&cache, 0..29).into_iter().map(|p| len_of(p) as u64).sum();
            assert_eq!(cache.bytes(), held, "{kind}");
            assert!(cache.bytes() <= 250, "{kind}");
        }
        if kind != PolicyKind::None {
            assert!(cache.bytes() > 250 - 100, "{kind}: no page is evicted without need");
        }
    }
    // Both limits at once: whichever binds first.
    let mut cache = PageCache::with_kind(CacheLimits { pages: Some(3), bytes: Some(100) }, PolicyKind::Lru);
    for p in 0..4 {
        request_len(&mut cache, p, 0.0, 20);
    }
    assert_eq!((cache.len(), cache.bytes()), (3, 60));
    request_len(&mut cache, 9, 0.0, 70);
    assert_eq!(resident(&cache, 0..10), [3, 9], "bytes bind: 20 + 70 ≤ 100");
}

#[test]
fn an_oversize_page_is_returned_but_not_kept() {
    for kind in [PolicyKind::Lru, PolicyKind::Dov, PolicyKind::DOV_TIME] {
        let mut cache = PageCache::with_kind(CacheLimits::max_bytes(100), kind);
        request_len(&mut cache, 1, 0.0, 60);
        request_len(&mut cache, 2, 0.0, 40);
        assert!(!request_len(&mut cache, 3, 1.0, 101), "returned, with its bytes");
        assert_eq!(resident(&cache, 1..=3), [1, 2], "{kind}: nothing evicted for it");
        assert_eq!(cache.bytes(), 100);
        assert!(!request_len(&mut cache, 3, 1.0, 101), "{kind}: read again");
        assert_eq!(cache.stats().evictions, 0);
        // Exactly the limit fits (and pushes the others out).
        request_len(&mut cache, 4, 1.0, 100);
        assert_eq!(resident(&cache, 1..=4), [4], "{kind}");
    }
    // A page limit of 0 keeps nothing either.
    let mut cache = PageCache::with_kind(CacheLimits::max_pages(0), PolicyKind::Lru);
    assert!(!request(&mut cache, 1, 0.0));
    assert!(!request(&mut cache, 1, 0.0));
    assert!(cache.is_empty());
}

#[test]
fn stats_add_up() {
    for kind in ALL {
        let mut cache = PageCache::with_kind(CacheLimits::max_pages(4), kind);
        let mut loads = 0;
        for i in 0..200u64 {
            let p = (i * i + 3 * i) % 9;
            cache
                .get_or_load(key(p), (p % 3) as f64, || {
                    loads += 1;
                    Ok::<_, Error>(bytes_of(key(p), 8))
                })
                .unwrap();
        }
        let s = cache.stats();
        assert_eq!(s.requests, 200, "{kind}");
        assert_eq!(s.requests, s.hits + s.misses, "{kind}");
        assert_eq!(s.misses, loads, "{kind}");
        assert_eq!(cache.now(), 200);
        if kind != PolicyKind::None {
            assert!(s.hits > 0, "{kind}");
            assert_eq!(s.misses - s.evictions, cache.len() as u64, "{kind}: every kept page stays or is evicted");
        }
        // A failed load counts as a request and a miss, keeps nothing, returns the error.
        let absent = key(100);
        let err = cache.get_or_load(absent, 1.0, || Err::<Arc<[u8]>, _>("disk on fire")).unwrap_err();
        assert_eq!(err, "disk on fire");
        assert!(!cache.contains(absent));
        assert_eq!(cache.stats().misses, s.misses + 1);
        assert_eq!(cache.stats().requests, s.requests + 1);
        // Resetting the counts keeps the contents and the clock.
        let len = cache.len();
        cache.reset_stats();
        assert_eq!(cache.stats(), CacheStats::default());
        assert_eq!((cache.len(), cache.now()), (len, 201));
        assert_eq!(cache.stats().hit_rate(), 0.0);
    }
}

#[test]
fn none_never_hits() {
    let mut cache = PageCache::with_kind(CacheLimits::UNLIMITED, PolicyKind::None);
    for i in 0..50 {
        assert!(!request(&mut cache, i % 3, 1.0));
        assert!(cache.is_empty());
        assert_eq!(cache.bytes(), 0);
    }
    assert!(!cache.set_priority(key(0), 1.0));
    assert_eq!(cache.stats(), CacheStats { requests: 50, hits: 0, misses: 50, evictions: 0 });
}

#[test]
fn set_priority_changes_who_is_evicted() {
    for kind in [PolicyKind::Dov, PolicyKind::DOV_TIME] {
        let mut cache = PageCache::with_kind(CacheLimits::max_pages(3), kind);
        request(&mut cache, 1, 0.9);
        request(&mut cache, 2, 0.5);
        request(&mut cache, 3, 0.1);
        // The viewer changed cell: page 3 is now the most visible, page 1 hidden.
        assert!(cache.set_priority(key(3), 1.0));
        assert!(cache.set_priority(key(1), 0.0));
        assert!(!cache.set_priority(key(4), 1.0), "not resident");
        let before = cache.stats();
        assert_eq!(cache.now(), 3, "{kind}: not a request");
        request(&mut cache, 4, 0.6);
        assert_eq!(resident(&cache, 1..=4), [2, 3, 4], "{kind}");
        request(&mut cache, 5, 0.7);
        assert_eq!(resident(&cache, 1..=5), [3, 4, 5], "{kind}");
        assert_eq!(cache.stats().requests, before.requests + 2);
    }
}

#[test]
fn remove_and_clear_drop_pages_without_counting_evictions() {
    for kind in [PolicyKind::Lru, PolicyKind::Dov, PolicyKind::DOV_TIME] {
        let mut cache = PageCache::with_kind(CacheLimits::max_pages(3), kind);
        for p in 1..=3 {
            request_len(&mut cache, p, p as f64, 10);
        }
        assert!(cache.remove(key(2)));
        assert!(!cache.remove(key(2)));
        assert_eq!((cache.len(), cache.bytes()), (2, 20));
        // The policy forgot page 2 too: the next two pages fill its slot, then evict.
        request_len(&mut cache, 4, 5.0, 10);
        assert_eq!(cache.stats().evictions, 0, "{kind}");
        request_len(&mut cache, 5, 5.0, 10);
        assert_eq!(cache.stats().evictions, 1, "{kind}");
        assert_eq!(resident(&cache, 1..=5), [3, 4, 5], "{kind}");
        cache.clear();
        assert!(cache.is_empty());
        assert_eq!(cache.bytes(), 0);
        assert_eq!(cache.stats().evictions, 1);
        assert!(!request(&mut cache, 3, 1.0), "{kind}: gone");
        assert!(request(&mut cache, 3, 1.0), "{kind}: usable after clear");
    }
}

#[test]
fn file_ids_keep_pages_of_different_files_apart() {
    let mut cache = PageCache::with_kind(CacheLimits::UNLIMITED, PolicyKind::Lru);
    let (tree, vpages) = (PageKey { file: 0, page: 5 }, PageKey { file: 1, page: 5 });
    cache.get_or_load(tree, 0.0, || Ok::<_, Error>(Arc::from(&b"tree"[..]))).unwrap();
    let got = cache.get_or_load(vpages, 0.0, || Ok::<_, Error>(Arc::from(&b"vpage"[..]))).unwrap();
    assert_eq!(&got[..], b"vpage");
    assert_eq!((cache.len(), cache.bytes(), cache.stats().misses), (2, 9, 2));
}

/// DPLRU on hand-made sequences through a two-page cache, γ = 1/3. Request i happens at time
/// i; when the third page arrives the residents were last accessed at 1, 2, 3, so the largest
/// age is 2 and `pl` = 1 − age/2 is 0, ½, 1 for them.
#[test]
fn dplru_evicts_the_smallest_priority_plus_normalised_recency() {
    let third = 1.0 / 3.0;
    // A (0.40, t1): f = 0.40 + ⅓·0 = 0.400;  B (0.30, t2): 0.30 + ⅓·½ = 0.467;
    // C (0.35, t3): 0.35 + ⅓·1 = 0.683. A goes: LRU's victim, where DoV would drop B.
    let mut cache = PageCache::with_kind(CacheLimits::max_pages(2), PolicyKind::Dplru);
    for (p, prio) in [(1, 0.40), (2, 0.30), (3, 0.35)] {
        request(&mut cache, p, prio);
    }
    assert_eq!(resident(&cache, 1..=3), [2, 3]);
    let f = |prio: f64, last: u64| Dplru::default().f(prio, last, 1, 3);
    assert!((f(0.40, 1) - 0.40).abs() < 1e-12 && (f(0.30, 2) - (0.30 + third / 2.0)).abs() < 1e-12);
    // A (0.90, t1): 0.900;  B (0.30, t2): 0.467;  C (0.35, t3): 0.683. B goes: DoV's victim,
    // where LRU would drop A.
    let mut cache = PageCache::with_kind(CacheLimits::max_pages(2), PolicyKind::Dplru);
    for (p, prio) in [(1, 0.90), (2, 0.30), (3, 0.35)] {
        request(&mut cache, p, prio);
    }
    assert_eq!(resident(&cache, 1..=3), [1, 3]);
    // Then D (0.10, t4): A (0.90, t1) age 3 → 0.900; C (0.35, t3) age 1 → 0.35 + ⅓·⅔ = 0.572;
    // D (0.10, t4) → 0.10 + ⅓ = 0.433: the newcomer itself is the smallest and is not kept.
    assert!(!request(&mut cache, 4, 0.10));
    assert_eq!(resident(&cache, 1..=4), [1, 3]);
    assert_eq!(cache.stats().evictions, 2);
    // A hit refreshes C (t5); the caller lowers A's priority (the viewer walked away from its
    // node): A (0.05, t1) → 0.05, C (0.35, t5) → 0.683, E (0.20, t6) → 0.533. A goes.
    assert!(request(&mut cache, 3, 0.35));
    assert!(cache.set_priority(key(1), 0.05));
    request(&mut cache, 5, 0.20);
    assert_eq!(resident(&cache, 1..=5), [3, 5]);
    // Equal f: the least recent goes. Page 1 (⅔, t1) → ⅔ + ⅓·0; page 2 (⅓, t2) → ⅓ + ⅓·1.
    let mut one = PageCache::with_kind(CacheLimits::max_pages(1), PolicyKind::Dplru);
    request(&mut one, 1, 2.0 * third);
    request(&mut one, 2, third);
    assert_eq!(resident(&one, 1..=2), [2], "page 1 ties on f and is older");
    assert_eq!(Dplru::default().gamma(), DEFAULT_GAMMA);
}

#[test]
fn the_cache_can_move_between_threads() {
    fn send<T: Send>(_: &T) {}
    send(&PageCache::with_kind(CacheLimits::UNLIMITED, PolicyKind::DOV_TIME));
}

#[test]
fn policy_names_round_trip() {
    for kind in ALL.into_iter().chain([PolicyKind::DovTime { kappa: 0.25 }]) {
        assert_eq!(kind.to_string().parse::<PolicyKind>(), Ok(kind));
    }
    let names: Vec<String> = ALL.iter().map(|k| k.to_string()).collect();
    let named: Vec<&str> = PolicyKind::all().iter().map(|k| Named::name(*k)).collect();
    assert_eq!(names, named);
    assert_eq!("dov-time".parse(), Ok(PolicyKind::DovTime { kappa: 0.001 }));
    assert_eq!("dov-time:0.01".parse(), Ok(PolicyKind::DovTime { kappa: 0.01 }));
    assert_eq!("dov-time:0.01".parse::<PolicyKind>().unwrap().name(), "dov-time");
    let err = "mru".parse::<PolicyKind>().unwrap_err();
    assert_eq!(err, "unknown cache policy 'mru' (expected none, lru, dov, dov-time or dplru)");
    assert!("dov-time:-1".parse::<PolicyKind>().unwrap_err().contains("kappa"));
    assert!("dov-time:nan".parse::<PolicyKind>().is_err());
}

#[test]
fn a_custom_policy_plugs_in() {
    /// First in, first out: hits do not matter, only the order of insertion.
    #[derive(Debug, Default)]
    struct Fifo(Vec<PageKey>);
    impl CachePolicy for Fifo {
        fn insert(&mut self, key: PageKey, _: f64, _: u64) {
            self.0.push(key);
        }
        fn access(&mut self, _: PageKey, _: f64, _: u64) {}
        fn remove(&mut self, key: PageKey) {
            self.0.retain(|k| *k != key);
        }
        fn victim(&mut self) -> Option<PageKey> {
            (!self.0.is_empty()).then(|| self.0.remove(0))
        }
        fn clear(&mut self) {
            self.0.clear();
        }
    }
    let mut cache = PageCache::new(CacheLimits::max_pages(2), Box::<Fifo>::default());
    for p in 1..=3 {
        request(&mut cache, p, 0.0);
    }
    assert_eq!(resident(&cache, 1..=3), [2, 3]);
    assert!(request(&mut cache, 2, 0.0));
    // The trait's default set_priority removes and re-inserts: page 2 becomes the newest.
    cache.set_priority(key(2), 0.0);
    request(&mut cache, 4, 0.0);
    assert_eq!(resident(&cache, 1..=4), [2, 4]);
}

// ---- random sequences against a model ----

#[derive(Clone, Debug)]
enum Op {
    Get { file: u32, page: u64, priority: f64 },
    FailedGet { page: u64 },
    SetPriority { page: u64, priority: f64 },
    Remove { page: u64 },
    Clear,
    ResetStats,
}

fn op() -> impl Strategy<Value = Op> {
    // Few distinct priorities, so that ties (broken by recency) are common.
    let priority = (0u8..5).prop_map(|p| f64::from(p) / 4.0);
    prop_oneof![
        12 => (0u32..2, 0u64..10, priority.clone()).prop_map(|(file, page, priority)| Op::Get { file, page, priority }),
        1 => (0u64..10).prop_map(|page| Op::FailedGet { page }),
        2 => (0u64..10, priority).prop_map(|(page, priority)| Op::SetPriority { page, priority }),
        1 => (0u64..10).prop_map(|page| Op::Remove { page }),
        1 => Just(Op::Clear),
        1 => Just(Op::ResetStats),
    ]
}

/// A page's length depends on its key only, so the model knows what the cache holds.
fn len_of(k: PageKey) -> usize {
    5 + ((k.page * 13 + u64::from(k.file) * 29) % 40) as usize
}

/// The cache the slow obvious way: a list of (key, priority, last access), the victim found by
/// scanning for the smallest (score, last).
#[derive(Default)]
struct Model {
    resident: Vec<(PageKey, f64, u64)>,
    now: u64,
    stats: CacheStats,
}

impl Model {
    /// `oldest` and `newest`: the least and most recent last access among the residents.
    fn score(kind: PolicyKind, priority: f64, last: u64, oldest: u64, newest: u64) -> f64 {
        match kind {
            PolicyKind::None | PolicyKind::Lru => 0.0,
            PolicyKind::Dov => priority,
            PolicyKind::DovTime { kappa } => priority + kappa * last as f64,
            PolicyKind::Dplru => {
                let span = newest - oldest;
                let pl = if span == 0 { 1.0 } else { 1.0 - (newest - last) as f64 / span as f64 };
                priority + DEFAULT_GAMMA * pl
            }
        }
    }

    fn bytes(&self) -> u64 {
        self.resident.iter().map(|(k, ..)| len_of(*k) as u64).sum()
    }

    /// A request; returns whether it hit.
    fn get(&mut self, kind: PolicyKind, limits: CacheLimits, k: PageKey, priority: f64, fails: bool) -> bool {
        self.now += 1;
        self.stats.requests += 1;
        if let Some(e) = self.resident.iter_mut().find(|e| e.0 == k) {
            *e = (k, priority, self.now);
            self.stats.hits += 1;
            return true;
        }
        self.stats.misses += 1;
        let len = len_of(k) as u64;
        if fails || kind == PolicyKind::None || limits.pages == Some(0) || limits.bytes.is_some_and(|b| len > b) {
            return false;
        }
        self.resident.push((k, priority, self.now));
        while limits.pages.is_some_and(|p| self.resident.len() > p) || limits.bytes.is_some_and(|b| self.bytes() > b) {
            let oldest = self.resident.iter().map(|e| e.2).min().unwrap();
            let newest = self.resident.iter().map(|e| e.2).max().unwrap();
            let worst = (0..self.resident.len())
                .min_by(|&i, &j| {
                    let (ki, pi, li) = self.resident[i];
                    let (kj, pj, lj) = self.resident[j];
                    let score = |p, l| Self::score(kind, p, l, oldest, newest);
                    let (si, sj) = (score(pi, li), score(pj, lj));
                    si.total_cmp(&sj).then(li.cmp(&lj)).then(ki.cmp(&kj))
                })
                .unwrap();
            self.resident.remove(worst);
            self.stats.evictions += 1;
        }
        false
    }
}

fn run_against_model(kind: PolicyKind, limits: CacheLimits, ops: &[Op]) -> Result<(), TestCaseError> {
    let mut cache = PageCache::with_kind(limits, kind);
    let mut model = Model::default();
    let mut loads = 0u64;
    for op in ops {
        match *op {
            Op::Get { file, page, priority } => {
                let k = PageKey { file, page };
                let mut loaded = false;
                let got = cache
                    .get_or_load(k, priority, || {
                        loaded = true;
                        Ok::<_, Error>(bytes_of(k, len_of(k)))
                    })
                    .unwrap();
                prop_assert_eq!(got, bytes_of(k, len_of(k)));
                loads += u64::from(loaded);
                prop_assert_eq!(!loaded, model.get(kind, limits, k, priority, false), "hit or miss of {:?}", k);
            }
            Op::FailedGet { page } => {
                let k = key(page);
                let mut loaded = false;
                let r = cache.get_or_load(k, 0.5, || {
                    loaded = true;
                    Err("no")
                });
                loads += u64::from(loaded);
                prop_assert_eq!(r.is_ok(), model.get(kind, limits, k, 0.5, true));
            }
            Op::SetPriority { page, priority } => {
                let k = key(page);
                let e = model.resident.iter_mut().find(|e| e.0 == k);
                prop_assert_eq!(cache.set_priority(k, priority), e.is_some());
                if let Some(e) = e {
                    e.1 = priority;
                }
            }
            Op::Remove { page } => {
                let at = model.resident.iter().position(|e| e.0 == key(page));
                prop_assert_eq!(cache.remove(key(page)), at.is_some());
                if let Some(at) = at {
                    model.resident.remove(at);
                }
            }
            Op::Clear => {
                cache.clear();
                model.resident.clear();
            }
            Op::ResetStats => {
                cache.reset_stats();
                model.stats = CacheStats::default();
                loads = 0;
            }
        }
        let s = cache.stats();
        prop_assert_eq!(s, model.stats);
        prop_assert_eq!(s.requests, s.hits + s.misses);
        prop_assert_eq!(s.misses, loads);
        prop_assert_eq!(cache.now(), model.now);
        prop_assert!(limits.pages.is_none_or(|p| cache.len() <= p));
        prop_assert!(limits.bytes.is_none_or(|b| cache.bytes() <= b));
        prop_assert_eq!(cache.len(), model.resident.len());
        prop_assert_eq!(cache.bytes(), model.bytes());
        for (k, ..) in &model.resident {
            prop_assert!(cache.contains(*k), "{:?} should be resident", k);
        }
        if kind == PolicyKind::None {
            prop_assert_eq!((s.hits, cache.len()), (0, 0));
        }
    }
    Ok(())
}

proptest! {
    #[test]
    fn random_sequences_match_the_model(
        pages in prop::option::of(0usize..6),
        bytes in prop::option::of(0u64..160),
        kappa in prop_oneof![Just(DEFAULT_KAPPA), Just(0.1), Just(0.0)],
        ops in prop::collection::vec(op(), 0..120),
    ) {
        let limits = CacheLimits { pages, bytes };
        for kind in [PolicyKind::None, PolicyKind::Lru, PolicyKind::Dov, PolicyKind::DovTime { kappa }, PolicyKind::Dplru] {
            run_against_model(kind, limits, &ops)?;
        }
    }
}

proptest! {
    /// LRU through the `lru` crate's list evicts exactly what the ranked structure does when every
    /// page has one priority (the DoV policy then orders by last access alone): the same hits,
    /// the same pages resident after every request, with page and byte limits.
    #[test]
    fn lru_crate_list_equals_the_ranked_lru(
        requests in prop::collection::vec(0u64..40, 1..400),
        pages in 1usize..12,
        bytes in prop::option::of(64u64..600),
    ) {
        let limits = CacheLimits { pages: Some(pages), bytes };
        let mut lru = PageCache::with_kind(limits, PolicyKind::Lru);
        let mut ranked = PageCache::with_kind(limits, PolicyKind::Dov);
        for p in requests {
            // Pages of many sizes, so that the byte limit evicts too; one page, one size.
            let len = 1 + (p as usize * 13) % 64;
            prop_assert_eq!(request_len(&mut lru, p, 0.5, len), request_len(&mut ranked, p, 0.5, len));
            prop_assert_eq!(resident(&lru, 0..40), resident(&ranked, 0..40));
        }
        prop_assert_eq!(lru.stats(), ranked.stats());
    }
}
