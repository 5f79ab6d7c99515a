//! Server CPU during a policy's run, measured one of two ways (the report says which):
//!
//! - **in-process** (the server listens on a socket this process holds, as in `portico demo`
//!   and the tests): `/proc/self/stat` utime+stime of the whole process minus that of the load
//!   tester's own threads (named `portico-lt`), in clock ticks of 1/100 s (Linux USER_HZ);
//! - **metrics**: otherwise, the delta of the server's own `process_cpu_seconds_total` on
//!   `/metrics` (its CPU time, whatever it spent it on); a server too old to report it gives
//!   `portico_request_seconds_sum` over the data routes instead — seconds spent inside request
//!   handlers (wall time, an upper bound on their CPU time on an idle server).

use std::collections::HashSet;

/// Linux's USER_HZ: `/proc` reports CPU times in 1/100 s on every mainstream configuration.
const TICKS_PER_S: f64 = 100.0;
/// Name prefix of the load tester's runtime threads (kernel thread names stop at 15 bytes).
pub const THREAD_NAME: &str = "portico-lt";
/// Routes whose handler time counts as server work.
const ROUTES: [&str; 5] = ["prefetch", "segment", "batch", "manifest", "cells"];

/// How server CPU is measured.
#[derive(Debug, Clone)]
pub struct Probe {
    in_process: bool,
    metrics_url: String,
    token: Option<String>,
    http: reqwest::Client,
}

/// One reading.
#[derive(Debug, Clone, Copy, Default)]
pub struct Sample {
    process_s: Option<f64>,
    own_s: Option<f64>,
    handler_s: Option<f64>,
    remote_cpu_s: Option<f64>,
}

/// Server CPU between two readings.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Usage {
    /// CPU seconds (in-process) or handler seconds (metrics); `None` when neither was readable.
    pub server_s: Option<f64>,
    /// Handler seconds from `/metrics`, whatever the source of `server_s`.
    pub handler_s: Option<f64>,
}

impl Probe {
    /// A probe for the server at `base`.
    pub fn new(base: &str, token: Option<String>) -> Probe {
        Probe {
            in_process: listens_here(base),
            metrics_url: format!("{}/metrics", base.trim_end_matches('/')),
            token,
            http: reqwest::Client::new(),
        }
    }

    /// Where `server_s` comes from, for the report.
    pub fn source(&self) -> &'static str {
        if self.in_process {
            "in-process: /proc/self/stat utime+stime minus the load tester's own threads (CPU s)"
        } else {
            "remote: /metrics process_cpu_seconds_total delta (the server's CPU s; from a server \
             without it, portico_request_seconds_sum over data routes: handler wall s)"
        }
    }

    /// Reads the counters now.
    pub async fn sample(&self) -> Sample {
        let page = self.page().await;
        Sample {
            process_s: self.in_process.then(process_cpu_s).flatten(),
            own_s: self.in_process.then(own_threads_cpu_s).flatten(),
            handler_s: page.as_deref().and_then(handler_seconds),
            remote_cpu_s: page
                .as_deref()
                .and_then(|t| metric(t, "process_cpu_seconds_total")),
        }
    }

    /// Usage between two samples.
    pub fn usage(&self, before: Sample, after: Sample) -> Usage {
        let delta = |a: Option<f64>, b: Option<f64>| Some((b? - a?).max(0.0));
        let handler_s = delta(before.handler_s, after.handler_s);
        let server_s = if self.in_process {
            delta(before.process_s, after.process_s)
                .zip(delta(before.own_s, after.own_s))
                .map(|(all, own)| (all - own).max(0.0))
        } else {
            delta(before.remote_cpu_s, after.remote_cpu_s).or(handler_s)
        };
        Usage {
            server_s,
            handler_s,
        }
    }

    async fn page(&self) -> Option<String> {
        let mut req = self.http.get(&self.metrics_url);
        if let Some(t) = &self.token {
            req = req.bearer_auth(t);
        }
        req.send().await.ok()?.text().await.ok()
    }
}

/// Sum of `portico_request_seconds_sum` over the data routes in a Prometheus text page.
pub fn handler_seconds(text: &str) -> Option<f64> {
    let mut found = false;
    let mut sum = 0.0;
    for line in text.lines() {
        let Some(rest) = line.strip_prefix("portico_request_seconds_sum{route=\"") else {
            continue;
        };
        let Some((route, value)) = rest.split_once("\"}") else {
            continue;
        };
        if ROUTES.contains(&route)
            && let Ok(v) = value.trim().parse::<f64>()
        {
            sum += v;
            found = true;
        }
    }
    found.then_some(sum)
}

/// The value of an unlabelled metric in a Prometheus text page.
pub fn metric(text: &str, name: &str) -> Option<f64> {
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
        .and_then(|v| v.trim().parse().ok())
}

