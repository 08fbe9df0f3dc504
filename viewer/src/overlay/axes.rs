//! The axis triad: x red, y green, z blue, turning with the camera.

use super::canvas::{cap_height, text_width, Canvas};
use super::Style;
use crate::camera::RayGen;

const COLOURS: [[f32; 3]; 3] = [[0.95, 0.25, 0.2], [0.3, 0.85, 0.3], [0.3, 0.5, 1.0]];
const LABELS: [&str; 3] = ["x", "y", "z"];

pub(super) fn draw(c: &mut Canvas, s: &Style, rays: &RayGen) {
    let [right, up, forward] = rays.axes();
    let len = 2.6 * s.font;
    let ox = s.margin + len + 0.6 * s.font;
    let oy = f64::from(c.height) - s.margin - len - 0.6 * s.font;
    // Farthest axis first, so the nearer ones are drawn over it.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| forward[b].total_cmp(&forward[a]));
    for a in order {
        // World axis `a` on screen: its components along the camera's right and up.
        let (dx, dy) = (right[a], -up[a]);
        let (ex, ey) = (ox + len * dx, oy + len * dy);
        c.line(ox, oy, ex, ey, 0.16 * s.font, s.paper, 0.7);
        c.line(ox, oy, ex, ey, 0.1 * s.font, COLOURS[a], 1.0);
        let n = (dx * dx + dy * dy).sqrt();
        let (lx, ly) = if n > 1e-6 {
            (ex + 0.55 * s.font * dx / n, ey + 0.55 * s.font * dy / n)
        } else {
            (ex + 0.4 * s.font, ey - 0.4 * s.font)
        };
        let size = 0.9 * s.font;
        c.text_with_halo(
            lx - 0.5 * text_width(size, LABELS[a]),
            ly + 0.5 * cap_height(size),
            size,
            LABELS[a],
            COLOURS[a],
            s.paper,
            s.u.max(1.0),
        );
    }
}
