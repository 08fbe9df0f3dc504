//! Transfer functions: an opaque iso-surface, or a Gaussian opacity band around the iso
//! value (the seed report's direct volume rendering).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// Render mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Opaque surface at the iso value, Phong-shaded with smooth normals (central differences of the reconstruction).
    Iso,
    /// Semi-transparent Gaussian band around the iso value (direct volume rendering).
    Dvr,
}

impl Mode {
    pub(crate) const ALL: [Mode; 2] = [Mode::Iso, Mode::Dvr];
    /// The name in view-state files and reports (`iso`, `dvr`).
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
    /// Opacity (per reference length) at the iso value, in 0..1 for a translucent shell
    /// ([`Band::SHELL_PEAK_OPACITY`] in new views). Read from `peak` too, its name before
    /// issue 26, so old state files render as before: their 1.6 (the seed report's) is
    /// above 1, which makes the middle of the band opaque, as it always did.
    #[serde(alias = "peak")]
    pub peak_opacity: f64,
    /// Half-width of the band in units of sigma.
    pub k: f64,
}

impl Band {
    /// Peak opacity of new views' bands: the seed report's 1.6 saturated the middle of
    /// the band, so the dvr shell looked like the iso-surface (44 dB PSNR between the two
    /// pictures of the bundled sample, issue 26); at this value the shell is translucent
    /// and the structure behind it shows through.
    pub const SHELL_PEAK_OPACITY: f64 = 0.7;

    /// The seed report's shape for iso 0.05: sigma = 0.004 (8 % of iso), peak 1.6, k = 2
    /// (band 0.042–0.058).
    pub const SEED_REPORT: Band = Band {
        sigma: 0.004,
        peak_opacity: 1.6,
        k: 2.0,
    };
}

/// Where a value lies relative to the transfer function's non-zero band.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Class {
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
    pub(crate) fn band(&self) -> (f64, f64) {
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
    pub(crate) fn opacity(&self, v: f64) -> f64 {
        let (lo, hi) = self.band();
        if !(v >= lo && v <= hi) {
            return 0.0;
        }
        let z = (v - self.iso) / self.band.sigma;
        (self.band.peak_opacity * (-0.5 * z * z).exp()).min(1.0)
    }

    #[inline]
    pub(crate) fn classify(&self, v: f64) -> Class {
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
    pub(crate) fn may_contribute(&self, min: f32, max: f32) -> bool {
        let (lo, hi) = self.band();
        range_meets(min, max, lo, hi)
    }
}

/// Whether the value range `[min, max]` meets the band `[lo, hi]`: the one test of
/// which regions can contribute.
#[inline]
pub(crate) fn range_meets(min: f32, max: f32, lo: f64, hi: f64) -> bool {
    (max as f64) >= lo && (min as f64) <= hi
}

/// Bins of the [`PreIntegrated`] table over the band.
const PRE_BINS: usize = 256;
/// Opacity cap before taking the logarithm: a sample of opacity 1 has infinite extinction.
/// 1 − 10⁻⁶ keeps a reference-length segment at opacity 0.999999, indistinguishable on screen.
const PRE_MAX_ALPHA: f64 = 1.0 - 1e-6;

/// Pre-integrated opacity (the seed report's §3.3) for the dvr band.
///
/// A point-sampled band thinner than the step is missed or caught by chance, depending on
/// where the samples fall; integrating the extinction over the values between two samples
/// (assuming the value varies linearly between them) makes a thin band contribute its full
/// opacity whatever the step. Because the band's opacity depends on the value alone, the
/// two-dimensional table over (front value, back value) of the general method reduces to
/// one cumulative integral `C(v) = ∫_lo^v τ(u) du` of the extinction
/// `τ(v) = −ln(1 − α(v)) / δ₀`: the mean extinction over a segment is
/// `(C(v_b) − C(v_f)) / (v_b − v_f)` and its opacity `1 − exp(−length · mean)`, exact for
/// any segment length. Colour is not pre-integrated: it comes from another field (speed)
/// and the Phong shading at the sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreIntegrated {
    lo: f64,
    hi: f64,
    /// `C` at the bin edges, world length⁻¹ × value.
    cum: [f64; PRE_BINS + 1],
    tf: Transfer,
    delta0: f64,
}

