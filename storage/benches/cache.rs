//! The LRU policy's recency list: the `lru` crate's (`PolicyKind::Lru`) against the ranked
//! structure the priority policies share, run as an LRU (`PolicyKind::Dov` with one priority for
//! every page orders by last access alone, so both evict the same pages: tests/cache.rs).
//!
//! `cargo bench -p hdov-storage --bench cache` (short: 10 samples, 1 s each). Each iteration is
//! 20,000 requests through a page cache of 256 or 4,096 pages, over 16,384 pages requested
//! with a skew (a quarter of the pages take three quarters of the requests), as a walk revisits
//! the pages near it.

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{Criterion, criterion_group};
use hdov_storage::{CacheLimits, Error, PageCache, PageKey, PolicyKind};

const REQUESTS: usize = 20_000;
const PAGES: u64 = 16_384;

/// A deterministic skewed request sequence (xorshift).
fn requests() -> Vec<u64> {
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    (0..REQUESTS)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            if x.is_multiple_of(4) { x % PAGES } else { x % (PAGES / 4) }
        })
        .collect()
}

fn run(kind: PolicyKind, pages: usize, requests: &[u64], page: &Arc<[u8]>) -> u64 {
    let mut cache = PageCache::with_kind(CacheLimits::max_pages(pages), kind);
    for &p in requests {
        let key = PageKey { file: 0, page: p };
        black_box(cache.get_or_load(key, 0.5, || Ok::<_, Error>(page.clone())).expect("load"));
    }
    cache.stats().hits
}

fn bench(c: &mut Criterion) {
    let requests = requests();
    let page: Arc<[u8]> = Arc::from(vec![7u8; 64]);
    for pages in [256usize, 4096] {
        let hits = [PolicyKind::Lru, PolicyKind::Dov].map(|k| run(k, pages, &requests, &page));
        assert_eq!(hits[0], hits[1], "the two lists evict the same pages");
        println!("{pages} pages: {} hits of {REQUESTS}", hits[0]);
        let mut g = c.benchmark_group(format!("lru list, {pages} pages"));
        g.bench_function("lru crate (PolicyKind::Lru)", |b| b.iter(|| run(PolicyKind::Lru, pages, &requests, &page)));
        g.bench_function("ranked BTreeSet (the former Lru)", |b| {
            b.iter(|| run(PolicyKind::Dov, pages, &requests, &page))
        });
        g.finish();
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).measurement_time(Duration::from_secs(1)).warm_up_time(Duration::from_millis(300));
    targets = bench
}

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
}
