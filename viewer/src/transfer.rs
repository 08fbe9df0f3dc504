//! Transfer functions: an opaque iso-surface, or a Gaussian opacity band around the iso
//! value (the seed report's direct volume rendering).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// Render mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Opaque surface at the iso value, Phong-shaded from the analytic gradient.
    Iso,
    /// Semi-transparent Gaussian band around the iso value (direct volume rendering).
    Dvr,
}

impl Mode {
    pub const ALL: [Mode; 2] = [Mode::Iso, Mode::Dvr];
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Iso => "iso",
            Mode::Dvr => "dvr",
        }
    }
}

impl fmt::Display for Mode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Mode::ALL
            .into_iter()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| format!("unknown mode `{s}`: expected iso or dvr"))
    }
}

/// Shape of the dvr opacity band around the iso value:
/// `min(1, peak·exp(-½((v-iso)/sigma)²))` inside `iso ± k·sigma`, zero outside.
/// This is the `transfer` object of a view state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Band {
    pub sigma: f64,
    pub peak: f64,
    /// Half-width of the band in units of sigma.
    pub k: f64,
}

impl Band {
    /// The seed report's shape for iso 0.05: sigma = 0.004 (8 % of iso), peak 1.6, k = 2
    /// (band 0.042–0.058).
    pub const SEED_REPORT: Band = Band {
        sigma: 0.004,
        peak: 1.6,
        k: 2.0,
    };
}

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
    pub band: Band,
}

impl Default for Transfer {
    /// The seed report's parameters: iso 0.05, σ 0.004, peak 1.6, band 0.042–0.058.
    fn default() -> Self {
        Transfer {
            mode: Mode::Iso,
            iso: 0.05,
            band: Band::SEED_REPORT,
        }
    }
}

impl Transfer {
    /// The non-zero band `[lo, hi]` (the iso value alone in iso mode).
    pub fn band(&self) -> (f64, f64) {
        match self.mode {
            Mode::Iso => (self.iso, self.iso),
            Mode::Dvr => (
                self.iso - self.band.k * self.band.sigma,
                self.iso + self.band.k * self.band.sigma,
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
        let z = (v - self.iso) / self.band.sigma;
        (self.band.peak * (-0.5 * z * z).exp()).min(1.0)
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
