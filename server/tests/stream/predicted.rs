//! Stream sessions under the predicted lookahead (the default policy): their places are the
//! eye's metre of its cell and buckets of its view, velocity and turn, and a walking observer
//! costs a lookup only when it changes place.

use super::common;
use super::{binary, connect, hello, next, shared, start};
use futures_util::SinkExt;
use portico_protocol::{LookaheadCull, Observer, StreamClient};
use std::time::{Duration, Instant};

#[tokio::test]
async fn under_the_predicted_lookahead_a_walker_computes_only_when_its_place_changes() {
    use std::sync::atomic::Ordering::Relaxed;
    let s = start(shared()).await;
    // The default policy: the predicted lookahead.
    let req = common::request(s.state.db());
    assert_eq!(req.policy.lookahead_cull, LookaheadCull::Predicted);
    let p = &s.state.prefetcher;
    // Walking along +x at 1.4 m/s, 20 updates a second, for 1.5 s, along the middle of a live
    // cell more than 3 m long.
    let g = p.graph().expect("cells");
    let c = g
        .cells
        .iter()
        .find(|c| c.live && c.bounds.max[0] - c.bounds.min[0] > 3.0)
        .expect("a long cell");
    let mid = |k: usize| (c.bounds.min[k] + c.bounds.max[k]) * 0.5;
    let walk: Vec<Observer> = (0..30)
        .map(|i| {
            let mut o = req.observer;
            o.eye = [c.bounds.min[0] + 0.4 + 0.07 * i as f32, mid(1), mid(2)];
            o.velocity = [1.4, 0.0, 0.0];
            o
        })
        .collect();
    let places: Vec<_> = walk
        .iter()
        .map(|o| p.share_place(o, &req.policy).expect("a place"))
        .collect();
    let changes = 1 + places.windows(2).filter(|w| w[0] != w[1]).count();
    assert!(
        (2..=walk.len() / 2).contains(&changes),
        "{changes} places along the walk"
    );
    let answers = p.shared_answers();
    let looked_up = || answers.hits.load(Relaxed) + answers.misses.load(Relaxed);
    let (before, computed_before) = (looked_up(), answers.misses.load(Relaxed));
    let mut ws = connect(&s.base).await;
    hello(&mut ws, req.policy, 1 << 30).await;
    for o in &walk {
        ws.send(binary(&StreamClient::Observer(*o))).await.unwrap();
        // Drain what comes while the next update is due.
        while next(&mut ws, Duration::from_millis(20)).await.is_some() {}
    }
    let m = &s.state.metrics;
    let deadline = Instant::now() + Duration::from_secs(10);
    while m.stream_updates.load(Relaxed) < walk.len() as u64 {
        assert!(Instant::now() < deadline, "the updates did not all arrive");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    // Each place's list was computed once at most, and looked up only when the walker changed
    // place (twice for a place whose next update came while its list was being computed):
    // most updates cost nothing; no session computed a list of its own.
    let computed = answers.misses.load(Relaxed) - computed_before;
    let lookups = looked_up() - before;
    assert!(
        (1..=changes as u64).contains(&computed),
        "{computed} lists computed for {changes} places"
    );
    assert!(
        lookups <= 2 * changes as u64 && lookups < walk.len() as u64 / 2,
        "{lookups} lookups for {changes} places in {} updates",
        walk.len()
    );
    assert_eq!(m.stream_own_lists.load(Relaxed), 0);
    assert!(m.prefetch_answers.load(Relaxed) <= 2 * changes as u64);
}
