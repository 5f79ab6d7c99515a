//! Server limits and options (`portico serve` flags map one to one onto these fields).

use std::time::Duration;

/// What a server instance allows and requires.
#[derive(Debug, Clone)]
pub struct Config {
    /// Bearer token every `/v1/*` request must carry (`Authorization: Bearer …`, or `?token=`
    /// for WebSocket clients that cannot set headers). `None` = no auth.
    pub token: Option<String>,
    /// Largest request body accepted (bytes); larger bodies get 413.
    pub max_body_bytes: usize,
    /// Most concurrent `/v1/stream` sessions; more get 503.
    pub max_sessions: usize,
    /// Cap on each stream session's push rate (bytes per second).
    pub max_session_rate: u64,
    /// Most segments in one batched request.
    pub max_batch: usize,
    /// Time limit for one HTTP request (not for stream sessions).
    pub request_timeout: Duration,
    /// A stream session that sends nothing for this long is closed.
    pub idle_timeout: Duration,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            token: None,
            max_body_bytes: 1 << 20,
            max_sessions: 1024,
            max_session_rate: 256 << 20,
            max_batch: 1024,
            request_timeout: Duration::from_secs(30),
            idle_timeout: Duration::from_secs(60),
        }
    }
}
