//! The scale bar: a round length in world units, true everywhere in an orthographic view
//! and at the pivot's depth in a perspective one (which its label says).

use super::canvas::{text_width, Canvas};
use super::ticks::format_value;
use super::Style;
use crate::camera::RayGen;

pub(super) fn draw(c: &mut Canvas, s: &Style, rays: &RayGen, pivot: [f64; 3]) {
    let depth = if rays.is_orthographic() {
        1.0
    } else {
        // The pivot's distance along the view (not along its ray): the pixel size of the
        // plane through it, parallel to the picture.
        let [_, _, f] = rays.axes();
        let e = rays.eye();
        let d: f64 = (0..3).map(|a| f[a] * (pivot[a] - e[a])).sum();
        if d.is_nan() || d <= 0.0 {
            return;
        }
        d
    };
    let px = rays.pixel_size_at(depth);
    let w = f64::from(c.width);
    let target = 0.18 * w * px;
    if !(target.is_finite() && target > 0.0) {
        return;
    }
    let length = round_down(target);
    let len_px = length / px;
    let x1 = w - s.margin;
    let x0 = x1 - len_px;
    let y = f64::from(c.height) - s.margin - 0.3 * s.font;
    let tick = 0.35 * s.font;
    for (xa, ya, xb, yb) in [(x0, y, x1, y), (x0, y - tick, x0, y), (x1, y - tick, x1, y)] {
        c.line(xa, ya, xb, yb, 0.2 * s.font, s.paper, 0.7);
        c.line(xa, ya, xb, yb, 0.1 * s.font, s.ink, 1.0);
    }
    let label = if rays.is_orthographic() {
        format_value(length)
    } else {
        format!("{} at pivot", format_value(length))
    };
    let size = 0.9 * s.font;
    let lw = text_width(size, &label);
    c.text_with_halo(
        (0.5 * (x0 + x1) - 0.5 * lw).min(x1 - lw),
        y - tick - 0.35 * s.font,
        size,
        &label,
        s.ink,
        s.paper,
        s.u.max(1.0),
    );
}

/// The largest 1, 2 or 5 × 10ᵏ not above `v` (> 0).
fn round_down(v: f64) -> f64 {
    let mag = 10f64.powf(v.log10().floor());
    let m = v / mag;
    let r = if m >= 5.0 {
        5.0
    } else if m >= 2.0 {
        2.0
    } else {
        1.0
    };
    r * mag
}

#[cfg(test)]
mod tests {
    #[test]
    fn bars_are_round_lengths() {
        assert_eq!(super::round_down(0.73), 0.5);
        assert_eq!(super::round_down(2.0), 2.0);
        assert_eq!(super::round_down(19.9), 10.0);
        assert!((super::round_down(0.0042) - 0.002).abs() < 1e-15);
    }
}
