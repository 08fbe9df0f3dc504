//! Colour by a second field (speed by default) through control points.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlPoint {
    pub value: f32,
    pub colour: [f32; 3],
}

/// A value within ±`band` of a control value takes its colour; between two control bands
/// colours interpolate linearly; outside the ends they clamp to the end colours.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColorMap {
    /// Name of the field that drives the colour (e.g. `speed`).
    pub field: String,
    /// Sorted by value.
    pub points: Vec<ControlPoint>,
    pub band: f32,
}

pub(crate) const BLUE: [f32; 3] = [0.1, 0.25, 0.95];
pub(crate) const GREEN: [f32; 3] = [0.1, 0.8, 0.2];
pub(crate) const RED: [f32; 3] = [0.95, 0.15, 0.1];
/// Colour of a map without control points, and of NaN values.
pub(crate) const NEUTRAL: [f32; 3] = [0.75, 0.75, 0.75];

fn lerp(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

/// The range of the colour field over what a picture shows: the finite values of its
/// surface pixels ([`crate::render::Frame::surface_values`]). `None` when no pixel shows
/// a surface, or they all show one value (no range to spread a map over).
pub fn visible_range(values: &[f32]) -> Option<(f32, f32)> {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    (lo < hi).then_some((lo, hi))
}

/// A field's range as every data-derived default reads it (the colour map here, the iso
/// value and band in [`crate::view_state`]): sorted, infinities taken as ±`f32::MAX` (the
/// baker stores overflowing values so; a file written otherwise may still carry them) and
/// a NaN bound as the other one (0 when both are), so that nothing derived from a file's
/// ranges is a number no user could have written into a view state.
pub(crate) fn finite_range(min: f32, max: f32) -> (f32, f32) {
    let clamp = |v: f32| v.clamp(-f32::MAX, f32::MAX);
    let (a, b) = match (min.is_nan(), max.is_nan()) {
        (false, false) => (clamp(min), clamp(max)),
        (true, false) => (clamp(max), clamp(max)),
        (false, true) => (clamp(min), clamp(min)),
        (true, true) => (0.0, 0.0),
    };
    (a.min(b), a.max(b))
}

impl ColorMap {
    /// Colour of value `v`.
    ///
    /// If two bands overlap (control values closer than `2·band`), the lower control
    /// point wins in the overlap. A NaN value, or a map without
    /// points, gives [`NEUTRAL`]. `points` must be sorted by value ([`ColorMap::validate`]).
    pub fn colour(&self, v: f32) -> [f32; 3] {
        let (Some(first), Some(last)) = (self.points.first(), self.points.last()) else {
            return NEUTRAL;
        };
        if v.is_nan() {
            return NEUTRAL;
        }
        let band = if self.band.is_finite() {
            self.band.max(0.0)
        } else {
            0.0
        };
        if v <= first.value + band {
            return first.colour;
        }
        if v >= last.value - band {
            return last.colour;
        }
        // First point whose value exceeds v; 1 ≤ i < len because of the clamps above.
        let i = self.points.partition_point(|p| p.value <= v);
        let (Some(a), Some(b)) = (self.points.get(i.wrapping_sub(1)), self.points.get(i)) else {
            return last.colour;
        };
        let lo = a.value + band;
        let hi = b.value - band;
        if v <= lo {
            return a.colour;
        }
        if v >= hi {
            return b.colour;
        }
        // lo < v < hi here, so hi - lo > 0.
        lerp(a.colour, b.colour, (v - lo) / (hi - lo))
    }

    /// The values of the first and last control points (`0..1` for a map without any).
    pub fn range(&self) -> (f32, f32) {
        match (self.points.first(), self.points.last()) {
            (Some(a), Some(b)) => (a.value, b.value),
            _ => (0.0, 1.0),
        }
    }

    /// Blue/green/red over a field's range, so any data set looks reasonable on first open.
    ///
    /// Control points at the minimum, the middle and the maximum; the band is 2 % of the
    /// range. Swapped or non-finite limits are repaired (non-finite → 0..1).
    pub(crate) fn default_for_range(field: &str, min: f32, max: f32) -> ColorMap {
        let (lo, hi) = finite_range(min, max);
        // A range as wide as f32 allows (a field whose overflowing values the baker
        // stored as ±f32::MAX) has a width beyond f32: then in f64, since a middle or a
        // band of infinite width is no state a user could have written.
        let width = hi - lo;
        let (mid, band) = if width.is_finite() {
            (lo + 0.5 * width, 0.02 * width)
        } else {
            let (lo, hi) = (f64::from(lo), f64::from(hi));
            ((0.5 * lo + 0.5 * hi) as f32, (0.02 * (hi - lo)) as f32)
        };
        ColorMap {
            field: field.to_string(),
            points: vec![
                ControlPoint {
                    value: lo,
                    colour: BLUE,
                },
                ControlPoint {
                    value: mid,
                    colour: GREEN,
                },
                ControlPoint {
                    value: hi,
                    colour: RED,
                },
            ],
            band,
        }
    }

    /// The seed report's speed colouring: 0.012 blue, 0.025 green, 0.072 red, ±0.0025.
    #[cfg(test)]
    pub(crate) fn seed_report() -> ColorMap {
        ColorMap {
            field: "speed".to_string(),
            points: vec![
                ControlPoint {
                    value: 0.012,
                    colour: BLUE,
                },
                ControlPoint {
                    value: 0.025,
                    colour: GREEN,
                },
                ControlPoint {
                    value: 0.072,
                    colour: RED,
                },
            ],
            band: 0.0025,
        }
    }

    /// Checks what serde cannot: finite, sorted values, a finite non-negative band,
    /// colours in 0..=1.
    pub fn validate(&self) -> Result<(), ColorMapError> {
        if !(self.band.is_finite() && self.band >= 0.0) {
            return Err(ColorMapError::Band { band: self.band });
        }
        if self.points.is_empty() {
            return Err(ColorMapError::NoPoints);
        }
        for (index, p) in self.points.iter().enumerate() {
            if !p.value.is_finite() {
                return Err(ColorMapError::Value {
                    index,
                    value: p.value,
                });
            }
            if p.colour.iter().any(|c| !(0.0..=1.0).contains(c)) {
                return Err(ColorMapError::Colour {
                    index,
                    colour: p.colour,
                });
            }
        }
        for (i, w) in self.points.windows(2).enumerate() {
            if let [a, b] = w {
                if b.value < a.value {
                    return Err(ColorMapError::Unsorted {
                        index: i + 1,
                        value: b.value,
                        previous: a.value,
                    });
                }
            }
        }
        Ok(())
    }
}

/// Why a colour map is refused. The message names the offending entry, so a view state's
/// error can prefix `colormap.`.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ColorMapError {
    #[error("band: expected a finite number ≥ 0, found {band}")]
    Band { band: f32 },
    #[error("points: expected at least one control point, found none")]
    NoPoints,
    #[error("points[{index}].value: not finite ({value})")]
    Value { index: usize, value: f32 },
    #[error("points[{index}].colour: expected components in 0..=1, found {colour:?}")]
    Colour { index: usize, colour: [f32; 3] },
    /// `points[index]` lies below the point before it.
    #[error(
        "points[{index}].value {value} is below points[{}].value {previous}: points must be sorted",
        .index - 1
    )]
    Unsorted {
        index: usize,
        value: f32,
        previous: f32,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f32; 3], b: [f32; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5)
    }

    #[test]
    fn bands_take_the_control_colour() {
        let m = ColorMap::seed_report();
        for (v, c) in [
            (0.012, BLUE),
            (0.012 + 0.0024, BLUE),
            (0.012 - 0.0024, BLUE),
            (0.025, GREEN),
            (0.0226, GREEN),
            (0.0274, GREEN),
            (0.072, RED),
            (0.0696, RED),
        ] {
            assert!(close(m.colour(v), c), "{v}: {:?}", m.colour(v));
        }
    }

    #[test]
    fn between_bands_interpolates_linearly() {
        let m = ColorMap::seed_report();
        // Blue band ends at 0.0145, green band starts at 0.0225: midpoint 0.0185.
        assert!(close(m.colour(0.0185), lerp(BLUE, GREEN, 0.5)));
        assert!(close(m.colour(0.0165), lerp(BLUE, GREEN, 0.25)));
        // Green band ends at 0.0275, red starts at 0.0695.
        let v = 0.0275 + 0.3 * (0.0695 - 0.0275);
        assert!(close(m.colour(v), lerp(GREEN, RED, 0.3)));
        // Continuity at band edges.
        for edge in [0.0145f32, 0.0225, 0.0275, 0.0695] {
            let a = m.colour(edge - 1e-6);
            let b = m.colour(edge + 1e-6);
            assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-3), "{edge}");
        }
    }

    #[test]
    fn outside_clamps_to_end_colours() {
        let m = ColorMap::seed_report();
        assert_eq!(m.colour(-5.0), BLUE);
        assert_eq!(m.colour(0.0), BLUE);
        assert_eq!(m.colour(1.0), RED);
        assert_eq!(m.colour(f32::INFINITY), RED);
        assert_eq!(m.colour(f32::NEG_INFINITY), BLUE);
        assert_eq!(m.colour(f32::NAN), NEUTRAL);
    }

    #[test]
    fn overlapping_bands_and_empty_maps_do_not_break() {
        let mut m = ColorMap::seed_report();
        m.band = 0.5; // every band overlaps every other
        for v in [-1.0, 0.0, 0.02, 0.03, 0.05, 0.1] {
            let c = m.colour(v);
            assert!(c.iter().all(|x| x.is_finite()));
        }
        m.points.clear();
        assert_eq!(m.colour(0.1), NEUTRAL);
        let one = ColorMap {
            field: "speed".into(),
            points: vec![ControlPoint {
                value: 1.0,
                colour: GREEN,
            }],
            band: 0.0,
        };
        assert_eq!(one.colour(-3.0), GREEN);
        assert_eq!(one.colour(3.0), GREEN);
    }

    #[test]
    fn default_for_range_spans_the_range() {
        let m = ColorMap::default_for_range("speed", 2.0, 10.0);
        assert_eq!(m.field, "speed");
        assert_eq!(m.colour(2.0), BLUE);
        assert_eq!(m.colour(6.0), GREEN);
        assert_eq!(m.colour(10.0), RED);
        assert!(m.validate().is_ok());
        // swapped, constant and non-finite ranges
        let s = ColorMap::default_for_range("s", 10.0, 2.0);
        assert_eq!(s.points[0].value, 2.0);
        let c = ColorMap::default_for_range("c", 3.0, 3.0);
        assert_eq!(c.colour(3.0), BLUE);
        assert!(c.validate().is_ok());
        let n = ColorMap::default_for_range("n", f32::NAN, 1.0);
        assert!(n.validate().is_ok());
        let i = ColorMap::default_for_range("i", f32::NEG_INFINITY, f32::INFINITY);
        assert!(i.validate().is_ok(), "{i:?}");
        assert_eq!(finite_range(f32::INFINITY, 2.0), (2.0, f32::MAX));
        assert_eq!(finite_range(f32::NAN, f32::NAN), (0.0, 0.0));
        // The widest finite range (values that overflowed, stored clamped) still gives a
        // valid map: its width overflows f32.
        let w = ColorMap::default_for_range("q", -f32::MAX, f32::MAX);
        assert!(w.validate().is_ok(), "{w:?}");
        assert_eq!(w.colour(0.0), GREEN);
    }

    /// Caught by the `sequence_state` fuzz target's check of the default state (on a
    /// written input, not by mutation): a manifest range from -3e38 to 3e38 made the
    /// default colour map's middle and band infinite, so a sequence without a state file
    /// failed with `view state: colormap.band: … found inf`.
    #[test]
    fn default_for_range_wider_than_f32_max_is_valid() {
        for (lo, hi) in [(-3e38, 3e38), (f32::MIN, f32::MAX), (-f32::MAX, 1.0)] {
            let m = ColorMap::default_for_range("q", lo, hi);
            assert_eq!(m.validate(), Ok(()), "{lo} … {hi}: {m:?}");
            assert_eq!((m.points[0].value, m.points[2].value), (lo, hi));
            assert!(lo <= m.points[1].value && m.points[1].value <= hi, "{m:?}");
            assert!(m.band > 0.0, "{m:?}");
            assert_eq!(m.colour(lo), BLUE);
            assert_eq!(m.colour(hi), RED);
        }
    }

    #[test]
    fn validate_names_the_problem() {
        let mut m = ColorMap::seed_report();
        m.points.swap(0, 1);
        assert!(matches!(
            m.validate(),
            Err(ColorMapError::Unsorted { index: 1, .. })
        ));
        let mut m = ColorMap::seed_report();
        m.band = -1.0;
        assert!(matches!(m.validate(), Err(ColorMapError::Band { .. })));
        let mut m = ColorMap::seed_report();
        m.points[2].colour = [2.0, 0.0, 0.0];
        assert!(matches!(
            m.validate(),
            Err(ColorMapError::Colour { index: 2, .. })
        ));
    }
}