impl PreIntegrated {
    /// The table of `tf` (dvr) with opacity per reference length `delta0`; `None` in iso
    /// mode or for a degenerate band.
    pub fn new(tf: &Transfer, delta0: f64) -> Option<PreIntegrated> {
        let (lo, hi) = tf.band();
        let usable = hi > lo && delta0 > 0.0 && (hi - lo).is_finite();
        if tf.mode != Mode::Dvr || !usable {
            return None;
        }
        let mut pre = PreIntegrated {
            lo,
            hi,
            cum: [0.0; PRE_BINS + 1],
            tf: *tf,
            delta0,
        };
        let w = (hi - lo) / PRE_BINS as f64;
        // Midpoint rule with 16 sub-samples per bin: the band is a smooth Gaussian (with a
        // flat top where peak·exp(…) ≥ 1), so this is far below screen precision.
        const SUB: usize = 16;
        for i in 0..PRE_BINS {
            let mut s = 0.0;
            for k in 0..SUB {
                let v = lo + w * (i as f64 + (k as f64 + 0.5) / SUB as f64);
                s += pre.extinction(v);
            }
            pre.cum[i + 1] = pre.cum[i] + s * w / SUB as f64;
        }
        Some(pre)
    }

    /// Extinction per world length at value `v`.
    #[inline]
    pub(crate) fn extinction(&self, v: f64) -> f64 {
        let a = self.tf.opacity(v).min(PRE_MAX_ALPHA);
        -(1.0 - a).ln() / self.delta0
    }

    /// `C(v)`, linear between the table's edges, constant outside the band.
    #[inline]
    fn cumulative(&self, v: f64) -> f64 {
        if v.is_nan() || v <= self.lo {
            return 0.0;
        }
        if v >= self.hi {
            return self.cum[PRE_BINS];
        }
        let x = (v - self.lo) / (self.hi - self.lo) * PRE_BINS as f64;
        let i = (x as usize).min(PRE_BINS - 1);
        let f = x - i as f64;
        self.cum[i] + f * (self.cum[i + 1] - self.cum[i])
    }

    /// Opacity of a segment of `length` (world units) whose value runs linearly from
    /// `front` to `back`.
    #[inline]
    pub(crate) fn segment_alpha(&self, front: f64, back: f64, length: f64) -> f64 {
        if length.is_nan() || length <= 0.0 {
            return 0.0;
        }
        let dv = back - front;
        let mean = if dv.abs() <= 1e-9 * (self.hi - self.lo) {
            self.extinction(back)
        } else {
            (self.cumulative(back) - self.cumulative(front)) / dv
        };
        1.0 - (-length * mean.max(0.0)).exp()
    }
}

#[cfg(test)]
mod pre_tests {
    use super::*;

    fn dvr() -> Transfer {
        Transfer {
            mode: Mode::Dvr,
            ..Transfer::default()
        }
    }

    #[test]
    fn constant_segment_matches_opacity_correction() {
        let tf = dvr();
        let pre = PreIntegrated::new(&tf, 0.5).expect("dvr table");
        for v in [0.043, 0.047, 0.05, 0.055] {
            for len in [0.1, 0.5, 2.0] {
                // Where the band saturates (opacity 1) the table holds the capped opacity,
                // so a segment shorter than the reference length is a little less than
                // opaque: 1 − (1 − cap)^(len/δ₀).
                let alpha = tf.opacity(v).min(PRE_MAX_ALPHA);
                let want = crate::integrate::correct_opacity(alpha, len, 0.5);
                let got = pre.segment_alpha(v, v, len);
                assert!(
                    (got - want).abs() < 1e-5,
                    "v {v} len {len}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn a_band_between_two_samples_still_counts() {
        let tf = dvr();
        let pre = PreIntegrated::new(&tf, 0.5).expect("dvr table");
        // Both ends outside the band: point sampling sees nothing.
        assert_eq!(tf.opacity(0.03), 0.0);
        assert_eq!(tf.opacity(0.07), 0.0);
        // The segment crosses the whole band: the same opacity whichever way.
        let up = pre.segment_alpha(0.03, 0.07, 2.0);
        let down = pre.segment_alpha(0.07, 0.03, 2.0);
        assert!(up > 0.05, "{up}");
        assert!((up - down).abs() < 1e-12);
        // Steeper crossing (same values, shorter segment): less of the band's material.
        assert!(pre.segment_alpha(0.03, 0.07, 1.0) < up);
        // Outside the band on one side only: nothing.
        assert_eq!(pre.segment_alpha(0.01, 0.03, 2.0), 0.0);
    }

    #[test]
    fn no_table_in_iso_mode() {
        assert!(PreIntegrated::new(&Transfer::default(), 0.5).is_none());
    }
}
