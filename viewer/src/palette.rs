//! Named colour maps — viridis, magma, cividis (perceptually uniform; cividis also for
//! colour-vision deficiencies), cool–warm (diverging: blue below a centre, red above) and
//! the seed report's blue/green/red speed colours — turned into the control points of a
//! [`ColorMap`] over a value range.
//!
//! The colours come from the `colorous` crate (the published tables of these maps). A map
//! is sampled at [`SAMPLES`] points; between them the colour map interpolates linearly,
//! closer to the published map than the eye can tell. A diverging map puts its middle
//! on the centre (Q is signed: centre 0 makes vortex cores red and strain blue) and
//! spreads both halves over the larger side, so equal distances from the centre get equal
//! strength of colour.

use std::str::FromStr;

use crate::colormap::{ColorMap, ControlPoint, BLUE, GREEN, RED};

/// Control points a named map is sampled at.
pub const SAMPLES: usize = 17;

/// A named colour map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Palette {
    Viridis,
    Magma,
    Cividis,
    CoolWarm,
    /// The seed report's blue, green, red.
    Speed,
}

impl Palette {
    pub const ALL: [Palette; 5] = [
        Palette::Viridis,
        Palette::Magma,
        Palette::Cividis,
        Palette::CoolWarm,
        Palette::Speed,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Palette::Viridis => "viridis",
            Palette::Magma => "magma",
            Palette::Cividis => "cividis",
            Palette::CoolWarm => "coolwarm",
            Palette::Speed => "speed",
        }
    }

    /// Whether the map is diverging (its middle marks a centre value).
    pub fn is_diverging(self) -> bool {
        self == Palette::CoolWarm
    }

    /// Colour at `t` in 0..=1 along the map.
    pub fn at(self, t: f64) -> [f32; 3] {
        let t = t.clamp(0.0, 1.0);
        let from = |c: colorous::Color| {
            [
                f32::from(c.r) / 255.0,
                f32::from(c.g) / 255.0,
                f32::from(c.b) / 255.0,
            ]
        };
        match self {
            Palette::Viridis => from(colorous::VIRIDIS.eval_continuous(t)),
            Palette::Magma => from(colorous::MAGMA.eval_continuous(t)),
            Palette::Cividis => from(colorous::CIVIDIS.eval_continuous(t)),
            // ColorBrewer's red–blue runs red to blue: turned round, blue is low.
            Palette::CoolWarm => from(colorous::RED_BLUE.eval_continuous(1.0 - t)),
            Palette::Speed => {
                if t < 0.5 {
                    lerp(BLUE, GREEN, (2.0 * t) as f32)
                } else {
                    lerp(GREEN, RED, (2.0 * t - 1.0) as f32)
                }
            }
        }
    }
}

fn lerp(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    std::array::from_fn(|i| a[i] + (b[i] - a[i]) * t)
}

/// A palette, possibly reversed (`viridis_r`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PaletteSpec {
    pub palette: Palette,
    pub reversed: bool,
}

/// Why a palette name is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "expected one of {} (add _r to reverse), found `{name}`",
    Palette::ALL.map(Palette::name).join(", ")
)]
pub struct PaletteError {
    pub name: String,
}

impl FromStr for PaletteSpec {
    type Err = PaletteError;
    fn from_str(s: &str) -> Result<Self, PaletteError> {
        let (base, reversed) = match s.strip_suffix("_r") {
            Some(b) => (b, true),
            None => (s, false),
        };
        Palette::ALL
            .into_iter()
            .find(|p| p.name() == base)
            .map(|palette| PaletteSpec { palette, reversed })
            .ok_or_else(|| PaletteError {
                name: s.to_string(),
            })
    }
}

impl std::fmt::Display for PaletteSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.palette.name())?;
        if self.reversed {
            f.write_str("_r")?;
        }
        Ok(())
    }
}

