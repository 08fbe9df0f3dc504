//! Work the window hands to a thread of its own so that it keeps drawing meanwhile:
//! opening a file (validating a large file reads its structure, seconds when its pages
//! are not in memory yet) and fitting the camera to the surface (see `framing`). The
//! window waits [`WAIT`] for the result, which is all most work takes, so on data of
//! ordinary size nothing changes; past that it polls once a UI frame.

use std::sync::mpsc::{self, RecvTimeoutError, TryRecvError};
use std::time::Duration;

/// How long the UI thread waits for work before it goes on without it: a pause this
/// short reads as the click's own response, not as a frozen window.
pub(crate) const WAIT: Duration = Duration::from_millis(100);

/// Work on its way, with its result of type `T`.
pub(crate) struct Pending<T> {
    rx: mpsc::Receiver<T>,
}

/// What became of the work when the window looked.
pub(crate) enum Poll<T> {
    /// Not done yet.
    Pending,
    Done(T),
    /// The thread ended without a result (it panicked).
    Failed,
}

impl<T: Send + 'static> Pending<T> {
    /// Starts `work` on a thread named `name`; without a thread to be had, does it here.
    pub(crate) fn start(name: &str, work: impl FnOnce() -> T + Send + 'static) -> Pending<T> {
        let (tx, rx) = mpsc::channel();
        // The work is shared with the fallback below: the closure handed to the thread
        // is lost with a failed spawn.
        let work = std::sync::Arc::new(std::sync::Mutex::new(Some(work)));
        let theirs = std::sync::Arc::clone(&work);
        let sender = tx.clone();
        let spawned = std::thread::Builder::new()
            .name(name.to_string())
            .spawn(move || {
                let w = theirs.lock().ok().and_then(|mut g| g.take());
                if let Some(w) = w {
                    // The window may have dropped the work (another file, another view):
                    // nobody is left to tell.
                    let _ = sender.send(w());
                }
            });
        if spawned.is_err() {
            let w = work.lock().ok().and_then(|mut g| g.take());
            if let Some(w) = w {
                let _ = tx.send(w());
            }
        }
        Pending { rx }
    }
}

impl<T> Pending<T> {
    /// The result, waiting at most `wait` for it; with no wait at all it is left for
    /// [`Pending::poll`] without a look, so that what the window does with late work
    /// does not depend on how fast the thread was (the tests use this).
    pub(crate) fn wait(&self, wait: Duration) -> Poll<T> {
        if wait.is_zero() {
            return Poll::Pending;
        }
        match self.rx.recv_timeout(wait) {
            Ok(v) => Poll::Done(v),
            Err(RecvTimeoutError::Timeout) => Poll::Pending,
            Err(RecvTimeoutError::Disconnected) => Poll::Failed,
        }
    }

    /// The result if it is there, without waiting.
    pub(crate) fn poll(&self) -> Poll<T> {
        match self.rx.try_recv() {
            Ok(v) => Poll::Done(v),
            Err(TryRecvError::Empty) => Poll::Pending,
            Err(TryRecvError::Disconnected) => Poll::Failed,
        }
    }

    /// The result, however long it takes.
    #[cfg(test)]
    pub(crate) fn finish(&self) -> Poll<T> {
        match self.rx.recv() {
            Ok(v) => Poll::Done(v),
            Err(_) => Poll::Failed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Work arrives through `wait` when it is quick, through `poll` or `finish` when it
    /// is not; a panic in it is `Failed`, not a hang or a panic of the window.
    #[test]
    fn work_arrives_by_wait_poll_or_finish_and_a_panic_is_a_failure() {
        let quick = Pending::start("t-quick", || 7);
        assert!(matches!(quick.wait(Duration::from_secs(30)), Poll::Done(7)));
        let (go, gate) = mpsc::channel::<()>();
        let slow = Pending::start("t-slow", move || {
            let _ = gate.recv();
            8
        });
        assert!(matches!(
            slow.wait(Duration::from_millis(20)),
            Poll::Pending
        ));
        assert!(matches!(slow.poll(), Poll::Pending));
        assert!(matches!(slow.wait(Duration::ZERO), Poll::Pending));
        go.send(()).expect("send");
        assert!(matches!(slow.finish(), Poll::Done(8)));
        let broken = Pending::start("t-panic", || -> u32 { panic!("broken work") });
        assert!(matches!(broken.finish(), Poll::Failed));
    }
}
