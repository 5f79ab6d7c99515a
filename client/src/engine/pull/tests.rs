//! The pull engine against scripted server answers on a simulated clock: deterministic, and
//! each runs in microseconds.

use super::*;
use portico_protocol::{NeedItem, NeedKind};

const SEG: u64 = 1000;

fn wire(_: u32) -> u64 {
    SEG
}

fn frame(lacking: Vec<u32>, consumed: u64) -> FrameState {
    FrameState {
        observer: crate::engine::test_observer(0.0),
        held: Vec::new(),
        lacking,
        incomplete: false,
        consumed,
    }
}

/// An answer listing `near` (needed next frame) then `far` (1,000 frames away).
fn answer(near: &[u32], far: &[u32]) -> PrefetchResponse {
    let item = |segment, frames| NeedItem {
        segment,
        kind: NeedKind::Geometry,
        lod: 0,
        bytes: SEG,
        frames,
    };
    PrefetchResponse {
        version: PROTOCOL_VERSION,
        items: near
            .iter()
            .map(|&s| item(s, 1))
            .chain(far.iter().map(|&s| item(s, 1000)))
            .collect(),
        evict: Vec::new(),
        range_cells: 1,
        lookahead_cells: 1,
        lookahead_objects: 1,
        lookahead_bytes: 0,
        truncated: false,
        micros: 0,
    }
}

/// Every request `pull` sends at `now`.
fn drain(pull: &mut Pull, now: Instant) -> Vec<Command> {
    std::iter::from_fn(|| pull.poll(now, &wire, &wire)).collect()
}

fn reads(cmds: &[Command]) -> Vec<(u64, Vec<u32>)> {
    cmds.iter()
        .filter_map(|c| match c {
            Command::Read(t, ids) => Some((*t, ids.clone())),
            Command::Ask(..) => None,
        })
        .collect()
}

fn asks(cmds: &[Command]) -> Vec<u64> {
    cmds.iter()
        .filter_map(|c| match c {
            Command::Ask(n, _) => Some(*n),
            Command::Read(..) => None,
        })
        .collect()
}

/// Every read of `cmds` comes back whole at `now`.
fn deliver(pull: &mut Pull, cmds: &[Command], now: Instant) -> Vec<Event> {
    reads(cmds)
        .into_iter()
        .flat_map(|(t, ids)| pull.read(t, now, Ok(ids.iter().map(|&i| (i, Ok(SEG))).collect())))
        .collect()
}

fn ms(t: Instant, ms: u64) -> Instant {
    t + Duration::from_millis(ms)
}

#[test]
fn a_cold_start_reads_what_the_frame_lacks_before_the_answer_comes() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    pull.frame(frame(vec![7, 8, 9], 0), t0, t0);
    let cmds = drain(&mut pull, t0);
    assert_eq!(asks(&cmds), vec![1]);
    assert_eq!(reads(&cmds), vec![(1, vec![7, 8, 9])]);
    // The answer comes 300 ms later: only then its items are read.
    let e = pull.answered(1, t0, Ok(answer(&[100, 101], &[])), ms(t0, 300));
    assert!(matches!(e, Event::Answer(_)));
    assert_eq!(
        reads(&drain(&mut pull, ms(t0, 300))),
        vec![(2, vec![100, 101])]
    );
}

#[test]
fn what_the_frame_lacks_goes_ahead_of_the_answer_and_is_not_read_twice() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    pull.frame(frame(vec![8], 0), t0, t0);
    let first = drain(&mut pull, t0);
    assert_eq!(reads(&first), vec![(1, vec![8])]);
    pull.answered(1, t0, Ok(answer(&[100, 8, 101], &[])), ms(t0, 1));
    assert_eq!(
        reads(&drain(&mut pull, ms(t0, 1))),
        vec![(2, vec![100, 101])]
    );
}

#[test]
fn read_ahead_waits_while_the_view_has_objects_with_nothing_to_draw() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    pull.frame(
        FrameState {
            incomplete: true,
            ..frame(vec![7], 0)
        },
        t0,
        t0,
    );
    let cmds = drain(&mut pull, t0);
    pull.answered(1, t0, Ok(answer(&[100, 101], &[])), ms(t0, 1));
    assert_eq!(reads(&cmds), vec![(1, vec![7])]);
    assert!(reads(&drain(&mut pull, ms(t0, 1))).is_empty());
}

#[test]
fn what_a_later_answer_can_bring_in_time_is_not_read_yet() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    pull.frame(frame(vec![], 0), t0, t0);
    drain(&mut pull, t0);
    pull.answered(1, t0, Ok(answer(&[100], &[200, 201])), ms(t0, 1));
    assert_eq!(reads(&drain(&mut pull, ms(t0, 1))), vec![(1, vec![100])]);
}

