//! The WebSocket stream's promises, each with a deadline: pushes are paced to the session's byte
//! rate, nothing the client holds is sent again (and an `Evicted` segment is), queued segments a
//! new observer no longer needs are reported `Dropped` and never sent, an observer that stays in
//! its cell and direction bucket costs no computation, and a silent client is closed after the
//! idle timeout with a Close frame. Those use Funkhouser's range lookahead on a server that
//! shares lists by place whatever its load; under the predicted lookahead (the default) a
//! session pushes an item only once a later list could not bring it in time, and a walker
//! looks a list up only when it changes place (`predicted.rs`).

use futures_util::{SinkExt, StreamExt};
use portico_data::prefetch::{Budget, NeedList};
use portico_protocol::{
    LookaheadCull, Observer, PROTOCOL_VERSION, Policy, PrefetchRequest, ServerFrame, StreamClient,
    StreamServer,
};
use portico_server::AppState;
use portico_server::Config;
use std::collections::HashSet;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::Message;

#[path = "../common/mod.rs"]
mod common;
mod paged;
mod predicted;
use common::start;

/// A request under Funkhouser's range lookahead (every visible cell), whose need lists the
/// sessions share.
fn request(db: &portico_data::Database) -> PrefetchRequest {
    let mut r = common::request(db);
    r.policy.lookahead_cull = LookaheadCull::Any;
    r
}

type Ws =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

fn binary(msg: &StreamClient) -> Message {
    Message::Binary(portico_protocol::to_bincode(msg).unwrap().into())
}

async fn connect(base: &str) -> Ws {
    let url = base.replace("http://", "ws://") + "/v1/stream";
    tokio_tungstenite::connect_async(&url).await.unwrap().0
}

async fn hello(ws: &mut Ws, policy: Policy, rate: u64) {
    let msg = StreamClient::Hello {
        version: PROTOCOL_VERSION,
        policy,
        rate_bytes_per_s: rate,
        rtt_ms: 0,
    };
    ws.send(binary(&msg)).await.unwrap();
}

/// A server that shares answers by place whatever its load (by default a few clients get their
/// own answers: `Config::exact_share`).
fn shared() -> Config {
    Config {
        exact_share: 0.0,
        ..Config::default()
    }
}

/// A server that answers every observer with its own list.
fn own() -> Config {
    Config {
        shared_answers: false,
        ..Config::default()
    }
}

/// The need list a session pushes for `obs`: the shared list of its cell and direction bucket.
fn need_list(state: &AppState, obs: &Observer, policy: &Policy) -> Arc<NeedList> {
    let p = &state.prefetcher;
    let key = p
        .share_key(obs, policy)
        .expect("the test building has cells");
    p.shared_list(&key, obs, policy, &Budget::unlimited())
        .unwrap()
}

/// What the server sends next, or `None` when nothing comes within `wait`.
#[derive(Debug)]
enum Got {
    Segment(u32, usize),
    Dropped(Vec<u32>),
    Error(String),
    /// A page's deflated bytes.
    Page(Vec<u8>),
    Close,
}

async fn next(ws: &mut Ws, wait: Duration) -> Option<Got> {
    loop {
        let m = tokio::time::timeout(wait, ws.next()).await.ok()?;
        match m {
            None | Some(Err(_)) | Some(Ok(Message::Close(_))) => return Some(Got::Close),
            Some(Ok(Message::Binary(frame))) => {
                return Some(
                    match portico_protocol::parse_server_frame(&frame).unwrap() {
                        ServerFrame::Segment(id, bytes) => Got::Segment(id, bytes.len()),
                        ServerFrame::Control(StreamServer::Dropped(d)) => Got::Dropped(d),
                        ServerFrame::Control(StreamServer::Error(e)) => Got::Error(e.message),
                        ServerFrame::Page(p) => Got::Page(p.to_vec()),
                    },
                );
            }
            Some(Ok(_)) => continue,
        }
    }
}

