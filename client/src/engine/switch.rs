//! Which transport carries the segments, without IO: server push over one `/v1/stream`
//! session when it is open, HTTP pull otherwise. The front end asks [`Switch::carrier`] each
//! frame and says what happened to its sessions; the switch says when to open one.
//!
//! - The first session holds pull back for [`OPEN_WAIT`] at most (a cold start would read
//!   everything twice otherwise); a later one opens while pull reads on.
//! - A try that does not open within [`OPEN_TIMEOUT`], or fails, or a session that ends, hands
//!   over to pull, and the next try waits for [`Reopen`]'s back-off.
//! - A session refused because the server serves another database now stops everything (the
//!   client must read the manifest again).

use super::reopen::{OPEN_TIMEOUT, OPEN_WAIT, Reopen};
use web_time::Instant;

/// Who carries the segments now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Carrier {
    /// The push session.
    Push,
    /// HTTP pull.
    Pull,
    /// Nobody yet: the first session is opening (pull waits for it a moment).
    Waiting,
    /// Nobody: the database is stale.
    Stopped,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum State {
    /// No session; the next try not before this (`None`: at once).
    Idle(Option<Instant>),
    /// A session is opening since then.
    Opening(Instant),
    /// A session is open since then.
    Open(Instant),
    /// Pull only, or stale.
    Off,
}

/// The push/pull choice (see the module).
#[derive(Debug, Clone)]
pub struct Switch {
    state: State,
    stale: bool,
    backoff: Reopen,
    /// Sessions tried so far.
    tries: u64,
}

impl Switch {
    /// A switch that pushes (`push`), or pulls only.
    pub fn new(push: bool) -> Switch {
        Switch {
            state: if push { State::Idle(None) } else { State::Off },
            stale: false,
            backoff: Reopen::default(),
            tries: 0,
        }
    }

    /// Sessions tried so far.
    pub fn tries(&self) -> u64 {
        self.tries
    }

    /// Whether to start opening a session at `now`; when it says so, it counts as opening.
    pub fn open_now(&mut self, now: Instant) -> bool {
        match self.state {
            State::Idle(at) if at.is_none_or(|t| now >= t) => {
                self.state = State::Opening(now);
                self.tries += 1;
                true
            }
            _ => false,
        }
    }

    /// The session opened.
    pub fn opened(&mut self, now: Instant) {
        if matches!(self.state, State::Opening(_)) {
            self.state = State::Open(now);
        }
    }

    /// The session being opened did not open, or the open one ended (not stale): pull carries
    /// on, and the next try waits for the back-off.
    pub fn failed(&mut self, now: Instant) {
        match self.state {
            State::Open(since) => self.backoff.ended(now.saturating_duration_since(since)),
            State::Opening(_) => {}
            State::Idle(_) | State::Off => return,
        }
        self.state = State::Idle(Some(now + self.backoff.next_try()));
    }

    /// The server serves another database now: nothing carries on.
    pub fn stale(&mut self) {
        self.stale = true;
        self.state = State::Off;
    }

    /// When the next session is due (after the back-off; `now` if at once), if none is open
    /// or opening and sessions are wanted at all.
    pub fn next_try(&self, now: Instant) -> Option<Instant> {
        match self.state {
            State::Idle(at) if !self.stale => Some(at.unwrap_or(now)),
            _ => None,
        }
    }

    /// Whether the session being opened has taken too long ([`OPEN_TIMEOUT`]): the front end
    /// gives it up and says [`Switch::failed`].
    pub fn timed_out(&self, now: Instant) -> bool {
        matches!(self.state, State::Opening(since) if now.saturating_duration_since(since) >= OPEN_TIMEOUT)
    }

    /// Who carries the segments at `now`.
    pub fn carrier(&self, now: Instant) -> Carrier {
        match self.state {
            _ if self.stale => Carrier::Stopped,
            State::Open(_) => Carrier::Push,
            State::Opening(since)
                if self.tries == 1 && now.saturating_duration_since(since) < OPEN_WAIT =>
            {
                Carrier::Waiting
            }
            _ => Carrier::Pull,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::reopen::{REOPEN_FIRST, REOPEN_MAX};
    use std::time::Duration;

    fn s(t: Instant, secs: f64) -> Instant {
        t + Duration::from_secs_f64(secs)
    }

    #[test]
    fn a_cold_start_waits_a_moment_for_the_stream_then_pulls() {
        let t = Instant::now();
        let mut sw = Switch::new(true);
        assert!(sw.open_now(t));
        assert!(!sw.open_now(t), "one try at a time");
        assert_eq!(sw.carrier(s(t, 0.5)), Carrier::Waiting);
        assert_eq!(
            sw.carrier(t + OPEN_WAIT),
            Carrier::Pull,
            "no longer than OPEN_WAIT"
        );
        sw.opened(s(t, 3.0));
        assert_eq!(
            sw.carrier(s(t, 3.0)),
            Carrier::Push,
            "a late session still takes over"
        );
    }

    #[test]
    fn a_session_that_ends_hands_over_to_pull_and_is_tried_again_with_back_off() {
        let t = Instant::now();
        let mut sw = Switch::new(true);
        sw.open_now(t);
        sw.opened(t);
        sw.failed(s(t, 2.0));
        assert_eq!(sw.carrier(s(t, 2.0)), Carrier::Pull);
        assert!(!sw.open_now(s(t, 2.5)), "the back-off");
        assert_eq!(sw.next_try(s(t, 2.5)), Some(s(t, 2.0) + REOPEN_FIRST));
        assert!(sw.open_now(s(t, 2.0) + REOPEN_FIRST));
        // A later try opening: pull reads on meanwhile.
        assert_eq!(sw.carrier(s(t, 3.1)), Carrier::Pull);
        assert!(!sw.timed_out(s(t, 3.1)));
        assert!(sw.timed_out(s(t, 3.0) + OPEN_TIMEOUT));
        sw.failed(s(t, 3.0) + OPEN_TIMEOUT);
        let mut waits = Vec::new();
        let mut now = s(t, 3.0) + OPEN_TIMEOUT;
        for _ in 0..8 {
            let from = now;
            while !sw.open_now(now) {
                now += Duration::from_millis(100);
            }
            waits.push((now - from).as_secs_f64().round() as u64);
            sw.failed(now);
        }
        assert_eq!(waits, vec![2, 4, 8, 16, 30, 30, 30, 30]);
        assert_eq!(*waits.last().unwrap(), REOPEN_MAX.as_secs());
        assert_eq!(sw.tries(), 10);
    }

    #[test]
    fn pull_only_never_opens_and_a_stale_database_stops_everything() {
        let t = Instant::now();
        let mut pull = Switch::new(false);
        assert!(!pull.open_now(t));
        assert_eq!(pull.next_try(t), None, "pull only tries nothing");
        assert_eq!(pull.carrier(t), Carrier::Pull);
        let mut sw = Switch::new(true);
        sw.open_now(t);
        sw.stale();
        assert_eq!(sw.carrier(t), Carrier::Stopped);
        assert!(!sw.open_now(s(t, 100.0)));
    }
}
