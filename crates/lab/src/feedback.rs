//! How long work reports progress and remarks without printing: the face decides how to show
//! them (a progress bar and stderr in the cli, nothing in a service, a callback in Python).

/// Progress and remarks of long work. Every method has a silent default, so a caller implements
/// only what it shows. Work in parallel calls [`tick`](Feedback::tick) from several threads.
pub trait Feedback: Sync {
    /// A step of `len` items named `what` begins (`len` may be 0 when unknown yet).
    fn begin(&self, _what: &str, _len: usize) {}
    /// The current step's length became known or changed.
    fn set_len(&self, _len: usize) {}
    /// The current step is at `done` items.
    fn set_done(&self, _done: usize) {}
    /// One more item of the current step is done.
    fn tick(&self) {}
    /// The current step is over.
    fn end(&self) {}
    /// Something the user should read: a skipped house, a dropped cache row, a failure kept.
    fn note(&self, _message: &str) {}
    /// Whether the user asked to stop (Ctrl-C in Python): long work asks between batches, on
    /// the thread that called it, and stops with [`LabError::Cancelled`](crate::LabError).
    fn cancelled(&self) -> bool {
        false
    }
}

/// Shows nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Feedback for Silent {}
