//! Which prefetch answer an observer gets: its own, computed for it, while the server could
//! answer every observer that way within a share of its compute slots, and the shared need
//! list of its place (`portico_data::prefetch::shared`) once it could not.
//!
//! A shared list holds the answer of every observer of its place, so it is conservative like
//! an observer's own, only wider: under the predicted lookahead a place's list is about twice
//! the bytes of one observer's answer (`data/tests/shared_predicted.rs`), and a client served
//! from it reads more that it never draws (on flattened `mega`, 8 clients at 50 ms / 10 Mbit/s
//! read 0.21 MB each from their own answers and 0.47 MB from shared ones). A few clients cost
//! little to answer one by one (16 walkers ask 320 answers a second, on flattened `mega` about
//! 0.2 to 0.4 of a core: the default share, 0.3 of the slots, holds them with room to spare;
//! at a tenth, the load tester's 8 pull and 8 push clients were shared in some runs and not in
//! others); a crowd cannot be (1,000 ask 20,000) but shares places, and a place's list is
//! computed once.
//!
//! The decision is the same for every observer at a time, so a server does not answer some
//! of a crowd exactly and queue the rest behind them: answers asked per second (the larger of
//! the last one-second window's rate and the current window's so far, the latter over at least
//! a tenth of a second) times the mean time of an own answer against the share. The tenth of
//! a second bounds what a crowd arriving at once is answered one by one: the share of the
//! slots for a tenth of a second, not for a whole window (on a cold server, 1,000 clients
//! arriving in one frame were 200 own answers queued ahead of everyone). The clock is passed
//! in.

use std::sync::Mutex;
use std::time::{Duration, Instant};

/// How long one window of the rate lasts.
const WINDOW: Duration = Duration::from_secs(1);

/// The shortest span the current window's rate is taken over (a burst at its start counts
/// at this rate, not at the whole window's).
const MIN_SPAN: Duration = Duration::from_millis(100);

/// The mean own answer's time assumed before one is measured (seconds).
const FIRST_COST_S: f64 = 1e-3;

/// Decides between own and shared answers (see the module).
#[derive(Debug)]
pub struct ExactBudget {
    /// Seconds of own answers allowed per second.
    allowed: f64,
    state: Mutex<Rate>,
}

#[derive(Debug)]
struct Rate {
    /// The current window's start.
    start: Instant,
    /// Answers asked in the current window and in the one before.
    asked: u64,
    asked_before: u64,
    /// Mean seconds of an own answer (a moving average).
    cost: f64,
}

impl ExactBudget {
    /// Own answers may take `share` of `slots` compute slots (0: every answer is shared).
    pub fn new(share: f64, slots: usize, now: Instant) -> ExactBudget {
        let share = if share.is_finite() {
            share.max(0.0)
        } else {
            0.0
        };
        ExactBudget {
            allowed: share * slots.max(1) as f64,
            state: Mutex::new(Rate {
                start: now,
                asked: 0,
                asked_before: 0,
                cost: FIRST_COST_S,
            }),
        }
    }

    /// Counts one answer asked for at `now`, and says whether it is the observer's own.
    pub fn own_answer(&self, now: Instant) -> bool {
        if self.allowed <= 0.0 {
            return false;
        }
        let mut r = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let mut since = now.saturating_duration_since(r.start);
        if since >= WINDOW {
            r.asked_before = if since < 2 * WINDOW { r.asked } else { 0 };
            r.asked = 0;
            r.start = now;
            since = Duration::ZERO;
        }
        r.asked += 1;
        let span = since.max(MIN_SPAN).as_secs_f64();
        let per_s = (r.asked as f64 / span).max(r.asked_before as f64 / WINDOW.as_secs_f64());
        per_s * r.cost <= self.allowed
    }

    /// Counts an own answer that took `seconds`.
    pub fn charge(&self, seconds: f64) {
        if seconds.is_finite() && seconds >= 0.0 {
            let mut r = self.state.lock().unwrap_or_else(|e| e.into_inner());
            r.cost = 0.9 * r.cost + 0.1 * seconds;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_few_observers_get_their_own_answers_and_a_crowd_shares() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        // A tenth of two slots, own answers of 0.5 ms: up to 400 a second.
        let b = ExactBudget::new(0.1, 2, t0);
        for _ in 0..50 {
            b.charge(0.5e-3);
        }
        // 8 clients at 20 answers a second: their own.
        let mut own = 0;
        for i in 0..160 {
            own += usize::from(b.own_answer(at(i * 1000 / 160)));
        }
        assert_eq!(own, 160);
        // 1,000 clients at 20 a second: shared once the rate passes 400 a second, over a
        // tenth of a second at least: after 40 of them (the measured cost is a moving average,
        // a little above 0.5 ms yet: 39).
        let second: Vec<bool> = (0..20_000)
            .map(|i| b.own_answer(at(1000 + i / 20)))
            .collect();
        assert!(second[..39].iter().all(|&o| o));
        assert!(second[39..].iter().all(|&o| !o));
        assert!(!b.own_answer(at(2000)), "the window before was a crowd's");
        // The crowd gone for a while: own answers again.
        assert!(b.own_answer(at(5000)));
        // No share: always shared.
        let none = ExactBudget::new(0.0, 2, t0);
        assert!(!none.own_answer(at(0)));
        assert!(!ExactBudget::new(f64::NAN, 2, t0).own_answer(at(0)));
    }

    #[test]
    fn a_crowd_arriving_at_once_on_a_cold_server_is_shared_almost_at_once() {
        let t0 = Instant::now();
        // A fresh budget (1 ms assumed per own answer) at the default share: 0.6 s of own
        // answers a second, so 60 in the first tenth of a second, and a crowd of 1,000 in
        // 50 ms gets no more.
        let b = ExactBudget::new(0.3, 2, t0);
        let own = (0..1000)
            .filter(|&i| b.own_answer(t0 + Duration::from_micros(i * 50)))
            .count();
        assert_eq!(own, 60);
    }

    #[test]
    fn the_cost_follows_the_own_answers_measured() {
        let t0 = Instant::now();
        let b = ExactBudget::new(0.1, 2, t0);
        // Slow answers (20 ms): 10 a second fit, so 4 a second are all own answers...
        for _ in 0..100 {
            b.charge(0.02);
        }
        let own = (0..8)
            .filter(|&i| b.own_answer(t0 + Duration::from_millis(i * 250)))
            .count();
        assert_eq!(own, 8);
        // ...and 20 a second are shared past the first (one in a tenth of a second fits).
        let busy: Vec<bool> = (0..20)
            .map(|i| b.own_answer(t0 + Duration::from_millis(3000 + i * 50)))
            .collect();
        assert_eq!(busy.iter().filter(|&&o| o).count(), 1, "{busy:?}");
        assert!(busy[0]);
        // Nonsense times are not counted: still 20 ms an answer (4 a second fit).
        b.charge(f64::NAN);
        b.charge(-1.0);
        let later = (0..8)
            .filter(|&i| b.own_answer(t0 + Duration::from_millis(6000 + i * 250)))
            .count();
        assert_eq!(later, 8);
    }
}