impl PaletteSpec {
    /// The colour map of `field` over `lo..hi` (swapped or non-finite limits repaired as
    /// [`ColorMap`]'s defaults do). A diverging palette is centred on `centre` (default:
    /// 0 when the range holds it, else the middle). `log`: the points are spaced evenly
    /// in log10 of the value, for a positive field spanning decades (a range that is not
    /// positive falls back to even spacing).
    pub fn colour_map(
        &self,
        field: &str,
        lo: f32,
        hi: f32,
        centre: Option<f32>,
        log: bool,
    ) -> ColorMap {
        let (lo, hi) = if lo.is_finite() && hi.is_finite() {
            (f64::from(lo.min(hi)), f64::from(lo.max(hi)))
        } else {
            (0.0, 1.0)
        };
        let (lo, hi) = if self.palette.is_diverging() {
            let c = centre.map(f64::from).filter(|c| c.is_finite()).unwrap_or(
                if lo <= 0.0 && hi >= 0.0 {
                    0.0
                } else {
                    0.5 * (lo + hi)
                },
            );
            let r = (c - lo).abs().max((hi - c).abs());
            (c - r, c + r)
        } else {
            (lo, hi)
        };
        let log = log && lo > 0.0 && !self.palette.is_diverging();
        let value = |t: f64| {
            if log {
                10f64.powf(lo.log10() + t * (hi.log10() - lo.log10()))
            } else {
                lo + t * (hi - lo)
            }
        };
        let mut points: Vec<ControlPoint> = (0..SAMPLES)
            .map(|i| {
                let t = i as f64 / (SAMPLES - 1) as f64;
                ControlPoint {
                    value: value(t) as f32,
                    colour: self.palette.at(if self.reversed { 1.0 - t } else { t }),
                }
            })
            .collect();
        // Values that round to the same f32 (a range narrower than f32 resolves) keep one.
        points.dedup_by(|b, a| b.value <= a.value);
        ColorMap {
            field: field.to_string(),
            points,
            band: 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_and_print() {
        for p in Palette::ALL {
            let spec: PaletteSpec = p.name().parse().expect("name");
            assert_eq!(spec.palette, p);
            assert!(!spec.reversed);
            let r: PaletteSpec = format!("{}_r", p.name()).parse().expect("reversed");
            assert!(r.reversed);
            assert_eq!(r.to_string(), format!("{}_r", p.name()));
        }
        let e = "jet".parse::<PaletteSpec>().expect_err("unknown");
        assert!(e.to_string().contains("viridis, magma"), "{e}");
    }

    #[test]
    fn maps_span_the_range_in_order_and_validate() {
        for p in Palette::ALL {
            for reversed in [false, true] {
                let spec = PaletteSpec {
                    palette: p,
                    reversed,
                };
                let m = spec.colour_map("speed", 0.01, 0.09, None, false);
                m.validate().expect("valid");
                let (first, last) = (m.points[0], m.points[m.points.len() - 1]);
                if p.is_diverging() {
                    // No zero in the range: centred on the middle.
                    assert!((0.5 * (first.value + last.value) - 0.05).abs() < 1e-6);
                } else {
                    assert_eq!((first.value, last.value), (0.01, 0.09));
                }
                // Reversing swaps the ends' colours.
                let fwd = PaletteSpec {
                    palette: p,
                    reversed: false,
                }
                .colour_map("speed", 0.01, 0.09, None, false);
                if reversed {
                    assert_eq!(first.colour, fwd.points[fwd.points.len() - 1].colour);
                }
            }
        }
        // Viridis runs dark purple to yellow.
        let v = PaletteSpec {
            palette: Palette::Viridis,
            reversed: false,
        }
        .colour_map("q", 0.0, 1.0, None, false);
        assert!(v.colour(0.0)[2] > v.colour(0.0)[1] && v.colour(1.0)[0] > 0.9);
    }

    #[test]
    fn a_diverging_map_is_centred_and_symmetric() {
        let spec = PaletteSpec {
            palette: Palette::CoolWarm,
            reversed: false,
        };
        // Q from -0.3 to 0.56, centred on 0: the map runs -0.56..0.56.
        let m = spec.colour_map("q", -0.3, 0.56, None, false);
        assert_eq!(m.points[0].value, -0.56);
        assert_eq!(m.points[m.points.len() - 1].value, 0.56);
        let mid = m.colour(0.0);
        assert!(
            mid.iter().all(|&c| c > 0.85),
            "near white at the centre: {mid:?}"
        );
        let (neg, pos) = (m.colour(-0.4), m.colour(0.4));
        assert!(neg[2] > neg[0] && pos[0] > pos[2], "{neg:?} {pos:?}");
        let m = spec.colour_map("q", -0.3, 0.56, Some(0.1), false);
        assert!((m.points[SAMPLES / 2].value - 0.1).abs() < 1e-6);
    }

    #[test]
    fn a_log_map_spaces_its_points_by_decades() {
        let spec = PaletteSpec {
            palette: Palette::Magma,
            reversed: false,
        };
        let m = spec.colour_map("density", 1e-4, 1.0, None, true);
        assert!((m.points[SAMPLES / 2].value - 1e-2).abs() < 1e-6);
        // Not positive: even spacing.
        let m = spec.colour_map("q", -1.0, 1.0, None, true);
        assert!((m.points[SAMPLES / 2].value).abs() < 1e-6);
    }
}
