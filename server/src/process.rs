//! The server process's own CPU time and memory, and the shared-answer cache's counters, for
//! `/metrics` (the standard `process_*` names, so a load tester in another process can measure
//! what the server alone spends per answer and per session): CPU from `getrusage`, memory
//! from Linux's `/proc/self/status`; where either is missing its line is left out.

use portico_data::prefetch::shared::SharedAnswers;
use portico_data::prefetch::sight::RegionSight;
use std::fmt::Write;
use std::sync::atomic::Ordering::Relaxed;

/// User plus system CPU seconds this process has used (`getrusage`, microsecond resolution).
#[cfg(unix)]
#[allow(unsafe_code)] // libc's getrusage: see the SAFETY notes.
pub fn cpu_seconds() -> Option<f64> {
    // SAFETY: an all-zero rusage is a valid value of this plain C struct.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage only writes the struct we pass, which lives for the whole call.
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return None;
    }
    let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    Some(s(u.ru_utime) + s(u.ru_stime))
}

/// Not measured off Unix.
#[cfg(not(unix))]
pub fn cpu_seconds() -> Option<f64> {
    None
}

/// Resident memory of this process, bytes.
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Appends the process and shared-cache lines in Prometheus text; `sharing` says whether
/// stream sessions share need lists (`portico serve` without `--exact-answers`).
pub fn render(out: &mut String, shared: &SharedAnswers, sight: &RegionSight, sharing: bool) {
    let mut line = |name: &str, kind: &str, help: &str, v: f64| {
        let _ = writeln!(
            out,
            "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {v}"
        );
    };
    if let Some(s) = cpu_seconds() {
        line(
            "process_cpu_seconds_total",
            "counter",
            "User and system CPU time of the server process, seconds.",
            s,
        );
    }
    if let Some(b) = resident_bytes() {
        line(
            "process_resident_memory_bytes",
            "gauge",
            "Resident memory of the server process, bytes.",
            b as f64,
        );
    }
    line(
        "portico_shared_answers",
        "gauge",
        "1 when stream sessions share need lists, 0 when each observer gets its own.",
        f64::from(u8::from(sharing)),
    );
    let (lists, bytes) = shared.usage();
    line(
        "portico_shared_hits_total",
        "counter",
        "Need lists served from the shared cache.",
        shared.hits.load(Relaxed) as f64,
    );
    line(
        "portico_shared_misses_total",
        "counter",
        "Need lists computed for the shared cache.",
        shared.misses.load(Relaxed) as f64,
    );
    line(
        "portico_shared_lists",
        "gauge",
        "Need lists in the shared cache.",
        lists as f64,
    );
    line(
        "portico_shared_bytes",
        "gauge",
        "Bytes of need lists in the shared cache.",
        bytes as f64,
    );
    line(
        "portico_region_sight_hits_total",
        "counter",
        "What a cell's part of a swept region may see, taken from the cache.",
        sight.hits.load(Relaxed) as f64,
    );
    line(
        "portico_region_sight_misses_total",
        "counter",
        "What a cell's part of a swept region may see, searched.",
        sight.misses.load(Relaxed) as f64,
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_process_reads_its_own_cpu_time_and_memory() {
        let before = cpu_seconds().expect("getrusage");
        // Burn CPU until the clock shows 20 ms of it (a loaded machine only makes this slower).
        let t = std::time::Instant::now();
        let mut x = 0u64;
        while cpu_seconds().unwrap() - before < 0.02 {
            for _ in 0..10_000 {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
            }
            assert!(t.elapsed().as_secs() < 30, "the CPU clock does not advance");
        }
        std::hint::black_box(x);
        let rss = resident_bytes().unwrap();
        assert!((1 << 20..1 << 36).contains(&rss), "{rss}");
        let mut s = String::new();
        render(
            &mut s,
            &SharedAnswers::new(1 << 20),
            &RegionSight::default(),
            true,
        );
        assert!(s.contains("process_cpu_seconds_total "));
        assert!(s.contains("portico_shared_misses_total 0"));
        assert!(s.contains("portico_shared_answers 1\n"));
        assert!(s.contains("portico_region_sight_misses_total 0\n"));
    }
}
