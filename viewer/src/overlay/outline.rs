//! The data's outline box: its twelve edges, and the outlines of the clip planes and
//! slices where they cross it; all hidden where a surface lies in front of them.

use super::canvas::Canvas;
use super::Style;
use crate::camera::RayGen;
use crate::planes::{clipped_section, HalfSpace, Plane, Slice};

/// Samples per pixel of an edge's length on screen when looking for where it hides.
const SAMPLES_PER_PIXEL: f64 = 2.0;

/// The box's edges: a little brighter than the planes' outlines.
const BOX: Ink = Ink {
    colour: [0.78, 0.8, 0.85],
    alpha: 0.75,
    width: 0.09,
    slack: 1e-3,
};
/// A clip plane's outline: faint, warm.
const CLIP: Ink = Ink {
    colour: [1.0, 0.78, 0.5],
    alpha: 0.45,
    width: 0.07,
    slack: 1e-2,
};
/// A slice's outline: a little brighter than a clip plane's, cool.
const SLICE: Ink = Ink {
    colour: [0.62, 0.88, 1.0],
    alpha: 0.6,
    width: 0.07,
    slack: 1e-2,
};

/// How an outline is drawn.
struct Ink {
    colour: [f32; 3],
    alpha: f32,
    /// Line width in units of the overlay's font size.
    width: f64,
    /// How far behind the surface seen at a pixel (relative to its distance) an outline
    /// still shows. A plane's outline runs along the slice it outlines, whose distance at
    /// a pixel's centre differs from the outline's by the slope across the pixel.
    slack: f64,
}

/// The box `lo..hi`: its twelve edges.
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
    for i in 0..8usize {
        for a in 0..3 {
            if i >> a & 1 == 0 {
                edge(c, s, rays, corner(i), corner(i | 1 << a), depth, &BOX);
            }
        }
    }
}

/// Where the clip planes and slices cross the box `lo..hi`: each one's polygon, cut to
/// what the clip planes keep (a clip plane's by the others), so the outlines trace the
/// faces the planes cut and the slices as drawn.
#[allow(clippy::too_many_arguments)]
pub(super) fn planes(
    c: &mut Canvas,
    s: &Style,
    rays: &RayGen,
    lo: [f64; 3],
    hi: [f64; 3],
    clip: &[Plane],
    slices: &[Slice],
    depth: Option<&[f32]>,
) {
    let keep: Vec<Option<HalfSpace>> = clip
        .iter()
        .map(|p| p.check().ok().map(|()| HalfSpace::new(p, [0.0; 3])))
        .collect();
    let others = |skip: Option<usize>| -> Vec<HalfSpace> {
        keep.iter()
            .enumerate()
            .filter(|&(i, _)| Some(i) != skip)
            .filter_map(|(_, h)| *h)
            .collect()
    };
    let outlines = clip
        .iter()
        .enumerate()
        .map(|(i, p)| (p, others(Some(i)), &CLIP))
        .chain(slices.iter().map(|sl| (&sl.plane, others(None), &SLICE)));
    for (plane, keep, ink) in outlines {
        let poly = clipped_section(plane, lo, hi, &keep);
        for k in 0..poly.len() {
            edge(c, s, rays, poly[k], poly[(k + 1) % poly.len()], depth, ink);
        }
    }
}

/// One straight edge from `p` to `q` (world), hidden where a surface lies in front of it.
fn edge(
    c: &mut Canvas,
    s: &Style,
    rays: &RayGen,
    p: [f64; 3],
    q: [f64; 3],
    depth: Option<&[f32]>,
    ink: &Ink,
) {
    let (w, h) = (c.width, c.height);
    let width = ink.width * s.font;
    // Screen length bound: both ends when both project, else the picture's size.
    let steps = match (rays.project(p), rays.project(q)) {
        (Some(u), Some(v)) => {
            ((u.0 - v.0).hypot(u.1 - v.1) * SAMPLES_PER_PIXEL).ceil() as usize + 1
        }
        (None, None) => return,
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
            .filter(|&(sx, sy, d)| visible(sx, sy, d, w, h, depth, ink.slack));
        match (seen, &mut run) {
            (Some((sx, sy, _)), Some(r)) => r.1 = (sx, sy),
            (Some((sx, sy, _)), None) => run = Some(((sx, sy), (sx, sy))),
            (None, Some(r)) => {
                c.line(r.0 .0, r.0 .1, r.1 .0, r.1 .1, width, ink.colour, ink.alpha);
                run = None;
            }
            (None, None) => {}
        }
    }
    if let Some(r) = run {
        c.line(r.0 .0, r.0 .1, r.1 .0, r.1 .1, width, ink.colour, ink.alpha);
    }
}

/// Whether a point of an outline at image position (`x`, `y`) and ray parameter `d` is
/// in front of the surface seen there (allowing `slack` of its distance).
fn visible(x: f64, y: f64, d: f64, w: u32, h: u32, depth: Option<&[f32]>, slack: f64) -> bool {
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
        .is_none_or(|&s| !s.is_finite() || d <= f64::from(s) * (1.0 + slack))
}
