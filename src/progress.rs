//! Progress for long library steps, on stderr: an indicatif bar on a terminal; elsewhere (a log,
//! CI, a pipe) one plain line at each quarter, so a long step is never silent.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::sync::Mutex;

/// A progress bar that follows the stages a library reports through `portico_data::build::Observer`.
pub struct Bars {
    state: Mutex<Option<Stage>>,
    terminal: bool,
}

/// The stage in progress.
struct Stage {
    name: String,
    total: u64,
    pos: u64,
    /// The next quarter (1..=4) to report without a terminal.
    next_quarter: u64,
    bar: Option<ProgressBar>,
}

impl Bars {
    /// No bar yet; one appears with the first stage.
    pub fn new() -> Self {
        Bars {
            state: Mutex::new(None),
            terminal: std::io::stderr().is_terminal(),
        }
    }

    /// Starts a new bar (finishing the previous one).
    pub fn start(&self, name: &str, total: u64) {
        let bar = self.terminal.then(|| {
            let bar = ProgressBar::new(total);
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix:>10} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            bar.set_prefix(name.to_string());
            bar
        });
        let stage = Stage {
            name: name.to_string(),
            total,
            pos: 0,
            next_quarter: 1,
            bar,
        };
        if let Ok(mut slot) = self.state.lock()
            && let Some(old) = slot.replace(stage)
            && let Some(b) = old.bar
        {
            b.finish();
        }
    }

    /// Advances the current bar.
    pub fn inc(&self, n: u64) {
        if let Ok(mut slot) = self.state.lock()
            && let Some(s) = slot.as_mut()
        {
            s.pos += n;
            match &s.bar {
                Some(b) => b.inc(n),
                None => {
                    if s.total >= 8 && s.next_quarter < 4 && s.pos * 4 >= s.total * s.next_quarter {
                        eprintln!("{:>10}: {}/{}", s.name, s.pos, s.total);
                        s.next_quarter = (s.pos * 4 / s.total + 1).min(4);
                    }
                }
            }
        }
    }

    /// Finishes the current bar.
    pub fn finish(&self) {
        if let Ok(mut slot) = self.state.lock()
            && let Some(s) = slot.take()
            && let Some(b) = s.bar
        {
            b.finish();
        }
    }
}

impl portico_data::build::Observer for Bars {
    fn stage(&self, name: &str, total: u64) {
        self.start(name, total);
    }
    fn advance(&self, n: u64) {
        self.inc(n);
    }
}
