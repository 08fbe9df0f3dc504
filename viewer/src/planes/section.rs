//! Where a plane crosses a box: the polygon the overlays outline for each clip plane and
//! slice, and the plane's position along its normal that the window's sliders move.
//!
//! A plane cuts an axis-aligned box in a convex polygon of three to six corners (a square
//! for a plane across an axis, a hexagon for one square to a diagonal), or in nothing. The
//! polygon can be cut further by half-spaces (the other clip planes), which keeps it
//! convex.

use super::{dot, HalfSpace, Plane};

/// The corners of the polygon where `plane` crosses the box `lo..hi` (world), in order
/// around it; empty when the plane misses the box or only touches an edge or a corner.
/// A plane along a face of the box gives that face.
pub fn box_section(plane: &Plane, lo: [f64; 3], hi: [f64; 3]) -> Vec<[f64; 3]> {
    // A box whose sides are all at least zero (NaN is none).
    let a_box = (0..3).all(|a| lo[a] <= hi[a]);
    if plane.check().is_err() || !a_box {
        return Vec::new();
    }
    let h = HalfSpace::new(plane, [0.0; 3]);
    let corner = |i: usize| -> [f64; 3] {
        std::array::from_fn(|a| if i >> a & 1 == 1 { hi[a] } else { lo[a] })
    };
    let size = (0..3).fold(0.0f64, |m, a| m.max(hi[a] - lo[a]));
    // Corners this close to the plane are on it (round-off of the offset).
    let eps = 1e-12 * (size + h.c.abs()).max(f64::MIN_POSITIVE);
    let dist: [f64; 8] = std::array::from_fn(|i| {
        let d = h.distance(&corner(i));
        if d.abs() <= eps {
            0.0
        } else {
            d
        }
    });
    let mut points: Vec<[f64; 3]> = Vec::with_capacity(12);
    for (i, &d) in dist.iter().enumerate() {
        if d == 0.0 {
            points.push(corner(i));
        }
    }
    // Each of the twelve edges whose ends lie on opposite sides crosses the plane once.
    for i in 0..8usize {
        for a in 0..3 {
            if i >> a & 1 == 1 {
                continue;
            }
            let j = i | 1 << a;
            let (di, dj) = (dist[i], dist[j]);
            if di * dj < 0.0 {
                let t = di / (di - dj);
                let (p, q) = (corner(i), corner(j));
                points.push(std::array::from_fn(|k| p[k] + t * (q[k] - p[k])));
            }
        }
    }
    order_around(points, &h.n)
}

/// `polygon` (convex, its corners in order) cut to the side of `keep` its normal points
/// to (Sutherland–Hodgman against one plane); empty when nothing of it is on that side.
pub fn clip_polygon(polygon: &[[f64; 3]], keep: &HalfSpace) -> Vec<[f64; 3]> {
    let n = polygon.len();
    let mut out = Vec::with_capacity(n + 1);
    for k in 0..n {
        let (p, q) = (polygon[k], polygon[(k + 1) % n]);
        let (dp, dq) = (keep.distance(&p), keep.distance(&q));
        if dp >= 0.0 {
            out.push(p);
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            let t = dp / (dp - dq);
            out.push(std::array::from_fn(|a| p[a] + t * (q[a] - p[a])));
        }
    }
    if out.len() < 3 {
        out.clear();
    }
    out
}

/// The polygon of [`box_section`] cut by every half-space of `keep` (world frame).
pub fn clipped_section(
    plane: &Plane,
    lo: [f64; 3],
    hi: [f64; 3],
    keep: &[HalfSpace],
) -> Vec<[f64; 3]> {
    keep.iter()
        .fold(box_section(plane, lo, hi), |poly, h| clip_polygon(&poly, h))
}