#[test]
fn one_prefetch_request_at_a_time_with_the_latest_observer() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    pull.frame(frame(vec![], 0), t0, t0);
    assert_eq!(asks(&drain(&mut pull, t0)), vec![1]);
    for (i, x) in [1.0, 2.0, 3.0].into_iter().enumerate() {
        let f = FrameState {
            observer: crate::engine::test_observer(x),
            ..frame(vec![], 0)
        };
        let at = ms(t0, 16 * (i as u64 + 1));
        pull.frame(f, at, at);
        assert!(drain(&mut pull, ms(t0, 16 * (i as u64 + 1))).is_empty());
    }
    pull.answered(1, t0, Ok(answer(&[], &[])), ms(t0, 60));
    let next = drain(&mut pull, ms(t0, 60));
    let [Command::Ask(2, req)] = next.as_slice() else {
        panic!("{next:?}")
    };
    assert_eq!(req.observer.eye[0], 3.0, "the latest observer");
}

#[test]
fn the_held_set_sent_names_what_is_on_its_way() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30).reasking(Reask::ALWAYS);
    let f = FrameState {
        held: vec![1, 2],
        ..frame(vec![5], 0)
    };
    pull.frame(f, t0, t0);
    let cmds = drain(&mut pull, t0);
    // The ask was sent before the read of 5: it names what the cache holds.
    let Command::Ask(_, req) = &cmds[0] else {
        panic!("{cmds:?}")
    };
    assert_eq!(portico_protocol::decode_held(&req.held), Some(vec![1, 2]));
    pull.answered(1, t0, Ok(answer(&[], &[])), ms(t0, 1));
    pull.frame(frame(vec![], 0), ms(t0, 2), ms(t0, 2));
    let cmds = drain(&mut pull, ms(t0, 2));
    let Command::Ask(_, req) = &cmds[0] else {
        panic!("{cmds:?}")
    };
    assert_eq!(
        portico_protocol::decode_held(&req.held),
        Some(vec![5]),
        "in flight"
    );
}

#[test]
fn a_walker_asks_again_once_it_has_moved_turned_or_waited_not_after_every_answer() {
    let t0 = Instant::now();
    let r = Reask::DEFAULT;
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    let at = |x: f32, dir: [f32; 3]| FrameState {
        observer: Observer {
            dir,
            ..crate::engine::test_observer(x)
        },
        ..frame(vec![], 0)
    };
    let ahead = [0.0, 0.0, -1.0];
    pull.frame(at(0.0, ahead), t0, t0);
    assert_eq!(asks(&drain(&mut pull, t0)), vec![1]);
    pull.answered(1, t0, Ok(answer(&[], &[])), ms(t0, 20));
    // Standing, or not yet as far as the threshold: the answer in hand stands.
    for (i, f) in [0.0, 0.2, 0.9].into_iter().enumerate() {
        let now = ms(t0, 40 + 20 * i as u64);
        pull.frame(at(f * r.moved_m, ahead), now, now);
        assert!(
            asks(&drain(&mut pull, now)).is_empty(),
            "asked at {f} of the way"
        );
    }
    // As far as the threshold: asked again.
    pull.frame(at(r.moved_m, ahead), ms(t0, 100), ms(t0, 100));
    assert_eq!(asks(&drain(&mut pull, ms(t0, 100))), vec![2]);
    pull.answered(2, ms(t0, 100), Ok(answer(&[], &[])), ms(t0, 120));
    // Turned past the threshold where it stands: asked again.
    let a = r.turned_rad * 1.01;
    let turned = [a.sin(), 0.0, -a.cos()];
    pull.frame(at(r.moved_m, turned), ms(t0, 140), ms(t0, 140));
    assert_eq!(asks(&drain(&mut pull, ms(t0, 140))), vec![3]);
    pull.answered(3, ms(t0, 140), Ok(answer(&[], &[])), ms(t0, 160));
    // Nothing changes: asked again once the answer has aged.
    let aged = ms(t0, 140 + (r.age_s * 1000.0) as u64);
    pull.frame(
        at(r.moved_m, turned),
        aged - Duration::from_millis(50),
        aged - Duration::from_millis(50),
    );
    assert!(asks(&drain(&mut pull, aged - Duration::from_millis(50))).is_empty());
    pull.frame(at(r.moved_m, turned), aged, aged);
    assert_eq!(asks(&drain(&mut pull, aged)), vec![4]);
    // Asking after every answer, as before: the same observer is asked about again.
    let mut every = Pull::new(Policy::default(), 8, 1 << 30).reasking(Reask::ALWAYS);
    every.frame(at(0.0, ahead), t0, t0);
    assert_eq!(asks(&drain(&mut every, t0)), vec![1]);
    every.answered(1, t0, Ok(answer(&[], &[])), ms(t0, 20));
    every.frame(at(0.0, ahead), ms(t0, 40), ms(t0, 40));
    assert_eq!(asks(&drain(&mut every, ms(t0, 40))), vec![2]);
}

