//! A push session's messages, on a simulated clock.

use super::*;
use portico_protocol::decode_held;

fn frame(held: &[u32], lacking: &[u32], consumed: u64) -> FrameState {
    FrameState {
        observer: crate::engine::test_observer(0.0),
        held: held.to_vec(),
        lacking: lacking.to_vec(),
        incomplete: false,
        consumed,
    }
}

fn open(held: &[u32], paged: bool) -> (Push, Vec<StreamClient>) {
    let rtt = Duration::from_millis(40);
    let held = held.iter().copied();
    Push::open(
        "ws://x/v1/stream",
        Policy::default(),
        1 << 20,
        rtt,
        paged,
        held,
        0,
    )
}

#[test]
fn a_session_opens_with_hello_pages_and_what_the_cache_holds() {
    let (_, out) = open(&[], false);
    assert!(matches!(
        out.as_slice(),
        [StreamClient::Hello { rtt_ms: 40, .. }]
    ));
    let (_, out) = open(&[5, 3], true);
    assert!(matches!(out[0], StreamClient::Hello { .. }));
    assert_eq!(out[1], StreamClient::Pages);
    let StreamClient::Holding(h) = &out[2] else {
        panic!("{out:?}")
    };
    assert_eq!(decode_held(h), Some(vec![3, 5]));
}

#[test]
fn each_frame_sends_its_observer_and_what_it_lacked_when_that_changed() {
    let t = Instant::now();
    let (mut push, _) = open(&[], false);
    let out = push.frame(&frame(&[], &[7, 8], 0), t);
    assert_eq!(out[0], StreamClient::Lacking(vec![7, 8]));
    assert!(matches!(out[1], StreamClient::Observer(_)));
    let out = push.frame(&frame(&[], &[7, 8], 0), t);
    assert!(
        matches!(out.as_slice(), [StreamClient::Observer(_)]),
        "unchanged"
    );
    let out = push.frame(&frame(&[], &[], 0), t);
    assert_eq!(out[0], StreamClient::Lacking(vec![]), "cleared");
}

#[test]
fn what_the_cache_released_is_told_even_if_it_came_and_went_between_frames() {
    let t = Instant::now();
    let (mut push, _) = open(&[1, 2], false);
    // Segment 9 is handed on as event 0, taken, and evicted before the next frame.
    push.handed(Some(9));
    push.handed(None);
    let out = push.frame(&frame(&[2], &[], 2), t);
    assert_eq!(out[0], StreamClient::Evicted(vec![1, 9]));
    // Handed but not yet taken: not evicted, whatever the held set says.
    push.handed(Some(10));
    let out = push.frame(&frame(&[2], &[], 2), t);
    assert!(matches!(out.as_slice(), [StreamClient::Observer(_)]));
    let out = push.frame(&frame(&[2, 10], &[], 3), t);
    assert!(matches!(out.as_slice(), [StreamClient::Observer(_)]));
    assert_eq!(push.events(), 3);
}

#[test]
fn pushed_segments_carry_when_the_observer_before_them_was_sent() {
    let t = Instant::now();
    let (mut push, _) = open(&[], false);
    push.frame(&frame(&[], &[], 0), t);
    let bytes = portico_protocol::segment_frame(4, b"abc");
    let got = push.incoming(&bytes, t + Duration::from_millis(30));
    let want = Pushed::Segment {
        id: 4,
        bytes: b"abc",
        listed_at: t,
    };
    assert_eq!(got, want);
    let garbage = push.incoming(&[0xEE, 1, 2], t);
    assert!(matches!(garbage, Pushed::Failed(ref e) if e.contains("ws://x/v1/stream")));
}

#[test]
fn a_close_for_another_database_is_stale_and_any_other_is_a_failure() {
    let (push, _) = open(&[], false);
    let stale = push.closed(Some((CLOSE_STALE, "rebuilt")));
    assert!(
        matches!(stale, Fault::Stale(ref w) if w.contains("rebuilt")),
        "{stale:?}"
    );
    assert!(matches!(push.closed(Some((1001, ""))), Fault::Failed(_)));
    assert!(matches!(push.closed(None), Fault::Failed(_)));
    assert_eq!(Push::rejected(3), StreamClient::Evicted(vec![3]));
}
