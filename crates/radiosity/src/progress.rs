//! Progress reporting and cancellation: the only channel from the library to the user.
//!
//! Long stages call [`Progress::begin`], [`Progress::advance`] and [`Progress::end`]; solvers
//! report each iteration through [`Progress::message`]. Work polls [`Progress::should_stop`]
//! (set by Ctrl-C in the program) and stops early, keeping the result computed so far.
//! Implementations must be cheap and thread-safe: `advance` is called from worker threads.

use std::sync::atomic::{AtomicBool, Ordering};

/// Receives progress from long computations. All methods have no-op defaults.
pub trait Progress: Sync {
    /// A stage with `total` units of work starts.
    fn begin(&self, _stage: &str, _total: u64) {}
    /// `n` more units of the current stage are done.
    fn advance(&self, _n: u64) {}
    /// The current stage has ended.
    fn end(&self) {}
    /// A one-line status, e.g. a solver's residual after an iteration.
    fn message(&self, _msg: &str) {}
    /// Something the user should know about the result (`msg` without a "warning:"
    /// prefix). Unlike [`Progress::message`] it is meant to be shown even when progress
    /// is not; by default it is a message.
    fn warning(&self, msg: &str) {
        self.message(&format!("warning: {msg}"));
    }
    /// True when the user asked to stop; work ends early and keeps what it has.
    fn should_stop(&self) -> bool {
        false
    }
}

/// Reports nothing and never stops.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;
impl Progress for NoProgress {}

/// Reports nothing; stops once its flag is set (from another thread or a signal handler).
#[derive(Debug, Default)]
pub struct StopFlag(pub AtomicBool);
impl StopFlag {
    /// Asks the work to stop.
    pub fn stop(&self) {
        self.0.store(true, Ordering::Relaxed)
    }
}
impl Progress for StopFlag {
    fn should_stop(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// Runs `f(i, &mut out[i])` for every item, in parallel chunks of 1024 (each chunk's
/// scratch from `scratch()`), reporting progress as stage `stage`; once `progress` asks to
/// stop, the chunks not started are left as they are. Returns the sum of `f`'s counts
/// (rays cast).
pub fn for_each_chunked<T: Send, S>(
    out: &mut [T],
    stage: &str,
    progress: &dyn Progress,
    scratch: impl Fn() -> S + Sync,
    f: impl Fn(usize, &mut T, &mut S) -> u64 + Sync,
) -> u64 {
    use rayon::prelude::*;
    const CHUNK: usize = 1024;
    progress.begin(stage, out.len() as u64);
    let total = out
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, chunk)| {
            if progress.should_stop() {
                return 0;
            }
            let mut s = scratch();
            let n: u64 = chunk.iter_mut().enumerate().map(|(k, x)| f(c * CHUNK + k, x, &mut s)).sum();
            progress.advance(chunk.len() as u64);
            n
        })
        .sum();
    progress.end();
    total
}
