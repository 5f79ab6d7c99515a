//! CPU-bound work (prefetch answers, request decoding) off the async workers.
//!
//! The async workers only move bytes; a prefetch answer (Funkhouser §5.2's lookahead) is
//! computed on tokio's blocking pool, at most [`Compute::slots`] at a time, with a deadline that
//! the computation itself checks ([`portico_data::prefetch::Budget`]): waiting for a slot counts
//! against it, and when it passes the request gets a 503 and the worker is free again. So a
//! flood of requests slows those requests, never `/healthz` or segment reads. A computation
//! whose asker stops waiting (a client that hung up, a stream session that ended) is cancelled
//! through the same [`Budget`]: no work goes on for nobody.

use crate::error::Error;
use axum::http::StatusCode;
use portico_data::prefetch::Budget;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::time::{Duration, Instant};
use tokio::sync::Semaphore;

/// The compute slots and the deadline of each computation.
#[derive(Debug, Clone)]
pub struct Compute {
    slots: Arc<Semaphore>,
    deadline: Duration,
    count: usize,
}

impl Compute {
    /// `slots` computations at a time (one per core is the right number: more only queue on the
    /// CPU), each stopped after `deadline` counted from when it was asked for.
    pub fn new(slots: usize, deadline: Duration) -> Compute {
        Compute {
            slots: Arc::new(Semaphore::new(slots.max(1))),
            deadline,
            count: slots.max(1),
        }
    }

    /// How many computations run at once.
    pub fn slots(&self) -> usize {
        self.count
    }

    /// The answer to an asker whose deadline passed before its computation was done (503).
    pub fn busy(&self) -> Error {
        Error::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "busy",
            format!(
                "the server could not compute this answer within {} ms; retry",
                self.deadline.as_millis()
            ),
        )
    }

    /// When a computation asked for now must be done.
    pub fn deadline_from_now(&self) -> Instant {
        Instant::now() + self.deadline
    }

    /// Runs `f` on the blocking pool within the deadline; `f` gets the [`Budget`] to check.
    pub async fn run<T, F>(&self, f: F) -> Result<T, Error>
    where
        T: Send + 'static,
        F: FnOnce(Budget) -> Result<T, Error> + Send + 'static,
    {
        self.run_until(self.deadline_from_now(), f).await
    }

    /// [`Compute::run`] with the deadline `until` (an asker that waited for something else
    /// first: `crate::inflight`).
    pub async fn run_until<T, F>(&self, until: Instant, f: F) -> Result<T, Error>
    where
        T: Send + 'static,
        F: FnOnce(Budget) -> Result<T, Error> + Send + 'static,
    {
        let busy = || self.busy();
        let permit =
            match tokio::time::timeout_at(until.into(), self.slots.clone().acquire_owned()).await {
                Ok(Ok(p)) => p,
                _ => return Err(busy()),
            };
        // Dropping this future (the asker is gone) sets the flag; the computation's next
        // budget check stops it.
        let cancel = Cancel(Arc::new(AtomicBool::new(false)));
        let budget = Budget::until(until).cancelled_by(cancel.0.clone());
        let job = tokio::task::spawn_blocking(move || {
            let _slot = permit;
            f(budget)
        });
        match job.await {
            Ok(r) => r,
            Err(e) => {
                tracing::error!("a computation failed: {e}");
                Err(Error::new(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    "internal",
                    "the computation failed (see the server log)",
                ))
            }
        }
    }
}

/// Sets its flag when dropped: the computation's asker stopped waiting.
struct Cancel(Arc<AtomicBool>);

impl Drop for Cancel {
    fn drop(&mut self) {
        self.0.store(true, Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_computation_past_its_deadline_is_stopped_and_frees_its_slot() {
        let c = Compute::new(1, Duration::from_millis(50));
        let t0 = Instant::now();
        let r: Result<(), Error> = c
            .run(|b| {
                loop {
                    b.check().map_err(Error::from)?;
                    std::thread::sleep(Duration::from_millis(1));
                }
            })
            .await;
        assert_eq!(r.unwrap_err().status(), StatusCode::SERVICE_UNAVAILABLE);
        assert!(t0.elapsed() < Duration::from_millis(500));
        // The slot is free again.
        assert_eq!(c.run(|_| Ok(7)).await.unwrap(), 7);
    }

    #[tokio::test]
    async fn a_computation_whose_asker_went_away_is_cancelled() {
        let c = Compute::new(1, Duration::from_secs(60));
        let (tx, rx) = std::sync::mpsc::channel();
        let asked = c.run(move |b| {
            let t0 = Instant::now();
            while b.check().is_ok() && t0.elapsed() < Duration::from_secs(20) {
                std::thread::sleep(Duration::from_millis(1));
            }
            let _ = tx.send(t0.elapsed());
            Ok(())
        });
        // The asker waits 50 ms, then gives up (a client hanging up).
        let _ = tokio::time::timeout(Duration::from_millis(50), asked).await;
        let ran = tokio::task::spawn_blocking(move || rx.recv_timeout(Duration::from_secs(30)))
            .await
            .unwrap()
            .expect("the computation ended");
        assert!(ran < Duration::from_secs(2), "ran {ran:?} for nobody");
        // And its slot is free at once.
        let t0 = Instant::now();
        assert_eq!(c.run(|_| Ok(3)).await.unwrap(), 3);
        assert!(t0.elapsed() < Duration::from_secs(1));
    }

    #[tokio::test]
    async fn waiting_for_a_slot_counts_against_the_deadline() {
        let c = Compute::new(1, Duration::from_millis(100));
        let held = c.clone();
        let long = tokio::spawn(async move {
            held.run(|_| {
                std::thread::sleep(Duration::from_millis(300));
                Ok(())
            })
            .await
        });
        tokio::time::sleep(Duration::from_millis(20)).await;
        let t0 = Instant::now();
        let r = c.run(|_| Ok(())).await;
        assert_eq!(r.unwrap_err().status(), StatusCode::SERVICE_UNAVAILABLE);
        assert!(t0.elapsed() < Duration::from_millis(250));
        let _ = long.await;
    }
}
