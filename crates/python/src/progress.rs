//! Progress of long work, when asked for (`progress=` of `evaluate`, `calibrate` and `select`):
//! the experiment layer's `Feedback` as lines on stderr a terminal, a log or a notebook's
//! console can show (the work runs without the GIL, on Rust threads, so it writes to the
//! process's stderr rather than `sys.stderr`), or as calls of a Python callable.

use std::io::{IsTerminal, Write};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use ferret_lab::Feedback;
use pyo3::prelude::*;

/// What the `progress` argument asks for: nothing (`None`, `False`), lines on stderr (`True`),
/// or calls `progress(what, done, total)` of a callable.
pub enum Progress {
    /// No progress.
    Off,
    /// Lines on stderr: redrawn in place on a terminal, every tenth of a step otherwise.
    Stderr,
    /// Calls of a Python callable.
    Call(Py<PyAny>),
}

impl<'py> FromPyObject<'py> for Progress {
    fn extract_bound(arg: &Bound<'py, PyAny>) -> PyResult<Self> {
        if arg.is_none() {
            Ok(Progress::Off)
        } else if let Ok(on) = arg.downcast::<pyo3::types::PyBool>() {
            Ok(if on.is_true() {
                Progress::Stderr
            } else {
                Progress::Off
            })
        } else if arg.is_callable() {
            Ok(Progress::Call(arg.clone().unbind()))
        } else {
            Err(pyo3::exceptions::PyTypeError::new_err(format!(
                "progress: expected True, False or a callable progress(what, done, total), got {}",
                arg.get_type().name()?
            )))
        }
    }
}

/// The step under way, as either kind of progress shows it.
#[derive(Default)]
struct Step {
    what: String,
    len: usize,
    done: usize,
    shown: usize,
    started: Option<Instant>,
}

/// Where a step's progress goes, and when: [`Stepped`] keeps the step and asks.
trait Show: Send + Sync {
    /// Shows `s` (`last`: the step has ended).
    fn show(&self, s: &Step, last: bool);
    /// Whether `s`, just updated, is to be shown.
    fn due(&self, s: &Step) -> bool;
    /// Whether `s`, ending, is to be shown once more.
    fn due_at_end(&self, s: &Step) -> bool;
    /// A remark beside the progress.
    fn note(&self, _message: &str) {}
}

/// The lab's [`Feedback`] over one [`Show`]: the current step's counts, shown when it says.
struct Stepped<S> {
    state: Mutex<Step>,
    out: S,
}

impl<S: Show> Stepped<S> {
    fn new(out: S) -> Self {
        Self {
            state: Mutex::new(Step::default()),
            out,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Step> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn show(&self, s: &mut Step, last: bool) {
        self.out.show(s, last);
        s.shown = s.done;
    }

    fn update(&self, f: impl FnOnce(&mut Step)) {
        let mut s = self.lock();
        f(&mut s);
        if self.out.due(&s) {
            self.show(&mut s, false);
        }
    }
}

impl<S: Show> Feedback for Stepped<S> {
    fn begin(&self, what: &str, len: usize) {
        let mut s = self.lock();
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
        let mut s = self.lock();
        if self.out.due_at_end(&s) {
            self.show(&mut s, true);
        }
    }

    fn note(&self, message: &str) {
        self.out.note(message);
    }
}

/// Each step's progress on stderr: redrawn in place on a terminal, and every tenth of the step
/// otherwise.
struct Stderr {
    terminal: bool,
}

impl Show for Stderr {
    fn show(&self, s: &Step, last: bool) {
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
    }

    fn due(&self, s: &Step) -> bool {
        let tenth = (s.len / 10).max(1);
        self.terminal || s.done >= s.shown + tenth || (s.len > 0 && s.done == s.len)
    }

    fn due_at_end(&self, s: &Step) -> bool {
        s.shown != s.done || self.terminal
    }

    fn note(&self, message: &str) {
        let _ = writeln!(std::io::stderr().lock(), "{message}");
    }
}

/// Progress handed to a Python callable as `progress(what, done, total)` (`total` 0 while
/// unknown): when a step begins and ends, and at most every hundredth of it in between, so a
/// slow callable does not slow the work. Remarks are not passed on. An exception the callable
/// raises is kept (the first one), stops the work at its next check and is raised by the call.
struct Callback {
    func: Py<PyAny>,
    raised: Arc<Mutex<Option<PyErr>>>,
}

impl Show for Callback {
    fn show(&self, s: &Step, _last: bool) {
        let mut raised = self.raised.lock().unwrap_or_else(|p| p.into_inner());
        if raised.is_some() {
            return;
        }
        let result = Python::with_gil(|py| self.func.call1(py, (s.what.as_str(), s.done, s.len)));
        if let Err(e) = result {
            *raised = Some(e);
        }
    }

    fn due(&self, s: &Step) -> bool {
        let hundredth = (s.len / 100).max(1);
        s.done >= s.shown + hundredth || (s.len > 0 && s.done == s.len && s.shown != s.done)
    }

    fn due_at_end(&self, s: &Step) -> bool {
        s.shown != s.done
    }
}

/// Progress as `progress` asks for it, and Ctrl-C: between batches of houses long work asks
/// [`Feedback::cancelled`] from the thread that called it, and this lets Python run its signal
/// handlers there (with the GIL, which the work released; only the main thread runs them),
/// keeping the exception (`KeyboardInterrupt`) to raise once the work has stopped.
pub struct Interruptible {
    inner: Box<dyn Feedback + Send>,
    raised: Arc<Mutex<Option<pyo3::PyErr>>>,
}

impl Interruptible {
    /// Progress as `progress` asks for it (none when `None`).
    pub fn new(progress: Option<Progress>) -> Self {
        let raised = Arc::new(Mutex::new(None));
        let inner: Box<dyn Feedback + Send> = match progress.unwrap_or(Progress::Off) {
            Progress::Off => Box::new(ferret_lab::Silent),
            Progress::Stderr => Box::new(Stepped::new(Stderr {
                terminal: std::io::stderr().is_terminal(),
            })),
            Progress::Call(func) => Box::new(Stepped::new(Callback {
                func,
                raised: raised.clone(),
            })),
        };
        Self { inner, raised }
    }

    /// The exception a signal handler or the progress callable raised, if one stopped the
    /// work; to raise once the work has returned.
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
