//! Watching a server under attack: `/healthz` polled from a thread of its own, and a stop
//! that must finish in time.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

/// The bound every `/healthz` answer must meet during an attack.
pub const HEALTHZ: Duration = Duration::from_millis(100);

/// Polls `/healthz` on a fresh connection every 20 ms from a thread of its own until `stop`,
/// returning each answer's latency (`None` for an answer that never came or was not 200).
pub fn watch_health(
    addr: String,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<Vec<Option<Duration>>> {
    std::thread::spawn(move || {
        let mut out = Vec::new();
        while !stop.load(std::sync::atomic::Ordering::Relaxed) {
            let t0 = Instant::now();
            let ok = (|| {
                let mut s = std::net::TcpStream::connect(&addr).ok()?;
                s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
                s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
                    .ok()?;
                let mut head = [0u8; 12];
                s.read_exact(&mut head).ok()?;
                head.starts_with(b"HTTP/1.1 200").then_some(())
            })();
            out.push(ok.map(|_| t0.elapsed()));
            std::thread::sleep(Duration::from_millis(20));
        }
        out
    })
}

/// Runs `attack` while watching `/healthz`; asserts every answer came within [`HEALTHZ`].
pub async fn under_attack<F: std::future::Future<Output = ()>>(addr: &str, name: &str, attack: F) {
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let watcher = watch_health(addr.to_string(), stop.clone());
    attack.await;
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let seen = watcher.join().unwrap();
    assert!(seen.len() >= 5, "{name}: only {} health checks", seen.len());
    let worst = seen
        .iter()
        .map(|l| l.unwrap_or(Duration::MAX))
        .max()
        .unwrap();
    let mut ms: Vec<u128> = seen
        .iter()
        .map(|l| l.map_or(u128::MAX, |d| d.as_millis()))
        .collect();
    ms.sort_unstable();
    eprintln!(
        "{name}: {} health checks, p50 {} ms, max {} ms",
        ms.len(),
        ms[ms.len() / 2],
        ms[ms.len() - 1]
    );
    assert!(
        worst <= HEALTHZ,
        "{name}: /healthz took {worst:?} (bound {HEALTHZ:?}): {ms:?}"
    );
}

/// Stops the server and asserts it is gone within 10 s.
pub async fn stops_in_time(mut s: super::Running) {
    let t0 = Instant::now();
    s.stop.take().unwrap().send(()).unwrap();
    tokio::time::timeout(Duration::from_secs(10), s.task)
        .await
        .expect("stopped within 10 s")
        .unwrap()
        .unwrap();
    eprintln!("stopped in {:?}", t0.elapsed());
}
