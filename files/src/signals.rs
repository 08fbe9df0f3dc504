//! Removing temporary files when the process is interrupted.
//!
//! Every output is first written to a hidden temporary file next to its target
//! ([`crate::output`]). While one exists its path is in a registry of live temporary
//! files; the first one registered installs a handler for SIGINT, SIGTERM and SIGHUP that
//! removes every registered file and then ends the process as the signal would have (so
//! the exit status still says "killed by SIGINT"). Without it, Ctrl-C in the middle of a
//! large write left a hidden temporary file behind on every run.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, Once};

/// Live temporary files, removed by the signal handler.
static LIVE_TEMPS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
static HANDLER: Once = Once::new();

/// Installs (once) the handler that removes live temporary files on SIGINT/SIGTERM/SIGHUP.
fn install_cleanup() {
    HANDLER.call_once(|| {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else {
            // Without the handler a signal still ends the process; only the cleanup of
            // temporary files is lost. Nothing better to do than write without it.
            return;
        };
        let spawned = std::thread::Builder::new()
            .name("qbricks-signal-cleanup".into())
            .spawn(move || {
                if let Some(signal) = signals.forever().next() {
                    remove_live_temps();
                    let _ = signal_hook::low_level::emulate_default_handler(signal);
                    // A signal whose default is not to terminate cannot reach here (only
                    // terminating ones are registered); end the process anyway.
                    std::process::exit(128 + signal);
                }
            });
        drop(spawned);
    });
}

fn remove_live_temps() {
    let live = registry();
    for p in live.iter() {
        let _ = std::fs::remove_file(p);
    }
    // The lock is held until the process ends, so no new temporary file is registered (or
    // renamed into place) after the cleanup.
    std::mem::forget(live);
}

/// The registry, locked. Holding the guard keeps the signal handler from removing files
/// half-way through a create-and-register or a rename-and-unregister.
pub(crate) fn registry() -> MutexGuard<'static, Vec<PathBuf>> {
    LIVE_TEMPS.lock().unwrap_or_else(|e| e.into_inner())
}

/// Installs the handler (once) and returns the locked registry, so the caller can create
/// a temporary file and register it before a signal could see it unregistered.
pub(crate) fn registry_with_cleanup() -> MutexGuard<'static, Vec<PathBuf>> {
    install_cleanup();
    registry()
}

/// Removes `path` from the registry (it was renamed into place or deleted).
pub(crate) fn unregister(live: &mut Vec<PathBuf>, path: &Path) {
    live.retain(|p| p != path);
}

#[cfg(test)]
pub(crate) fn live() -> Vec<PathBuf> {
    registry().clone()
}
