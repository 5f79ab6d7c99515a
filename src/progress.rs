//! Progress bars (indicatif) for long library steps, drawn on stderr and hidden when stderr is
//! not a terminal.

use indicatif::{ProgressBar, ProgressStyle};
use std::sync::Mutex;

/// A progress bar that follows the stages a library reports through `portico_data::build::Observer`.
pub struct Bars {
    bar: Mutex<Option<ProgressBar>>,
}

impl Bars {
    /// No bar yet; one appears with the first stage.
    pub fn new() -> Self {
        Bars {
            bar: Mutex::new(None),
        }
    }

    /// Starts a new bar (finishing the previous one).
    pub fn start(&self, name: &str, total: u64) {
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template(
                "{prefix:>10} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        bar.set_prefix(name.to_string());
        if let Ok(mut slot) = self.bar.lock()
            && let Some(old) = slot.replace(bar)
        {
            old.finish();
        }
    }

    /// Advances the current bar.
    pub fn inc(&self, n: u64) {
        if let Ok(slot) = self.bar.lock()
            && let Some(b) = slot.as_ref()
        {
            b.inc(n);
        }
    }

    /// Finishes the current bar.
    pub fn finish(&self) {
        if let Ok(mut slot) = self.bar.lock()
            && let Some(b) = slot.take()
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
