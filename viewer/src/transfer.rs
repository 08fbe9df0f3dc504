//! Transfer functions: an opaque iso-surface, or a Gaussian opacity band around the iso
//! value (the seed report's direct volume rendering).

use serde::{Deserialize, Serialize};

pub use crate::view_state::Mode;

/// Where a value lies relative to the transfer function's non-zero band.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    Below,
    Inside,
    Above,
}

/// Opacity `min(1, peak·exp(−½((v−iso)/σ)²))` inside `iso ± k·σ`, zero outside; in iso
/// mode only `iso` matters. Opacity is per `reference_length` of ray (see
/// [`crate::integrate::correct_opacity`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Transfer {
    pub mode: Mode,
    pub iso: f64,
    pub sigma: f64,
    pub peak: f64,
    /// Half-width of the band in units of σ.
    pub k: f64,
}

impl Default for Transfer {
    /// The seed report's parameters: iso 0.05, σ 0.004, peak 1.6, band 0.042–0.058.
    fn default() -> Self {
        Transfer {
            mode: Mode::Iso,
            iso: 0.05,
            sigma: 0.004,
            peak: 1.6,
            k: 2.0,
        }
    }
}

impl Transfer {
    /// The non-zero band `[lo, hi]` (the iso value alone in iso mode).
    pub fn band(&self) -> (f64, f64) {
        match self.mode {
            Mode::Iso => (self.iso, self.iso),
            Mode::Dvr => (
                self.iso - self.k * self.sigma,
                self.iso + self.k * self.sigma,
            ),
        }
    }

    /// Opacity per reference length at value `v` (dvr).
    #[inline]
    pub fn opacity(&self, v: f64) -> f64 {
        let (lo, hi) = self.band();
        if !(v >= lo && v <= hi) {
            return 0.0;
        }
        let z = (v - self.iso) / self.sigma;
        (self.peak * (-0.5 * z * z).exp()).min(1.0)
    }

    #[inline]
    pub fn classify(&self, v: f64) -> Class {
        let (lo, hi) = self.band();
        if v < lo {
            Class::Below
        } else if v > hi {
            Class::Above
        } else {
            Class::Inside
        }
    }

    /// Whether a region whose values lie in `[min, max]` can contribute (empty-space skip).
    #[inline]
    pub fn may_contribute(&self, min: f32, max: f32) -> bool {
        let (lo, hi) = self.band();
        (max as f64) >= lo && (min as f64) <= hi
    }
}