#[test]
fn a_failed_ask_is_made_again_after_the_backoff_though_the_observer_stands() {
    let t0 = Instant::now();
    let r = Reask::DEFAULT;
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    let at = |x: f32| FrameState {
        observer: crate::engine::test_observer(x),
        ..frame(vec![], 0)
    };
    pull.frame(at(0.0), t0, t0);
    assert_eq!(asks(&drain(&mut pull, t0)), vec![1]);
    pull.answered(1, t0, Ok(answer(&[], &[])), ms(t0, 20));
    // Moved on: asked, and the ask fails.
    pull.frame(at(r.moved_m), ms(t0, 40), ms(t0, 40));
    assert_eq!(asks(&drain(&mut pull, ms(t0, 40))), vec![2]);
    pull.answered(
        2,
        ms(t0, 40),
        Err(Fault::Failed("refused".into())),
        ms(t0, 60),
    );
    // Standing where it was when the ask failed: not during the backoff, then asked again (the
    // answer in hand is still the one from before it moved).
    pull.frame(at(r.moved_m), ms(t0, 80), ms(t0, 80));
    assert!(asks(&drain(&mut pull, ms(t0, 80))).is_empty());
    let later = ms(t0, 60) + BACKOFF;
    pull.frame(at(r.moved_m), later, later);
    assert_eq!(asks(&drain(&mut pull, later)), vec![3]);
}

#[test]
fn the_wait_before_the_next_ask_follows_the_pace() {
    let r = Reask::DEFAULT;
    let still = crate::engine::test_observer(0.0);
    assert_eq!(r.wait_s(&still), f64::from(r.age_s));
    let walking = Observer {
        velocity: [1.5, 0.0, 0.0],
        ..still
    };
    assert!((r.wait_s(&walking) - f64::from(r.moved_m / 1.5)).abs() < 1e-6);
    let turning = Observer {
        turn: [0.0, 4.0, 0.0],
        ..walking
    };
    assert!((r.wait_s(&turning) - f64::from(r.turned_rad / 4.0)).abs() < 1e-6);
    assert_eq!(Reask::ALWAYS.wait_s(&turning), 0.0);
}

#[test]
fn a_failed_prefetch_request_waits_before_the_next() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    pull.frame(frame(vec![], 0), t0, t0);
    drain(&mut pull, t0);
    let e = pull.answered(1, t0, Err(Fault::Failed("refused".into())), ms(t0, 10));
    assert_eq!(e, Event::Failed("refused".into()));
    pull.frame(frame(vec![], 1), ms(t0, 20), ms(t0, 20));
    assert!(
        asks(&drain(&mut pull, ms(t0, 20))).is_empty(),
        "backing off"
    );
    assert_eq!(asks(&drain(&mut pull, ms(t0, 10) + BACKOFF)), vec![2]);
}

#[test]
fn a_410_stops_pull() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    pull.frame(frame(vec![3], 0), t0, t0);
    let cmds = drain(&mut pull, t0);
    let stale = Fault::Stale("410 Gone".into());
    let events = pull.read(reads(&cmds)[0].0, ms(t0, 5), Err(stale));
    assert_eq!(events, vec![Event::Stale("410 Gone".into())]);
    assert!(pull.stopped());
    pull.frame(frame(vec![4], 1), ms(t0, 10), ms(t0, 10));
    assert!(drain(&mut pull, ms(t0, 10)).is_empty());
}

#[test]
fn a_damaged_segment_fails_alone_and_is_read_again_after_a_rest() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    pull.frame(frame(vec![3, 4], 0), t0, t0);
    let cmds = drain(&mut pull, t0);
    let events = pull.read(
        reads(&cmds)[0].0,
        ms(t0, 5),
        Ok(vec![(3, Err("segment 3: corrupt".into())), (4, Ok(SEG))]),
    );
    assert_eq!(events[0], Event::Failed("segment 3: corrupt".into()));
    assert!(matches!(events[1], Event::Segment { id: 4, .. }));
    pull.frame(frame(vec![3], 2), ms(t0, 6), ms(t0, 6));
    assert!(reads(&drain(&mut pull, ms(t0, 6))).is_empty(), "resting");
    let later = ms(t0, 5) + crate::schedule::RETRY_AFTER;
    pull.answered(1, t0, Ok(answer(&[], &[])), later);
    pull.frame(frame(vec![3], 2), later, later);
    assert_eq!(reads(&drain(&mut pull, later))[0].1, vec![3]);
}