/// Receives segments until `want` of them have arrived (10 s at most); their ids and bytes.
async fn segments(ws: &mut Ws, want: usize) -> Vec<(u32, usize)> {
    let mut got = Vec::new();
    while got.len() < want {
        match next(ws, Duration::from_secs(10)).await {
            Some(Got::Segment(id, n)) => got.push((id, n)),
            Some(Got::Dropped(d)) => panic!("dropped {d:?} with one observer"),
            Some(Got::Error(e)) => panic!("error: {e}"),
            Some(Got::Page(_)) => panic!("a page for a session that asked for none"),
            Some(Got::Close) => panic!("closed after {} of {want} segments", got.len()),
            None => panic!("only {} of {want} segments within 10 s", got.len()),
        }
    }
    got
}

#[tokio::test]
async fn pushes_are_paced_to_the_sessions_byte_rate() {
    let s = start(shared()).await;
    let req = request(s.state.db());
    let answer = need_list(&s.state, &req.observer, &req.policy);
    let total: u64 = answer.items.iter().map(|i| i.bytes).sum();
    assert!(total > 50_000, "too little to pace: {total} bytes");
    // A rate that takes 1.2 s for the whole answer, and one that is not a limit.
    let rate = total * 10 / 12;
    let mut elapsed = Vec::new();
    for rate in [rate, 1 << 30] {
        let mut ws = connect(&s.base).await;
        hello(&mut ws, req.policy, rate).await;
        let t = Instant::now();
        ws.send(binary(&StreamClient::Observer(req.observer)))
            .await
            .unwrap();
        let got = segments(&mut ws, answer.items.len()).await;
        elapsed.push(t.elapsed().as_secs_f64());
        let sent: u64 = got.iter().map(|&(_, n)| n as u64).sum();
        assert_eq!(sent, total);
    }
    // The first push goes at once and the last waits for all before it, less the pacing
    // bucket's 10 ms burst: at least (total - the largest item) / rate - 10 ms.
    let largest = answer.items.iter().map(|i| i.bytes).max().unwrap() as f64;
    let paced_floor = (total as f64 - largest) / rate as f64 - 0.010;
    assert!(
        elapsed[0] >= paced_floor,
        "paced: {:.3} s, at least {paced_floor:.3} s expected",
        elapsed[0]
    );
    assert!(
        elapsed[1] < elapsed[0],
        "unpaced {:.3} s vs paced {:.3} s",
        elapsed[1],
        elapsed[0]
    );
}

#[tokio::test]
async fn nothing_held_is_sent_again_and_an_evicted_segment_is() {
    let s = start(shared()).await;
    let req = request(s.state.db());
    let n = need_list(&s.state, &req.observer, &req.policy).items.len();
    let mut ws = connect(&s.base).await;
    hello(&mut ws, req.policy, 1 << 30).await;
    let observe = binary(&StreamClient::Observer(req.observer));
    ws.send(observe.clone()).await.unwrap();
    let got = segments(&mut ws, n).await;
    let ids: HashSet<u32> = got.iter().map(|&(id, _)| id).collect();
    assert_eq!(ids.len(), n, "a segment was sent twice");
    // The same observer again: the client holds everything, nothing comes.
    ws.send(observe.clone()).await.unwrap();
    // (Only silence counts: a close or an error would also mean nothing was sent.)
    let quiet = next(&mut ws, Duration::from_millis(500)).await;
    assert!(quiet.is_none(), "held, yet the server sent {quiet:?}");
    // The client evicts one: it, and only it, comes again.
    let evicted = got[got.len() / 2].0;
    ws.send(binary(&StreamClient::Evicted(vec![evicted])))
        .await
        .unwrap();
    ws.send(observe).await.unwrap();
    let again = segments(&mut ws, 1).await;
    assert_eq!(again[0].0, evicted);
    let quiet = next(&mut ws, Duration::from_millis(500)).await;
    assert!(quiet.is_none(), "held again, yet the server sent {quiet:?}");
}

