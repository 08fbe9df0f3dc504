//! Front-to-back compositing of one ray, with opacity correction and early termination.

/// Stop marching once the remaining transmittance falls below this.
pub(crate) const EARLY_TERMINATION: f64 = 1.0 / 512.0;

/// `α' = 1 − (1 − α)^(Δ/Δ₀)`: opacity `alpha` defined per reference length `delta0`,
/// corrected for a ray interval of length `delta`.
#[inline]
pub(crate) fn correct_opacity(alpha: f64, delta: f64, delta0: f64) -> f64 {
    if alpha <= 0.0 || delta <= 0.0 {
        return 0.0;
    }
    if alpha >= 1.0 {
        return 1.0;
    }
    1.0 - (1.0 - alpha).powf(delta / delta0)
}

/// Premultiplied colour and transmittance of a ray so far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Accum {
    pub rgb: [f64; 3],
    pub transmittance: f64,
}

impl Default for Accum {
    fn default() -> Self {
        Accum {
            rgb: [0.0; 3],
            transmittance: 1.0,
        }
    }
}

impl Accum {
    /// Adds a sample of colour `c` and (corrected) opacity `alpha` behind what is there.
    #[inline]
    pub(crate) fn add(&mut self, c: [f64; 3], alpha: f64) {
        let w = self.transmittance * alpha;
        for a in 0..3 {
            self.rgb[a] += w * c[a];
        }
        self.transmittance *= 1.0 - alpha;
    }

    /// Puts what `behind` gathered (along a later stretch of the same ray) behind what is
    /// here.
    #[inline]
    pub(crate) fn then(&mut self, behind: &Accum) {
        for a in 0..3 {
            self.rgb[a] += self.transmittance * behind.rgb[a];
        }
        self.transmittance *= behind.transmittance;
    }

    /// Opacity reached; nothing behind can show.
    #[inline]
    pub(crate) fn done(&self) -> bool {
        self.transmittance < EARLY_TERMINATION
    }

    pub fn alpha(&self) -> f64 {
        1.0 - self.transmittance
    }

    /// Composites over a background colour.
    pub(crate) fn over(&self, bg: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| self.rgb[a] + self.transmittance * bg[a])
    }
}
