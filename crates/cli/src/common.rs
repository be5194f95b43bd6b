//! What several commands share: progress bars and remarks on stderr (the experiment layer's
//! [`Feedback`]), and logging.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Duration;

use ferret_lab::Feedback;
use indicatif::{ProgressBar, ProgressStyle};

pub use crate::args::{GridArgs, HouseArgs, ProtocolArgs};
pub use ferret_lab::strategies::check_distinct;

/// Sends `tracing` output to stderr; `-v` raises the level, `RUST_LOG` overrides.
pub fn init_tracing(verbose: u8) {
    let default = match verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    // Colour codes only for a terminal: in a log file or a pipe they are noise.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
}

/// A progress bar in ferret's style (hidden when stderr is not a terminal).
pub fn progress(len: usize, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {msg:<14} [{bar:40}] {pos}/{len} ({elapsed}, eta {eta})",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}

/// Progress bars in ferret's style and remarks on stderr: what the experiment layer reports.
#[derive(Default)]
pub struct Bars {
    bar: Mutex<Option<ProgressBar>>,
}

impl Bars {
    fn with(&self, f: impl FnOnce(&ProgressBar)) {
        let bar = self.bar.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(b) = bar.as_ref() {
            f(b);
        }
    }
}

impl Feedback for Bars {
    fn begin(&self, what: &str, len: usize) {
        let mut bar = self.bar.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(old) = bar.take() {
            old.finish_and_clear();
        }
        *bar = Some(progress(len, what));
    }

    fn set_len(&self, len: usize) {
        self.with(|b| b.set_length(len as u64));
    }

    fn set_done(&self, done: usize) {
        self.with(|b| b.set_position(done as u64));
    }

    fn tick(&self) {
        self.with(|b| b.inc(1));
    }

    fn end(&self) {
        let mut bar = self.bar.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(b) = bar.take() {
            b.finish_and_clear();
        }
    }

    fn note(&self, message: &str) {
        let bar = self.bar.lock().unwrap_or_else(|p| p.into_inner());
        match bar.as_ref() {
            Some(b) => b.suspend(|| eprintln!("{message}")),
            None => eprintln!("{message}"),
        }
    }
}