#[tokio::test]
async fn queued_segments_no_longer_needed_are_dropped_and_never_sent() {
    let s = start(shared()).await;
    let db = s.state.db();
    let req = request(db);
    let g = db.cell_graph().unwrap().unwrap();
    // A second observer in the live cell farthest from the first.
    let here = glam::Vec3::from(req.observer.eye);
    let far = g
        .cells
        .iter()
        .filter(|c| c.live)
        .map(|c| glam::Vec3::from(c.bounds.min).lerp(glam::Vec3::from(c.bounds.max), 0.5))
        .max_by(|a, b| a.distance(here).total_cmp(&b.distance(here)))
        .unwrap();
    let there = Observer {
        eye: far.into(),
        ..req.observer
    };
    let policy = Policy {
        read_bytes: 1 << 30,
        ..req.policy
    };
    let answer =
        |o: &Observer| -> HashSet<u32> { need_list(&s.state, o, &policy).segments.clone() };
    let (first, second) = (answer(&req.observer), answer(&there));
    assert!(
        first.difference(&second).count() > 2,
        "the two observers need nearly the same segments"
    );
    let mut ws = connect(&s.base).await;
    // 20 KB/s: the first answer's queue drains for seconds.
    hello(&mut ws, policy, 20_000).await;
    ws.send(binary(&StreamClient::Observer(req.observer)))
        .await
        .unwrap();
    let early = segments(&mut ws, 1).await;
    ws.send(binary(&StreamClient::Observer(there)))
        .await
        .unwrap();
    let mut sent: HashSet<u32> = early.iter().map(|&(id, _)| id).collect();
    let mut dropped = None;
    while dropped.is_none() {
        match next(&mut ws, Duration::from_secs(10)).await {
            Some(Got::Segment(id, _)) => {
                sent.insert(id);
            }
            Some(Got::Dropped(d)) => dropped = Some(d),
            other => panic!("no Dropped within 10 s: {}", other.is_some()),
        }
    }
    let dropped: HashSet<u32> = dropped.unwrap().into_iter().collect();
    assert!(!dropped.is_empty());
    assert!(
        dropped.is_subset(&first) && dropped.is_disjoint(&second),
        "dropped segments must be the first observer's that the second does not need"
    );
    // What was dropped never comes; the rest of what arrives is the second observer's.
    while let Some(Got::Segment(id, _)) = next(&mut ws, Duration::from_millis(700)).await {
        assert!(
            !dropped.contains(&id),
            "segment {id} sent after it was dropped"
        );
        assert!(
            second.contains(&id),
            "segment {id} is not needed by the latest observer"
        );
    }
}

#[tokio::test]
async fn a_silent_client_is_closed_after_the_idle_timeout() {
    let s = start(Config {
        idle_timeout: Duration::from_millis(300),
        ..Config::default()
    })
    .await;
    let mut ws = connect(&s.base).await;
    let t = Instant::now();
    match next(&mut ws, Duration::from_secs(5)).await {
        Some(Got::Close) => {}
        Some(_) => panic!("a message to a silent client"),
        None => panic!("still open after 5 s"),
    }
    let waited = t.elapsed();
    assert!(
        waited >= Duration::from_millis(250) && waited < Duration::from_secs(3),
        "closed after {waited:?}, the idle timeout is 300 ms"
    );
    // A client that talks is not closed: pings at 100 ms keep it open past the timeout.
    let mut ws = connect(&s.base).await;
    for _ in 0..8 {
        ws.send(Message::Ping(vec![].into())).await.unwrap();
        if let Some(Got::Close) = next(&mut ws, Duration::from_millis(100)).await {
            panic!("closed although the client talks");
        }
    }
}

