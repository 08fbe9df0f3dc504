//! Colour by a second field (speed by default) through control points.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ControlPoint {
    pub value: f32,
    pub colour: [f32; 3],
}

/// A value within ±`band` of a control value takes its colour; between two control bands
/// colours interpolate linearly; outside the ends they clamp to the end colours.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColorMap {
    /// Name of the field that drives the colour (e.g. `speed`).
    pub field: String,
    /// Sorted by value.
    pub points: Vec<ControlPoint>,
    pub band: f32,
}

impl ColorMap {
    pub fn colour(&self, v: f32) -> [f32; 3] {
        let _ = v;
        unimplemented!("provisional stub: the scene helper writes this")
    }

    /// Blue/green/red over a field's range, so any data set looks reasonable on first open.
    pub fn default_for_range(field: &str, min: f32, max: f32) -> ColorMap {
        let _ = (field, min, max);
        unimplemented!("provisional stub: the scene helper writes this")
    }
}
