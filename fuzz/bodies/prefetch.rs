//! Fuzzes what a prefetch request reaches on the server: any bytes, decoded as a request (bincode
//! and JSON), checked by the server's `validate`, and, when valid, answered by
//! `Prefetcher::answer_within` on the tiny building under a deadline. Never a panic, and every
//! answer stays within its bounds (release hints capped).
use portico_data::prefetch::{Budget, MAX_RELEASE_HINTS, Prefetcher};
use portico_protocol::PrefetchRequest;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

fn prefetcher() -> &'static Prefetcher {
    static P: OnceLock<Prefetcher> = OnceLock::new();
    P.get_or_init(|| {
        let db = portico_data::Database::open(crate::tiny::tiny_db()).unwrap();
        Prefetcher::new(Arc::new(db)).unwrap()
    })
}

/// One input; returns how many requests it decoded to were answered (0, 1 or 2), so a replay
/// can tell that the answers' checks ran at all.
pub fn run(data: &[u8]) -> usize {
    let p = prefetcher();
    let segments = p.database().segments().len();
    let decoded = [
        portico_protocol::from_bincode::<PrefetchRequest>(data).ok(),
        portico_protocol::from_json::<PrefetchRequest>(data).ok(),
    ];
    let mut answered = 0;
    for req in decoded.into_iter().flatten() {
        let Ok(held) = portico_server::validate_prefetch(&req, segments) else {
            continue;
        };
        let budget = Budget::until(Instant::now() + Duration::from_millis(250));
        if let Ok(a) = p.answer_within(&req.observer, &req.policy, &held, &budget) {
            assert!(a.evict.len() <= MAX_RELEASE_HINTS);
            assert!(a.items.iter().all(|i| (i.segment as usize) < segments));
            answered += 1;
        }
    }
    answered
}