#[tokio::test]
async fn an_observer_that_stays_in_its_cell_and_bucket_costs_no_computation() {
    use std::sync::atomic::Ordering::Relaxed;
    let s = start(shared()).await;
    let req = request(s.state.db());
    let p = &s.state.prefetcher;
    let place = p.share_place(&req.observer, &req.policy).unwrap();
    // Twenty observers a few centimetres apart, turning a little: one place.
    let walk: Vec<Observer> = (0..20)
        .map(|i| {
            let mut o = req.observer;
            o.eye[0] += 0.002 * i as f32;
            o.dir[1] += 0.001 * i as f32;
            o
        })
        .filter(|o| p.share_place(o, &req.policy) == Some(place))
        .collect();
    assert!(walk.len() >= 10, "the walk left its place at once");
    let n = need_list(&s.state, &req.observer, &req.policy).items.len();
    let misses = p.shared_answers().misses.load(Relaxed);
    let answers = s.state.metrics.prefetch_answers.load(Relaxed);
    let mut ws = connect(&s.base).await;
    hello(&mut ws, req.policy, 1 << 30).await;
    for o in &walk {
        ws.send(binary(&StreamClient::Observer(*o))).await.unwrap();
    }
    let got = segments(&mut ws, n).await;
    assert_eq!(got.len(), n);
    let quiet = next(&mut ws, Duration::from_millis(300)).await;
    assert!(quiet.is_none(), "more than the list: {quiet:?}");
    // The list was computed once (above, by need_list) and taken from the cache once; the
    // other observers changed nothing.
    assert_eq!(p.shared_answers().misses.load(Relaxed), misses);
    assert_eq!(s.state.metrics.prefetch_answers.load(Relaxed), answers + 1);
    assert_eq!(
        s.state.metrics.stream_updates.load(Relaxed),
        walk.len() as u64
    );
    let text = reqwest::get(format!("{}/metrics", s.base))
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    let count = text
        .lines()
        .find_map(|l| l.strip_prefix("portico_stream_update_seconds_count "))
        .unwrap();
    assert_eq!(count, walk.len().to_string());
    assert!(text.contains("process_cpu_seconds_total "), "{text}");
    assert!(text.contains("portico_shared_hits_total 1\n"), "{text}");
}

#[tokio::test]
async fn a_session_pushes_no_more_than_the_clients_cache_holds_but_all_it_must() {
    let s = start(shared()).await;
    let req = request(s.state.db());
    let full = need_list(&s.state, &req.observer, &req.policy);
    // A cache that holds a third of the list.
    let third: u64 = full.items.iter().map(|i| i.bytes).sum::<u64>() / 3;
    let policy = Policy {
        cache_bytes: third,
        ..req.policy
    };
    let list = need_list(&s.state, &req.observer, &policy);
    assert!(
        list.fit > 0 && list.fit < list.items.len(),
        "{} of {}",
        list.fit,
        list.items.len()
    );
    let want: HashSet<u32> = (0..list.items.len())
        .filter(|&i| i < list.fit || list.must[i])
        .map(|i| list.items[i].segment)
        .collect();
    let mut ws = connect(&s.base).await;
    hello(&mut ws, policy, 1 << 30).await;
    ws.send(binary(&StreamClient::Observer(req.observer)))
        .await
        .unwrap();
    let got = segments(&mut ws, want.len()).await;
    let got: HashSet<u32> = got.iter().map(|&(id, _)| id).collect();
    assert_eq!(got, want);
    let quiet = next(&mut ws, Duration::from_millis(400)).await;
    assert!(quiet.is_none(), "pushed past the cache: {quiet:?}");
}