/// Distinct points sorted by angle around their centroid in the plane of normal `n`;
/// fewer than three distinct points (a touching plane) give none.
fn order_around(mut points: Vec<[f64; 3]>, n: &[f64; 3]) -> Vec<[f64; 3]> {
    // Two directions in the plane: `u` across the normal's smallest component, `v = n×u`.
    let a = (0..3)
        .min_by(|&i, &j| n[i].abs().total_cmp(&n[j].abs()))
        .unwrap_or(0);
    let mut e = [0.0; 3];
    e[a] = 1.0;
    let u = normalize(cross(n, &e));
    let v = cross(n, &u);
    let scale = points
        .iter()
        .flatten()
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .max(f64::MIN_POSITIVE);
    let same = |p: &[f64; 3], q: &[f64; 3]| (0..3).all(|k| (p[k] - q[k]).abs() <= 1e-12 * scale);
    let mut distinct: Vec<[f64; 3]> = Vec::with_capacity(points.len());
    for p in points.drain(..) {
        if !distinct.iter().any(|q| same(&p, q)) {
            distinct.push(p);
        }
    }
    if distinct.len() < 3 {
        return Vec::new();
    }
    let m = distinct.len() as f64;
    let c: [f64; 3] = std::array::from_fn(|k| distinct.iter().map(|p| p[k]).sum::<f64>() / m);
    let angle = |p: &[f64; 3]| {
        let d: [f64; 3] = std::array::from_fn(|k| p[k] - c[k]);
        dot(&d, &v).atan2(dot(&d, &u))
    };
    distinct.sort_by(|p, q| angle(p).total_cmp(&angle(q)));
    distinct
}

impl Plane {
    /// The direction [`Plane::offset`] is measured along: the unit normal, turned round
    /// when its largest component is negative, so that `z>0.3` and `z<0.3` both lie at
    /// 0.3 and flipping a plane leaves its offset alone (the plane must pass
    /// [`Plane::check`]).
    pub fn direction(&self) -> [f64; 3] {
        let n = self.unit_normal();
        let largest = (0..3).fold(0, |b, a| if n[a].abs() > n[b].abs() { a } else { b });
        if n[largest] < 0.0 {
            n.map(|x| -x)
        } else {
            n
        }
    }

    /// The plane's position along its normal: `d·origin` for the [`Plane::direction`] `d`.
    pub fn offset(&self) -> f64 {
        dot(&self.direction(), &self.origin)
    }

    /// The plane moved along its normal to position `offset` ([`Plane::offset`]); the
    /// normal, and the origin's place within the plane, stay.
    pub fn with_offset(&self, offset: f64) -> Plane {
        let d = self.direction();
        let by = offset - self.offset();
        Plane {
            origin: std::array::from_fn(|a| self.origin[a] + by * d[a]),
            normal: self.normal,
        }
    }

    /// The positions along the plane's normal ([`Plane::offset`]) at which it meets the
    /// box `lo..hi`: from one of the box's corners furthest from it to the other.
    pub fn offset_range(&self, lo: [f64; 3], hi: [f64; 3]) -> (f64, f64) {
        let d = self.direction();
        let (mut a, mut b) = (0.0, 0.0);
        for k in 0..3 {
            let (x, y) = (d[k] * lo[k], d[k] * hi[k]);
            a += x.min(y);
            b += x.max(y);
        }
        (a, b)
    }

    /// The axis (0, 1, 2 for x, y, z) the normal lies along, if it does.
    pub fn axis(&self) -> Option<usize> {
        let along: Vec<usize> = (0..3).filter(|&a| self.normal[a] != 0.0).collect();
        match along.as_slice() {
            [a] => Some(*a),
            _ => None,
        }
    }

    /// The plane through the same origin across axis `axis` (0, 1, 2), its normal
    /// pointing the way the current one points along that axis (forwards when it is
    /// square to it).
    pub fn across_axis(&self, axis: usize) -> Plane {
        let mut normal = [0.0; 3];
        normal[axis.min(2)] = if self.normal[axis.min(2)] < 0.0 {
            -1.0
        } else {
            1.0
        };
        Plane {
            origin: self.origin,
            normal,
        }
    }

    /// The plane through `point` across the axis that the view direction `forward` runs
    /// most along, its normal pointing away from the camera: as a clip plane it keeps
    /// the half beyond `point` and opens the data up towards the viewer.
    pub fn facing_view(point: [f64; 3], forward: [f64; 3]) -> Plane {
        let axis = (0..3)
            .max_by(|&i, &j| forward[i].abs().total_cmp(&forward[j].abs()))
            .unwrap_or(2);
        let mut normal = [0.0; 3];
        normal[axis] = if forward[axis] < 0.0 { -1.0 } else { 1.0 };
        Plane {
            origin: point,
            normal,
        }
    }
}

fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = dot(&a, &a).sqrt();
    if l > 0.0 {
        a.map(|x| x / l)
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LO: [f64; 3] = [-1.0, -1.0, -1.0];
    const HI: [f64; 3] = [1.0, 1.0, 1.0];

    fn plane(origin: [f64; 3], normal: [f64; 3]) -> Plane {
        Plane { origin, normal }
    }

    fn close(a: &[f64; 3], b: &[f64; 3]) -> bool {
        (0..3).all(|k| (a[k] - b[k]).abs() < 1e-12)
    }

    /// Every corner on the plane and in the box, and consecutive corners turning one way
    /// (a convex polygon in order).
    fn check_polygon(poly: &[[f64; 3]], p: &Plane, lo: [f64; 3], hi: [f64; 3]) {
        let h = HalfSpace::new(p, [0.0; 3]);
        for c in poly {
            assert!(h.distance(c).abs() < 1e-12, "{c:?} is off the plane");
            assert!((0..3).all(|a| c[a] >= lo[a] - 1e-12 && c[a] <= hi[a] + 1e-12));
        }
        let m = poly.len();
        for k in 0..m {
            let (a, b, c) = (poly[k], poly[(k + 1) % m], poly[(k + 2) % m]);
            let e1: [f64; 3] = std::array::from_fn(|i| b[i] - a[i]);
            let e2: [f64; 3] = std::array::from_fn(|i| c[i] - b[i]);
            assert!(
                dot(&cross(&e1, &e2), &h.n) > 0.0,
                "not convex in order: {poly:?}"
            );
        }
    }

    #[test]
    fn a_plane_across_an_axis_through_the_centre_gives_a_square() {
        for axis in 0..3 {
            let mut n = [0.0; 3];
            n[axis] = 1.0;
            let p = plane([0.0; 3], n);
            let poly = box_section(&p, LO, HI);
            assert_eq!(poly.len(), 4, "axis {axis}: {poly:?}");
            check_polygon(&poly, &p, LO, HI);
            // The square's corners are the box's edge midpoints across that axis.
            for c in &poly {
                assert_eq!(c[axis], 0.0);
                assert!((0..3).filter(|&a| a != axis).all(|a| c[a].abs() == 1.0));
            }
            // Sides of length 2, diagonals of 2√2.
            for k in 0..4 {
                let (a, b) = (poly[k], poly[(k + 1) % 4]);
                let len = (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
                assert!((len - 2.0).abs() < 1e-12, "{len}");
            }
        }
    }

    #[test]
    fn an_oblique_plane_through_the_centre_gives_a_hexagon() {
        let p = plane([0.0; 3], [1.0, 1.0, 1.0]);
        let poly = box_section(&p, LO, HI);
        assert_eq!(poly.len(), 6, "{poly:?}");
        check_polygon(&poly, &p, LO, HI);
        // A regular hexagon: every side √2.
        for k in 0..6 {
            let (a, b) = (poly[k], poly[(k + 1) % 6]);
            let len = (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
            assert!((len - 2f64.sqrt()).abs() < 1e-12, "{len}");
        }
        // Near a corner the same normal cuts a triangle.
        let near = plane([0.8, 0.8, 0.8], [1.0, 1.0, 1.0]);
        let tri = box_section(&near, LO, HI);
        assert_eq!(tri.len(), 3, "{tri:?}");
        check_polygon(&tri, &near, LO, HI);
        // Tilted about one axis: a rectangle longer than the box is wide.
        let tilted = plane([0.0; 3], [1.0, 0.0, 0.5]);
        let rect = box_section(&tilted, LO, HI);
        assert_eq!(rect.len(), 4, "{rect:?}");
        check_polygon(&rect, &tilted, LO, HI);
    }

    #[test]
    fn a_plane_that_misses_or_touches_the_box_gives_nothing() {
        assert!(box_section(&plane([3.0, 0.0, 0.0], [1.0, 0.0, 0.0]), LO, HI).is_empty());
        assert!(box_section(&plane([0.0, 0.0, -5.0], [1.0, 1.0, 1.0]), LO, HI).is_empty());
        // Through one corner only, and along one edge only.
        assert!(box_section(&plane(HI, [1.0, 1.0, 1.0]), LO, HI).is_empty());
        assert!(box_section(&plane([1.0, 1.0, 0.0], [1.0, 1.0, 0.0]), LO, HI).is_empty());
        // Not a plane, not a box.
        assert!(box_section(&plane([0.0; 3], [0.0; 3]), LO, HI).is_empty());
        assert!(box_section(&plane([0.0; 3], [1.0, 0.0, 0.0]), HI, LO).is_empty());
    }

    #[test]
    fn a_plane_along_a_face_gives_the_face() {
        let p = plane([0.0, 0.0, 1.0], [0.0, 0.0, -1.0]);
        let poly = box_section(&p, LO, HI);
        assert_eq!(poly.len(), 4, "{poly:?}");
        for c in &poly {
            assert_eq!(c[2], 1.0);
            assert!(c[0].abs() == 1.0 && c[1].abs() == 1.0);
        }
        // In a box far from the origin, where the offset's round-off is larger.
        let (lo, hi) = ([1e6, 2e6, 3e6], [1e6 + 3.0, 2e6 + 1.0, 3e6 + 2.0]);
        let p = plane([0.0, 0.0, 3e6 + 2.0], [0.0, 0.0, 1.0]);
        assert_eq!(box_section(&p, lo, hi).len(), 4);
    }

    #[test]
    fn cutting_a_section_by_another_plane_keeps_its_side() {
        let p = plane([0.0; 3], [0.0, 0.0, 1.0]);
        let keep = HalfSpace::new(&plane([0.5, 0.0, 0.0], [1.0, 0.0, 0.0]), [0.0; 3]);
        let poly = clipped_section(&p, LO, HI, &[keep]);
        assert_eq!(poly.len(), 4, "{poly:?}");
        check_polygon(&poly, &p, LO, HI);
        assert!(poly.iter().all(|c| c[0] >= 0.5 - 1e-12));
        let xs: Vec<f64> = poly.iter().map(|c| c[0]).collect();
        assert!(xs.iter().any(|&x| (x - 0.5).abs() < 1e-12));
        assert!(xs.iter().any(|&x| (x - 1.0).abs() < 1e-12));
        // A half-space that keeps none of it, or all of it.
        let none = HalfSpace::new(&plane([2.0, 0.0, 0.0], [1.0, 0.0, 0.0]), [0.0; 3]);
        assert!(clipped_section(&p, LO, HI, &[none]).is_empty());
        let all = HalfSpace::new(&plane([-2.0, 0.0, 0.0], [1.0, 0.0, 0.0]), [0.0; 3]);
        assert_eq!(clipped_section(&p, LO, HI, &[all]), box_section(&p, LO, HI));
    }

    #[test]
    fn a_plane_moves_along_its_normal_over_the_box() {
        // Measured along +z whichever way the normal points, so flipping keeps it.
        let p = plane([0.2, 0.3, 0.4], [0.0, 0.0, -2.0]);
        assert_eq!(p.direction(), [0.0, 0.0, 1.0]);
        assert!((p.offset() - 0.4).abs() < 1e-15);
        assert_eq!(p.flipped().offset(), p.offset());
        let moved = p.with_offset(0.5);
        assert!(close(&moved.origin, &[0.2, 0.3, 0.5]));
        assert_eq!(moved.normal, p.normal);
        assert_eq!(p.offset_range(LO, HI), (-1.0, 1.0));
        let q = plane([0.0; 3], [0.2, -0.9, 0.1]);
        assert!(q.direction()[1] > 0.0 && q.direction()[0] < 0.0);
        let oblique = plane([0.0; 3], [1.0, 1.0, 0.0]);
        let (a, b) = oblique.offset_range(LO, [1.0, 3.0, 1.0]);
        let r = 0.5f64.sqrt();
        assert!(
            (a + 2.0 * r).abs() < 1e-12 && (b - 4.0 * r).abs() < 1e-12,
            "{a} {b}"
        );
        // The ends of the range touch the box, inside them the plane crosses it.
        let inside = oblique.with_offset(0.5 * (a + b));
        assert!(!box_section(&inside, LO, [1.0, 3.0, 1.0]).is_empty());
        let beyond = oblique.with_offset(b + 1e-9);
        assert!(box_section(&beyond, LO, [1.0, 3.0, 1.0]).is_empty());
    }

    #[test]
    fn axes_and_the_view() {
        let p = plane([1.0, 2.0, 3.0], [0.0, -3.0, 0.0]);
        assert_eq!(p.axis(), Some(1));
        assert_eq!(plane([0.0; 3], [1.0, 1.0, 0.0]).axis(), None);
        let x = p.across_axis(0);
        assert_eq!((x.origin, x.normal), ([1.0, 2.0, 3.0], [1.0, 0.0, 0.0]));
        // The sign along the axis is kept.
        assert_eq!(p.across_axis(1).normal, [0.0, -1.0, 0.0]);
        // Looking down from above and a little from the side: the plane across z,
        // normal pointing down (away from the camera).
        let v = Plane::facing_view([0.5, 0.5, 0.5], [0.3, -0.2, -1.0]);
        assert_eq!((v.origin, v.normal), ([0.5, 0.5, 0.5], [0.0, 0.0, -1.0]));
        let v = Plane::facing_view([0.0; 3], [2.0, 1.0, 0.5]);
        assert_eq!(v.normal, [1.0, 0.0, 0.0]);
    }
}
