//! Fitting the camera to the surface off the UI thread. The fit reads the iso field's
//! values wherever the surface may be: on a billion-cell file gigabytes of the file's
//! pages and seconds of work. The window keeps drawing (and rendering the view it has)
//! and moves the camera when the fit arrives, if the view it was made for is still the
//! one shown.

use std::sync::Arc;

use super::background::{Pending, Poll};
use crate::camera::Camera;
use crate::dataset::Dataset;
use crate::view_state::ViewState;

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
    pub job: Pending<Camera>,
    pub purpose: Purpose,
    /// What the fit is of: the data, the iso field and value.
    dataset: Arc<Dataset>,
    iso_field: String,
    iso: f64,
    /// The camera when the fit started.
    from: Camera,
}

impl Fit {
    /// Starts fitting `state`'s camera (at its image size and projection) to the surface
    /// of its iso field and value in `dataset`, as [`ViewState::frame_surface`] does.
    pub(crate) fn start(dataset: Arc<Dataset>, state: &ViewState, purpose: Purpose) -> Fit {
        let mut fitted = state.clone();
        let data = Arc::clone(&dataset);
        let job = Pending::start("qbricks-framing", move || {
            fitted.frame_surface(data.volume());
            fitted.camera
        });
        Fit {
            job,
            purpose,
            dataset,
            iso_field: state.iso_field.clone(),
            iso: state.iso,
            from: state.camera,
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

/// What the window does with a fit it looked at.
pub(crate) type Outcome = Poll<Camera>;
