//! A write timeout on a connection: a socket whose writes make no progress for the timeout
//! fails with `TimedOut`, and hyper closes the connection. Without it an answer to a client that
//! never reads (a batch, a viewer file, a stream session's frame) holds its connection, and
//! the descriptor the connection cap counts, for ever.
//!
//! The connection's [`Stall`] says since when its writes have been stuck, so that at the cap the
//! accept loop can close the connection stuck longest to make room ([`crate::listen`]).

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::task::{Context, Poll, ready};
use std::time::{Duration, Instant};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::time::Sleep;

/// Since when a connection's writes have been stuck (shared with the accept loop).
#[derive(Debug, Default, Clone)]
pub struct Stall(Arc<AtomicU64>);

impl Stall {
    /// How long the writes have been stuck now (`None`: they are not).
    pub fn stuck_for(&self, epoch: Instant) -> Option<Duration> {
        match self.0.load(Relaxed) {
            0 => None,
            since => {
                let since = Duration::from_micros(since);
                Some(epoch.elapsed().saturating_sub(since))
            }
        }
    }

    fn set(&self, epoch: Instant) {
        let _ = self.0.compare_exchange(
            0,
            (epoch.elapsed().as_micros() as u64).max(1),
            Relaxed,
            Relaxed,
        );
    }

    fn clear(&self) {
        self.0.store(0, Relaxed);
    }
}

/// `io` whose writes fail after `timeout` without progress.
pub struct Timed<I> {
    io: I,
    timeout: Duration,
    /// Armed while a write makes no progress (boxed: the connection's IO must be `Unpin` for
    /// hyper's upgrades).
    timer: Option<Pin<Box<Sleep>>>,
    stall: Stall,
    epoch: Instant,
    /// Counts the connections timed out (`portico_write_timeouts_total`).
    metrics: Option<Arc<crate::metrics::Metrics>>,
}

impl<I> Timed<I> {
    /// Wraps `io`; `stall` is set while its writes are stuck (times counted from `epoch`).
    pub fn new(io: I, timeout: Duration, stall: Stall, epoch: Instant) -> Timed<I> {
        Timed {
            io,
            timeout,
            timer: None,
            stall,
            epoch,
            metrics: None,
        }
    }

    /// Counts each time-out in `metrics`.
    pub fn counting(mut self, metrics: Arc<crate::metrics::Metrics>) -> Timed<I> {
        self.metrics = Some(metrics);
        self
    }
}

impl<I: AsyncWrite + Unpin> Timed<I> {
    /// Runs one write-side poll: progress (`progressed` says what is) disarms the timer; a
    /// poll that cannot go on arms it, and its firing is the `TimedOut` error.
    fn guard<T>(
        &mut self,
        cx: &mut Context<'_>,
        progressed: impl Fn(&io::Result<T>) -> bool,
        op: impl FnOnce(Pin<&mut I>, &mut Context<'_>) -> Poll<io::Result<T>>,
    ) -> Poll<io::Result<T>> {
        match op(Pin::new(&mut self.io), cx) {
            Poll::Ready(r) => {
                if progressed(&r) {
                    self.timer = None;
                    self.stall.clear();
                }
                Poll::Ready(r)
            }
            Poll::Pending => {
                let (timeout, stall, epoch) = (self.timeout, &self.stall, self.epoch);
                let timer = self.timer.get_or_insert_with(|| {
                    stall.set(epoch);
                    Box::pin(tokio::time::sleep(timeout))
                });
                ready!(timer.as_mut().poll(cx));
                // Counted once, however often the stuck write is polled again.
                if let Some(m) = self.metrics.take() {
                    m.write_timeouts.fetch_add(1, Relaxed);
                }
                Poll::Ready(Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    "the client took nothing for the write timeout",
                )))
            }
        }
    }
}

/// Whether a write made progress: bytes taken, or an error (the connection ends anyway). A
/// flush or shutdown that completes is no progress of the bytes: on a socket it is a no-op.
fn wrote(r: &io::Result<usize>) -> bool {
    !matches!(r, Ok(0))
}

impl<I: AsyncRead + Unpin> AsyncRead for Timed<I> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_read(cx, buf)
    }
}

impl<I: AsyncWrite + Unpin> AsyncWrite for Timed<I> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        self.guard(cx, wrote, |io, cx| io.poll_write(cx, buf))
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        self.guard(cx, wrote, |io, cx| io.poll_write_vectored(cx, bufs))
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        self.guard(cx, |_| false, |io, cx| io.poll_flush(cx))
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        self.guard(cx, |_| false, |io, cx| io.poll_shutdown(cx))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::AsyncWriteExt;

    #[tokio::test]
    async fn a_write_nobody_reads_fails_after_the_timeout_and_says_since_when() {
        // A pipe with a 1 KB buffer that nobody reads.
        let (a, _b) = tokio::io::duplex(1024);
        let stall = Stall::default();
        let epoch = Instant::now();
        let mut w = Timed::new(a, Duration::from_millis(100), stall.clone(), epoch);
        let t0 = Instant::now();
        let big = vec![7u8; 64 << 10];
        let e = w.write_all(&big).await.unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::TimedOut);
        let took = t0.elapsed();
        assert!(
            took >= Duration::from_millis(100) && took < Duration::from_secs(2),
            "{took:?}"
        );
        assert!(
            stall
                .stuck_for(epoch)
                .is_some_and(|d| d >= Duration::from_millis(90))
        );
    }

    #[tokio::test]
    async fn a_slow_reader_that_keeps_reading_is_not_timed_out() {
        let (a, mut b) = tokio::io::duplex(1024);
        let stall = Stall::default();
        let epoch = Instant::now();
        // A generous timeout: the reader takes 512 bytes every 20 ms, far more often.
        let mut w = Timed::new(a, Duration::from_secs(1), stall.clone(), epoch);
        let reader = tokio::spawn(async move {
            use tokio::io::AsyncReadExt;
            let mut buf = [0u8; 512];
            let mut n = 0;
            while n < 16 << 10 {
                tokio::time::sleep(Duration::from_millis(20)).await;
                n += b.read(&mut buf).await.unwrap();
            }
        });
        // 16 KB at 512 B per 20 ms: 0.6 s in all, never long without progress.
        w.write_all(&vec![1u8; 16 << 10]).await.unwrap();
        reader.await.unwrap();
        assert_eq!(stall.stuck_for(epoch), None);
    }
}
