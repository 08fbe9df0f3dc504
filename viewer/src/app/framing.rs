//! Framing the surface off the UI thread. Fitting the camera to the iso surface reads the
//! iso field's values wherever the surface may be: on a billion-cell file that is
//! gigabytes of the file's pages and seconds of work, during which a window that waited
//! would not draw. So the fit runs on a thread of its own; the window keeps drawing (and
//! rendering the view it has) and moves the camera when the fit arrives, if the view it
//! was made for is still the one shown. A fit that arrives within [`WAIT`] (all of
//! them on data of ordinary size) is applied at once, as if it had run in place.

use std::sync::mpsc::{self, RecvTimeoutError, TryRecvError};
use std::sync::Arc;
use std::time::Duration;

use crate::camera::Camera;
use crate::dataset::Dataset;
use crate::view_state::ViewState;

/// How long the UI thread waits for a fit before it goes on without it: a pause this
/// short reads as the click's own response, not as a frozen window.
pub(crate) const WAIT: Duration = Duration::from_millis(100);

/// Why the camera is fitted, which decides whether a late fit still applies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Purpose {
    /// The first view of a newly opened file: a late fit applies only while the camera is
    /// still the one the file opened with (a user who already moved it keeps their view).
    Open,
    /// The user asked for it (F, the panel's button): a late fit applies whatever the
    /// camera did meanwhile.
    Asked,
}

/// A fit on its way.
pub(crate) struct Fit {
    rx: mpsc::Receiver<Camera>,
    pub purpose: Purpose,
    /// What the fit is of: the data, the iso field and value.
    dataset: Arc<Dataset>,
    iso_field: String,
    iso: f64,
    /// The camera when the fit started.
    from: Camera,
}

/// What became of a fit when the window looked.
pub(crate) enum Outcome {
    /// Not done yet.
    Pending,
    /// Done: the camera that frames the surface.
    Done(Camera),
    /// The thread ended without a camera (it panicked).
    Failed,
}

impl Fit {
    /// Starts fitting `state`'s camera (at its image size and projection) to the surface
    /// of its iso field and value in `dataset`, as [`ViewState::frame_surface`] does.
    pub(crate) fn start(dataset: Arc<Dataset>, state: &ViewState, purpose: Purpose) -> Fit {
        let (tx, rx) = mpsc::channel();
        let mut fitted = state.clone();
        let data = Arc::clone(&dataset);
        let work = move || {
            fitted.frame_surface(data.volume());
            // The window may have dropped the fit (another file, another view): nobody
            // is left to tell.
            let _ = tx.send(fitted.camera);
        };
        let spawned = std::thread::Builder::new()
            .name("qbricks-framing".into())
            .spawn(work);
        let fit = Fit {
            rx,
            purpose,
            dataset,
            iso_field: state.iso_field.clone(),
            iso: state.iso,
            from: state.camera,
        };
        if spawned.is_err() {
            // No thread to be had (the closure, and its sender, went with the error): fit
            // here, as the window did before it had the thread.
            let mut fitted = state.clone();
            fitted.frame_surface(fit.dataset.volume());
            let (tx, rx) = mpsc::channel();
            let _ = tx.send(fitted.camera);
            return Fit { rx, ..fit };
        }
        fit
    }

    /// The fit, waiting at most `wait` for it; with no wait at all it is left for
    /// [`Fit::poll`] without a look, so that the window's part in a late fit does not
    /// depend on how fast the thread was.
    pub(crate) fn wait(&self, wait: Duration) -> Outcome {
        if wait.is_zero() {
            return Outcome::Pending;
        }
        match self.rx.recv_timeout(wait) {
            Ok(camera) => Outcome::Done(camera),
            Err(RecvTimeoutError::Timeout) => Outcome::Pending,
            Err(RecvTimeoutError::Disconnected) => Outcome::Failed,
        }
    }

    /// The fit if it is done, without waiting.
    pub(crate) fn poll(&self) -> Outcome {
        match self.rx.try_recv() {
            Ok(camera) => Outcome::Done(camera),
            Err(TryRecvError::Empty) => Outcome::Pending,
            Err(TryRecvError::Disconnected) => Outcome::Failed,
        }
    }

    /// Whether a fit made for the view it started from still applies to the view shown
    /// now, of the data open now (`None`: none is).
    pub(crate) fn applies(&self, dataset: Option<&Arc<Dataset>>, now: &ViewState) -> bool {
        let same_data = dataset.is_some_and(|d| Arc::ptr_eq(d, &self.dataset));
        let same_surface = now.iso_field == self.iso_field
            && (now.iso == self.iso || (now.iso.is_nan() && self.iso.is_nan()));
        let camera_ok = match self.purpose {
            Purpose::Open => now.camera == self.from,
            Purpose::Asked => true,
        };
        same_data && same_surface && camera_ok
    }
}