/// utime+stime (seconds) from the text of a `/proc/.../stat` file.
pub fn stat_cpu_s(stat: &str) -> Option<f64> {
    // The command name may hold spaces and parentheses: fields start after the last ')'.
    let rest = &stat[stat.rfind(')')? + 1..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    Some((utime + stime) / TICKS_PER_S)
}

fn process_cpu_s() -> Option<f64> {
    stat_cpu_s(&std::fs::read_to_string("/proc/self/stat").ok()?)
}

/// CPU of this process's threads named [`THREAD_NAME`]….
fn own_threads_cpu_s() -> Option<f64> {
    let mut sum = 0.0;
    for e in std::fs::read_dir("/proc/self/task").ok()?.flatten() {
        let comm = std::fs::read_to_string(e.path().join("comm")).unwrap_or_default();
        if comm.starts_with(THREAD_NAME)
            && let Ok(stat) = std::fs::read_to_string(e.path().join("stat"))
        {
            sum += stat_cpu_s(&stat).unwrap_or(0.0);
        }
    }
    Some(sum)
}

/// Whether a socket listening on the URL's port is open in this process (Linux `/proc`).
fn listens_here(base: &str) -> bool {
    let Some(port) = reqwest::Url::parse(base)
        .ok()
        .and_then(|u| u.port_or_known_default())
    else {
        return false;
    };
    let inodes: HashSet<String> = ["/proc/self/net/tcp", "/proc/self/net/tcp6"]
        .iter()
        .filter_map(|p| std::fs::read_to_string(p).ok())
        .flat_map(|t| listening_inodes(&t, port))
        .collect();
    if inodes.is_empty() {
        return false;
    }
    let Ok(fds) = std::fs::read_dir("/proc/self/fd") else {
        return false;
    };
    fds.flatten().any(|fd| {
        std::fs::read_link(fd.path()).is_ok_and(|l| {
            let l = l.to_string_lossy();
            l.strip_prefix("socket:[")
                .and_then(|r| r.strip_suffix(']'))
                .is_some_and(|i| inodes.contains(i))
        })
    })
}

/// Inodes of the listening sockets on `port` in a `/proc/net/tcp` table.
pub fn listening_inodes(table: &str, port: u16) -> Vec<String> {
    table
        .lines()
        .skip(1)
        .filter_map(|line| {
            let f: Vec<&str> = line.split_whitespace().collect();
            let local_port = f.get(1)?.rsplit_once(':')?.1;
            let listening = *f.get(3)? == "0A";
            let same = u16::from_str_radix(local_port, 16).ok()? == port;
            (listening && same).then(|| f.get(9).map(|s| s.to_string()))?
        })
        .collect()
}

/// This machine's name.
pub fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|_| "unknown".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_stat_and_metrics_parse() {
        let stat = "1234 (tokio (x) w) S 1 2 3 4 5 6 7 8 9 10 250 150 0 0 20 0";
        assert_eq!(stat_cpu_s(stat), Some(4.0));
        assert_eq!(stat_cpu_s("garbage"), None);
        let text = "portico_request_seconds_sum{route=\"prefetch\"} 1.5\n\
                    portico_request_seconds_sum{route=\"metrics\"} 9\n\
                    portico_request_seconds_sum{route=\"segment\"} 0.25\n";
        assert_eq!(handler_seconds(text), Some(1.75));
        assert_eq!(handler_seconds("nothing"), None);
        let page = "process_cpu_seconds_total_x 1\nprocess_cpu_seconds_total 2.5\n";
        assert_eq!(metric(page, "process_cpu_seconds_total"), Some(2.5));
        assert_eq!(metric(page, "missing"), None);
        let table = "  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode\n   0: 0100007F:1F4E 00000000:0000 0A 00000000:00000000 00:00000000 00000000     0        0 4242 1\n   1: 0100007F:1F4E 0100007F:9999 01 00000000:00000000 00:00000000 00000000     0        0 4343 1\n";
        assert_eq!(listening_inodes(table, 8014), vec!["4242".to_string()]);
        assert!(listening_inodes(table, 80).is_empty());
    }

    #[test]
    fn a_listener_in_this_process_is_found() {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let url = format!("http://{}", l.local_addr().unwrap());
        if std::path::Path::new("/proc/self/net/tcp").exists() {
            assert!(listens_here(&url));
        }
        drop(l);
        assert!(!listens_here("http://127.0.0.1:1"));
        assert!(!listens_here("not a url"));
    }

    #[test]
    fn a_remote_servers_own_cpu_time_wins_over_its_handler_time() {
        let probe = Probe::new("http://127.0.0.1:1", None);
        assert!(!probe.in_process);
        let at = |handler: f64, cpu: Option<f64>| Sample {
            handler_s: Some(handler),
            remote_cpu_s: cpu,
            ..Sample::default()
        };
        let u = probe.usage(at(1.0, Some(10.0)), at(3.0, Some(10.5)));
        assert_eq!(u.server_s, Some(0.5));
        assert_eq!(u.handler_s, Some(2.0));
        // A server without process_cpu_seconds_total: handler time, as before.
        assert_eq!(
            probe.usage(at(1.0, None), at(3.0, None)).server_s,
            Some(2.0)
        );
    }
}
