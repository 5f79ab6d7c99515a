//! When to try a push session again, without IO: after a session ends or does not open, pull
//! reads while sessions are tried again with back-off ([`REOPEN_FIRST`] doubling to
//! [`REOPEN_MAX`]); a session that lasted [`HEALTHY`] starts the back-off afresh. Every front
//! end (the native IO thread, the page) keeps one [`Reopen`].

use std::time::Duration;

/// Longest a session's handshake may take before the try counts as failed.
pub const OPEN_TIMEOUT: Duration = Duration::from_secs(10);

/// How long pull stays idle while a page's session opens (a socket that is not open by then
/// is given up and pull reads).
pub const OPEN_WAIT: Duration = Duration::from_secs(2);

/// The wait before the first try after a session ended or did not open.
pub const REOPEN_FIRST: Duration = Duration::from_secs(1);

/// The longest wait between tries.
pub const REOPEN_MAX: Duration = Duration::from_secs(30);

/// A session that lasted this long was healthy: after it ends, the wait starts again from
/// [`REOPEN_FIRST`].
pub const HEALTHY: Duration = Duration::from_secs(10);

/// The back-off between tries to open a session.
#[derive(Debug, Clone)]
pub struct Reopen {
    wait: Duration,
}

impl Default for Reopen {
    fn default() -> Reopen {
        Reopen { wait: REOPEN_FIRST }
    }
}

impl Reopen {
    /// A session that was open for `lasted` ended: a healthy one starts the back-off afresh.
    pub fn ended(&mut self, lasted: Duration) {
        if lasted >= HEALTHY {
            self.wait = REOPEN_FIRST;
        }
    }

    /// How long to wait before the next try; each call doubles the next wait, up to
    /// [`REOPEN_MAX`].
    pub fn next_try(&mut self) -> Duration {
        let wait = self.wait;
        self.wait = (self.wait * 2).min(REOPEN_MAX);
        wait
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tries_back_off_to_the_limit_and_a_healthy_session_starts_afresh() {
        let mut r = Reopen::default();
        let waits: Vec<u64> = (0..7).map(|_| r.next_try().as_secs()).collect();
        assert_eq!(waits, vec![1, 2, 4, 8, 16, 30, 30]);
        r.ended(HEALTHY / 2);
        assert_eq!(
            r.next_try(),
            REOPEN_MAX,
            "a short session keeps the back-off"
        );
        r.ended(HEALTHY);
        assert_eq!(r.next_try(), REOPEN_FIRST);
    }
}
