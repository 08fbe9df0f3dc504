//! The data's outline box: its twelve edges, hidden where a surface lies in front of them.

use super::canvas::Canvas;
use super::Style;
use crate::camera::RayGen;

/// Samples per pixel of an edge's length on screen when looking for where it hides.
const SAMPLES_PER_PIXEL: f64 = 2.0;

pub(super) fn draw(
    c: &mut Canvas,
    s: &Style,
    rays: &RayGen,
    lo: [f64; 3],
    hi: [f64; 3],
    depth: Option<&[f32]>,
) {
    let corner = |i: usize| -> [f64; 3] {
        std::array::from_fn(|a| if i >> a & 1 == 1 { hi[a] } else { lo[a] })
    };
    let (w, h) = (c.width, c.height);
    let width = 0.09 * s.font;
    let colour = [0.78, 0.8, 0.85];
    for i in 0..8usize {
        for a in 0..3 {
            if i >> a & 1 == 1 {
                continue;
            }
            let (p, q) = (corner(i), corner(i | 1 << a));
            // Screen length bound: both ends when both project, else the picture's size.
            let steps = match (rays.project(p), rays.project(q)) {
                (Some(u), Some(v)) => {
                    ((u.0 - v.0).hypot(u.1 - v.1) * SAMPLES_PER_PIXEL).ceil() as usize + 1
                }
                (None, None) => continue,
                _ => 2 * (w + h) as usize,
            }
            .min(64 * (w + h) as usize);
            // Runs of visible samples, each one straight line on screen.
            let mut run: Option<((f64, f64), (f64, f64))> = None;
            for k in 0..=steps {
                let t = k as f64 / steps as f64;
                let x: [f64; 3] = std::array::from_fn(|j| p[j] + t * (q[j] - p[j]));
                let seen = rays
                    .project(x)
                    .filter(|&(sx, sy, d)| visible(sx, sy, d, w, h, depth));
                match (seen, &mut run) {
                    (Some((sx, sy, _)), Some(r)) => r.1 = (sx, sy),
                    (Some((sx, sy, _)), None) => run = Some(((sx, sy), (sx, sy))),
                    (None, Some(r)) => {
                        c.line(r.0 .0, r.0 .1, r.1 .0, r.1 .1, width, colour, 0.75);
                        run = None;
                    }
                    (None, None) => {}
                }
            }
            if let Some(r) = run {
                c.line(r.0 .0, r.0 .1, r.1 .0, r.1 .1, width, colour, 0.75);
            }
        }
    }
}

/// Whether a point of the box at image position (`x`, `y`) and ray parameter `d` is in
/// front of the surface seen there (allowing a thousandth for round-off).
fn visible(x: f64, y: f64, d: f64, w: u32, h: u32, depth: Option<&[f32]>) -> bool {
    let Some(depth) = depth else {
        return true;
    };
    if x < 0.0 || y < 0.0 || x >= f64::from(w) || y >= f64::from(h) {
        // Off the picture: nothing hides it (and the line is clipped there anyway).
        return true;
    }
    let i = y as usize * w as usize + x as usize;
    depth
        .get(i)
        .is_none_or(|&s| !s.is_finite() || d <= f64::from(s) * (1.0 + 1e-3))
}