#[test]
fn a_segment_missing_from_a_batch_is_asked_again() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    pull.frame(frame(vec![3, 4], 0), t0, t0);
    let cmds = drain(&mut pull, t0);
    let events = pull.read(reads(&cmds)[0].0, ms(t0, 5), Ok(vec![(4, Ok(SEG))]));
    assert_eq!(events.len(), 1);
    let later = ms(t0, 5) + crate::schedule::RETRY_AFTER;
    pull.frame(frame(vec![3, 4], 1), later, later);
    assert_eq!(reads(&drain(&mut pull, later))[0].1, vec![3]);
}

#[test]
fn the_window_bounds_what_is_delivered_and_not_taken() {
    let t0 = Instant::now();
    // Room for two segments; each read request carries what fits.
    let mut pull = Pull::new(Policy::default(), 8, 2 * SEG);
    pull.frame(frame((1..=6).collect(), 0), t0, t0);
    let cmds = drain(&mut pull, t0);
    assert_eq!(reads(&cmds), vec![(1, vec![1, 2])]);
    let events = deliver(&mut pull, &cmds, ms(t0, 5));
    assert_eq!(events.len(), 2);
    // Delivered but not taken: still no room.
    assert!(reads(&drain(&mut pull, ms(t0, 6))).is_empty());
    // The frame loop took both (events 1 and 2).
    pull.answered(1, t0, Ok(answer(&[], &[])), ms(t0, 7));
    pull.frame(frame((3..=6).collect(), 3), ms(t0, 8), ms(t0, 8));
    assert_eq!(reads(&drain(&mut pull, ms(t0, 8)))[0].1, vec![3, 4]);
}

#[test]
fn no_more_than_parallel_reads_are_in_flight() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 2, 1 << 30);
    // 100 small segments: seven read requests' worth, but two at a time.
    pull.frame(frame((1..=100).collect(), 0), t0, t0);
    let cmds = drain(&mut pull, t0);
    assert_eq!(reads(&cmds).len(), 2, "{cmds:?}");
    assert_eq!(pull.in_flight(), 3, "two reads and the prefetch request");
    let first = reads(&cmds)[0].clone();
    pull.read(
        first.0,
        ms(t0, 5),
        Ok(first.1.iter().map(|&i| (i, Ok(SEG))).collect()),
    );
    assert_eq!(
        reads(&drain(&mut pull, ms(t0, 5))).len(),
        1,
        "one more as one ends"
    );
}

#[test]
fn events_are_numbered_from_where_another_transport_left_off() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 3 * SEG).resume(10);
    pull.frame(frame(vec![1, 2, 3], 10), t0, t0);
    let cmds = drain(&mut pull, t0);
    deliver(&mut pull, &cmds, ms(t0, 5));
    assert_eq!(pull.events(), 13);
    // Taken up to event 12 only: segment 3 still holds its place in the window.
    pull.frame(frame(vec![4, 5, 6], 12), ms(t0, 6), ms(t0, 6));
    assert_eq!(reads(&drain(&mut pull, ms(t0, 6)))[0].1, vec![4, 5]);
}

#[test]
fn the_clients_own_list_asks_the_server_nothing() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 8, 1 << 30);
    pull.want(vec![9, 8], 0, t0);
    let cmds = drain(&mut pull, t0);
    assert_eq!(cmds, vec![Command::Read(1, vec![9, 8])]);
}

#[test]
fn handing_over_to_push_forgets_the_list_but_not_what_is_in_flight() {
    let t0 = Instant::now();
    let mut pull = Pull::new(Policy::default(), 1, 1 << 30);
    pull.frame(frame(vec![1], 0), t0, t0);
    let cmds = drain(&mut pull, t0);
    pull.answered(1, t0, Ok(answer(&[2, 3], &[])), ms(t0, 1));
    pull.clear(ms(t0, 2));
    let events = deliver(&mut pull, &cmds, ms(t0, 3));
    assert!(matches!(events[0], Event::Segment { id: 1, .. }));
    assert!(drain(&mut pull, ms(t0, 3)).is_empty());
}
