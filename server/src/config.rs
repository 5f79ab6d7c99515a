//! Server limits and options (`portico serve` flags map one to one onto these fields).

use std::time::Duration;

/// What a server instance allows and requires.
#[derive(Debug, Clone)]
pub struct Config {
    /// Bearer token every `/v1/*` request must carry in `Authorization: Bearer …` (a WebSocket
    /// upgrade of `/v1/stream` may give it as `?token=`, which browsers need). `None` = no auth.
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
    /// A connection whose client takes no bytes of an answer (a stream session: of one
    /// message) for this long is closed: a client that never reads cannot keep its slot.
    pub write_timeout: Duration,
    /// Deadline of one prefetch computation, waiting for a compute slot included.
    pub compute_deadline: Duration,
    /// Prefetch computations at once (default: one per core).
    pub compute_slots: usize,
    /// Most open connections (default: below the process's file-descriptor limit); more are
    /// answered 503 and closed.
    pub max_connections: usize,
    /// Time a client has to send a request's headers (and an idle keep-alive connection to
    /// start its next request) before the connection is closed.
    pub header_timeout: Duration,
    /// Stream sessions and `/v1/prefetch` share one need list per place (eye cell and
    /// direction bucket; under the predicted lookahead also the eye's metre and the velocity's
    /// and turn's buckets) and a session recomputes only when its observer leaves its place
    /// (`portico_data::prefetch::shared`); off, every observer gets its own list, computed for
    /// it (exact; the baseline of the stress figures).
    pub shared_answers: bool,
    /// With `shared_answers`, the share of the compute slots observers' own answers may take:
    /// while answering every observer with its own would fit, each gets its own; past it,
    /// answers are shared (`crate::answers`): a few clients get their own, a crowd shares.
    /// 0: always shared.
    pub exact_share: f64,
    /// Memory for the shared need lists (bytes; least recently used dropped first).
    pub shared_cache_bytes: usize,
    /// How long requests in flight may finish after a stop or reload before their connections
    /// are closed.
    pub drain: Duration,
    /// The folder of the built browser viewer (`web/build.sh`: `index.html`, `portico_web.js`,
    /// `portico_web_bg.wasm`), served at `/`; `None`: `/` says how to build it.
    pub viewer: Option<std::path::PathBuf>,
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
            write_timeout: Duration::from_secs(10),
            compute_deadline: Duration::from_millis(250),
            compute_slots: std::thread::available_parallelism().map_or(2, |n| n.get()),
            max_connections: crate::listen::default_max_connections(),
            header_timeout: Duration::from_secs(10),
            drain: Duration::from_secs(10),
            shared_answers: true,
            exact_share: 0.3,
            shared_cache_bytes: portico_data::prefetch::shared::DEFAULT_CACHE_BYTES,
            viewer: None,
        }
    }
}