/// Deadline-ordered push (`portico_data::deadline`): with the predicted lookahead a session
/// pushes what the observer needs now at once, and an item needed `frames` ahead only when the
/// list has aged enough that the next one could not bring it in time; in the end, all of it.
#[tokio::test]
async fn a_predicted_session_pushes_each_item_when_it_cannot_wait_for_the_next_list() {
    let s = start(own()).await;
    let mut req = common::request(s.state.db());
    assert_eq!(req.policy.lookahead_cull, LookaheadCull::Predicted);
    req.observer.velocity = [1.5, 0.0, 0.0];
    let list = s
        .state
        .prefetcher
        .need_list_within(&req.observer, &req.policy, &Budget::unlimited())
        .unwrap();
    let frames: std::collections::HashMap<u32, u32> =
        list.items.iter().map(|i| (i.segment, i.frames)).collect();
    let late = list.items.iter().filter(|i| i.frames >= 8).count();
    let now = list.items.iter().filter(|i| i.frames == 0).count();
    assert!(
        late > 0 && now > 0,
        "{now} items now, {late} 8 frames ahead or more"
    );
    let want: HashSet<u32> = (0..list.items.len())
        .filter(|&i| i < list.fit || list.must[i])
        .map(|i| list.items[i].segment)
        .collect();

    let mut ws = connect(&s.base).await;
    hello(&mut ws, req.policy, 1 << 30).await;
    let t0 = Instant::now();
    ws.send(binary(&StreamClient::Observer(req.observer)))
        .await
        .unwrap();
    let dt = f64::from(req.policy.frame_time_s);
    let mut got = HashSet::new();
    while got.len() < want.len() {
        match next(&mut ws, Duration::from_secs(10)).await {
            Some(Got::Segment(id, _)) => {
                // Due when 3 frames (the next list, the margin) plus the list's age reach it;
                // a frame of slack for the scheduler.
                let age = t0.elapsed().as_secs_f64() / dt;
                let f = *frames
                    .get(&id)
                    .unwrap_or_else(|| panic!("segment {id} is not in the observer's own list"));
                assert!(
                    f64::from(f) <= 4.0 + age,
                    "segment {id}, needed {f} frames ahead, pushed after {age:.1} frames"
                );
                got.insert(id);
            }
            other => panic!("{other:?} after {} of {} segments", got.len(), want.len()),
        }
    }
    assert_eq!(got, want);
    let quiet = next(&mut ws, Duration::from_millis(300)).await;
    assert!(quiet.is_none(), "pushed past the list: {quiet:?}");
}

/// What the client's frame lacked (`Lacking`) goes ahead of the need list, and a `Lacking`
/// naming a segment the database does not have is refused, naming it, while the session goes
/// on.
#[tokio::test]
async fn what_the_frame_lacked_is_pushed_first_and_a_bad_id_is_refused() {
    let s = start(own()).await;
    let req = common::request(s.state.db());
    let list = s
        .state
        .prefetcher
        .need_list_within(&req.observer, &req.policy, &Budget::unlimited())
        .unwrap();
    let n = s.state.db().segments().len() as u32;
    // Two segments the list does not name: nothing but Lacking can bring them.
    let extra: Vec<u32> = (0..n)
        .rev()
        .filter(|id| !list.segments.contains(id))
        .take(2)
        .collect();
    assert_eq!(extra.len(), 2);
    let mut ws = connect(&s.base).await;
    hello(&mut ws, req.policy, 1 << 30).await;
    ws.send(binary(&StreamClient::Lacking(vec![n + 7])))
        .await
        .unwrap();
    match next(&mut ws, Duration::from_secs(5)).await {
        Some(Got::Error(e)) => assert!(e.contains(&format!("segment {}", n + 7)), "{e}"),
        other => panic!("expected an error, got {other:?}"),
    }
    ws.send(binary(&StreamClient::Lacking(extra.clone())))
        .await
        .unwrap();
    ws.send(binary(&StreamClient::Observer(req.observer)))
        .await
        .unwrap();
    let got = segments(&mut ws, 3).await;
    let first: Vec<u32> = got.iter().take(2).map(|&(id, _)| id).collect();
    assert_eq!(first, extra, "what the frame lacked comes first");
    assert!(list.segments.contains(&got[2].0), "then the list: {got:?}");
}
