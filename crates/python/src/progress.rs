//! Progress of long work on stderr, when asked for: the experiment layer's `Feedback` as lines a
//! terminal, a log or a notebook's console can show (the work runs without the GIL, on Rust
//! threads, so it writes to the process's stderr rather than `sys.stderr`).

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::Instant;

use ferret_lab::Feedback;

/// Prints each step's progress to stderr: redrawn in place on a terminal, and every tenth of
/// the step otherwise.
pub struct Stderr {
    state: Mutex<Step>,
    terminal: bool,
}

#[derive(Default)]
struct Step {
    what: String,
    len: usize,
    done: usize,
    shown: usize,
    started: Option<Instant>,
}

impl Default for Stderr {
    fn default() -> Self {
        Self {
            state: Mutex::new(Step::default()),
            terminal: std::io::stderr().is_terminal(),
        }
    }
}

impl Stderr {
    fn show(&self, s: &mut Step, last: bool) {
        let secs = s.started.map_or(0.0, |t| t.elapsed().as_secs_f64());
        let line = if s.len > 0 {
            format!("{}: {}/{} ({secs:.1} s)", s.what, s.done, s.len)
        } else {
            format!("{}: {} ({secs:.1} s)", s.what, s.done)
        };
        let mut err = std::io::stderr().lock();
        // Progress is a courtesy: a closed stderr must not fail the work.
        let _ = if self.terminal {
            write!(err, "\r{line}\x1b[K{}", if last { "\n" } else { "" })
        } else {
            writeln!(err, "{line}")
        };
        let _ = err.flush();
        s.shown = s.done;
    }

    fn update(&self, f: impl FnOnce(&mut Step)) {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        f(&mut s);
        let tenth = (s.len / 10).max(1);
        if self.terminal || s.done >= s.shown + tenth || (s.len > 0 && s.done == s.len) {
            self.show(&mut s, false);
        }
    }
}

impl Feedback for Stderr {
    fn begin(&self, what: &str, len: usize) {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        *s = Step {
            what: what.to_string(),
            len,
            started: Some(Instant::now()),
            ..Step::default()
        };
        self.show(&mut s, false);
    }

    fn set_len(&self, len: usize) {
        self.update(|s| s.len = len);
    }

    fn set_done(&self, done: usize) {
        self.update(|s| s.done = done);
    }

    fn tick(&self) {
        self.update(|s| s.done += 1);
    }

    fn end(&self) {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        if s.shown != s.done || self.terminal {
            self.show(&mut s, true);
        }
    }

    fn note(&self, message: &str) {
        let _ = writeln!(std::io::stderr().lock(), "{message}");
    }
}

/// Progress on stderr when asked for, else none.
pub fn feedback(progress: bool) -> Box<dyn Feedback + Send> {
    if progress {
        Box::new(Stderr::default())
    } else {
        Box::new(ferret_lab::Silent)
    }
}

/// Progress as [`feedback`] shows it, and Ctrl-C: between batches of houses long work asks
/// [`Feedback::cancelled`] from the thread that called it, and this lets Python run its signal
/// handlers there (with the GIL, which the work released; only the main thread runs them),
/// keeping the exception (`KeyboardInterrupt`) to raise once the work has stopped.
pub struct Interruptible {
    inner: Box<dyn Feedback + Send>,
    raised: Mutex<Option<pyo3::PyErr>>,
}

impl Interruptible {
    /// Progress on stderr when `progress`.
    pub fn new(progress: bool) -> Self {
        Self {
            inner: feedback(progress),
            raised: Mutex::new(None),
        }
    }

    /// The exception a signal handler raised, if the work was stopped by one.
    pub fn take(&self) -> Option<pyo3::PyErr> {
        self.raised.lock().unwrap_or_else(|p| p.into_inner()).take()
    }
}

impl Feedback for Interruptible {
    fn begin(&self, what: &str, len: usize) {
        self.inner.begin(what, len);
    }

    fn set_len(&self, len: usize) {
        self.inner.set_len(len);
    }

    fn set_done(&self, done: usize) {
        self.inner.set_done(done);
    }

    fn tick(&self) {
        self.inner.tick();
    }

    fn end(&self) {
        self.inner.end();
    }

    fn note(&self, message: &str) {
        self.inner.note(message);
    }

    fn cancelled(&self) -> bool {
        let mut raised = self.raised.lock().unwrap_or_else(|p| p.into_inner());
        if raised.is_some() {
            return true;
        }
        match pyo3::Python::with_gil(|py| py.check_signals()) {
            Ok(()) => false,
            Err(e) => {
                *raised = Some(e);
                true
            }
        }
    }
}
