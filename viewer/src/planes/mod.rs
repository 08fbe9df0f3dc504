//! Planes that cut into the flow: clip planes, which remove the half-space behind them,
//! and slice planes, which show the colour field where they cross the data.
//!
//! Both are written `OX,OY,OZ:NX,NY,NZ` (a point on the plane and its normal) or, for a
//! plane across an axis, `x>1.5`, `z<0` (the side kept, or for a slice, the side its
//! normal points to). A clip keeps the side its normal points to. Rays meet planes
//! analytically: a clip plane shortens a ray's interval before any walk starts (so
//! empty-space skipping is untouched), and a slice is a single point along each ray.
//!
//! `section`: the polygon where a plane crosses the data's box (what the overlays
//! outline) and a plane's position along its normal (what the window's sliders move).

use serde::{Deserialize, Serialize};

mod section;
pub use section::{box_section, clip_polygon, clipped_section};

/// Most clip planes in one view: six make any box.
pub const MAX_CLIP_PLANES: usize = 6;
/// Most slice planes in one view.
pub const MAX_SLICES: usize = 3;

/// A plane through `origin` with normal `normal` (any non-zero length; world units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plane {
    pub origin: [f64; 3],
    pub normal: [f64; 3],
}

/// A slice plane: the colour field drawn where the plane crosses the data.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Slice {
    #[serde(flatten)]
    pub plane: Plane,
    /// 1 hides what lies behind the slice; less lets it show through.
    #[serde(default = "one")]
    pub opacity: f64,
    /// Draw the iso values' contour lines on the slice.
    #[serde(default)]
    pub contours: bool,
    /// Also remove what lies between the camera and the slice.
    #[serde(default)]
    pub clip: bool,
}

fn one() -> f64 {
    1.0
}

impl Slice {
    /// An opaque slice without contours that clips nothing.
    pub fn new(plane: Plane) -> Slice {
        Slice {
            plane,
            opacity: 1.0,
            contours: false,
            clip: false,
        }
    }
}

/// Why a plane spec or a plane is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlaneError {
    #[error(
        "expected OX,OY,OZ:NX,NY,NZ (a point and a normal) or an axis shorthand like \
         `x>1.5` or `z<0`, found `{0}`"
    )]
    Syntax(String),
    #[error("the origin {0:?} is not finite")]
    Origin([f64; 3]),
    #[error("the normal {0:?} is zero or not finite")]
    Normal([f64; 3]),
}

impl Plane {
    /// Checks that the plane is one: a finite origin and a finite non-zero normal.
    pub fn check(&self) -> Result<(), PlaneError> {
        if self.origin.iter().any(|x| !x.is_finite()) {
            return Err(PlaneError::Origin(self.origin));
        }
        let len2: f64 = self.normal.iter().map(|x| x * x).sum();
        // Scaled first, so that huge or tiny (but usable) normals are not refused by
        // an overflowing or underflowing square.
        let m = self.normal.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        if !(m > 0.0 && m.is_finite()) || len2.is_nan() {
            return Err(PlaneError::Normal(self.normal));
        }
        Ok(())
    }

    /// The unit normal (the plane must pass [`Plane::check`]).
    pub fn unit_normal(&self) -> [f64; 3] {
        let m = self.normal.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let n = self.normal.map(|x| x / m);
        let len = n.iter().map(|x| x * x).sum::<f64>().sqrt();
        n.map(|x| x / len)
    }

    /// The same plane with its normal turned round (a clip that keeps the other side).
    pub fn flipped(&self) -> Plane {
        Plane {
            origin: self.origin,
            normal: self.normal.map(|x| -x),
        }
    }
}

impl std::str::FromStr for Plane {
    type Err = PlaneError;

    /// `OX,OY,OZ:NX,NY,NZ`, or `x>V`, `x<V` (also `>=`, `<=`; axes x, y, z): the plane
    /// across that axis at V whose normal points to the side named.
    fn from_str(s: &str) -> Result<Plane, PlaneError> {
        let bad = || PlaneError::Syntax(s.to_string());
        let t = s.trim();
        let plane = if let Some((o, n)) = t.split_once(':') {
            let o = crate::probe::parse_xyz(o).map_err(|_| bad())?;
            let n = crate::probe::parse_xyz(n).map_err(|_| bad())?;
            Plane {
                origin: o,
                normal: n,
            }
        } else {
            let mut chars = t.chars();
            let axis = match chars.next().map(|c| c.to_ascii_lowercase()) {
                Some('x') => 0,
                Some('y') => 1,
                Some('z') => 2,
                _ => return Err(bad()),
            };
            let rest = chars.as_str().trim_start();
            let (sign, value) = if let Some(v) = rest.strip_prefix(">=") {
                (1.0, v)
            } else if let Some(v) = rest.strip_prefix("<=") {
                (-1.0, v)
            } else if let Some(v) = rest.strip_prefix('>') {
                (1.0, v)
            } else if let Some(v) = rest.strip_prefix('<') {
                (-1.0, v)
            } else {
                return Err(bad());
            };
            let v: f64 = value.trim().parse().map_err(|_| bad())?;
            let mut origin = [0.0; 3];
            let mut normal = [0.0; 3];
            origin[axis] = v;
            normal[axis] = sign;
            Plane { origin, normal }
        };
        plane.check()?;
        Ok(plane)
    }
}

/// A plane resolved for rays: unit normal `n` and offset `c = n·origin`, so a point `p`
/// is on the kept (normal) side when `n·p ≥ c`. In the volume's local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HalfSpace {
    pub n: [f64; 3],
    pub c: f64,
}

impl HalfSpace {
    /// `plane` in a frame whose origin is the world point `frame` (the volume's local
    /// frame: local = world − frame).
    pub fn new(plane: &Plane, frame: [f64; 3]) -> HalfSpace {
        let n = plane.unit_normal();
        let o: [f64; 3] = std::array::from_fn(|a| plane.origin[a] - frame[a]);
        HalfSpace { n, c: dot(&n, &o) }
    }

    /// Signed distance of `p` from the plane, positive on the kept side.
    #[inline]
    pub fn distance(&self, p: &[f64; 3]) -> f64 {
        dot(&self.n, p) - self.c
    }

    /// Where the ray `o + t d` crosses the plane (`None` when parallel to it).
    #[inline]
    pub fn crossing(&self, o: &[f64; 3], d: &[f64; 3]) -> Option<f64> {
        let nd = dot(&self.n, d);
        if nd == 0.0 {
            return None;
        }
        let t = -self.distance(o) / nd;
        t.is_finite().then_some(t)
    }

    /// `[t0, t1]` cut to the part of the ray `o + t d` on the kept side; `None` when
    /// nothing of it is. A ray in the plane is kept.
    #[inline]
    pub fn clip(&self, o: &[f64; 3], d: &[f64; 3], t0: f64, t1: f64) -> Option<(f64, f64)> {
        let s0 = self.distance(o);
        let nd = dot(&self.n, d);
        let (mut lo, mut hi) = (t0, t1);
        if nd > 0.0 {
            lo = lo.max(-s0 / nd);
        } else if nd < 0.0 {
            hi = hi.min(-s0 / nd);
        } else if s0 < 0.0 {
            return None;
        }
        // `lo == hi` keeps a ray that only touches the kept side (a grazing ray): it
        // meets nothing but the background there, like any empty interval.
        (lo <= hi).then_some((lo, hi))
    }
}

#[inline]
fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `[t0, t1]` cut by every half-space of `clips`: a convex set, so one interval.
pub fn clip_interval(
    clips: &[HalfSpace],
    o: &[f64; 3],
    d: &[f64; 3],
    t0: f64,
    t1: f64,
) -> Option<(f64, f64)> {
    clips
        .iter()
        .try_fold((t0, t1), |(a, b), h| h.clip(o, d, a, b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse() {
        let p: Plane = "1,2,3:0,0,2".parse().unwrap();
        assert_eq!(p.origin, [1.0, 2.0, 3.0]);
        assert_eq!(p.unit_normal(), [0.0, 0.0, 1.0]);
        let p: Plane = "x>1.5".parse().unwrap();
        assert_eq!((p.origin, p.normal), ([1.5, 0.0, 0.0], [1.0, 0.0, 0.0]));
        let p: Plane = "z < -0.25".parse().unwrap();
        assert_eq!((p.origin, p.normal), ([0.0, 0.0, -0.25], [0.0, 0.0, -1.0]));
        let p: Plane = "Y>=2".parse().unwrap();
        assert_eq!(p.normal, [0.0, 1.0, 0.0]);
        for bad in [
            "",
            "w>1",
            "x=1",
            "x>",
            "x>nan",
            "1,2:0,0,1",
            "0,0,0:0,0,0",
            "0,0,0:1,inf,0",
        ] {
            assert!(bad.parse::<Plane>().is_err(), "{bad}");
        }
        assert_eq!(
            "0,0,0:0,0,0".parse::<Plane>(),
            Err(PlaneError::Normal([0.0; 3]))
        );
    }

    #[test]
    fn tiny_and_huge_normals_are_unit() {
        for s in [1e-300, 1e300] {
            let p = Plane {
                origin: [0.0; 3],
                normal: [s, s, 0.0],
            };
            p.check().unwrap();
            let n = p.unit_normal();
            assert!((n[0] - 0.5f64.sqrt()).abs() < 1e-15 && n[2] == 0.0, "{n:?}");
        }
    }

    #[test]
    fn clipping_keeps_the_normal_side() {
        let h = HalfSpace::new(&"x>1".parse().unwrap(), [0.0; 3]);
        // Along +x from 0: kept from t = 1 on.
        assert_eq!(
            h.clip(&[0.0; 3], &[1.0, 0.0, 0.0], 0.0, 5.0),
            Some((1.0, 5.0))
        );
        // Along −x from 3: kept until t = 2.
        assert_eq!(
            h.clip(&[3.0, 0.0, 0.0], &[-1.0, 0.0, 0.0], 0.0, 5.0),
            Some((0.0, 2.0))
        );
        // Parallel: all or nothing.
        assert_eq!(
            h.clip(&[2.0, 0.0, 0.0], &[0.0, 1.0, 0.0], 0.0, 5.0),
            Some((0.0, 5.0))
        );
        assert_eq!(h.clip(&[0.0; 3], &[0.0, 1.0, 0.0], 0.0, 5.0), None);
        // In a local frame offset by (1, 0, 0), the plane is at local x = 0.
        let h = HalfSpace::new(&"x>1".parse().unwrap(), [1.0, 0.0, 0.0]);
        assert_eq!(h.crossing(&[-1.0, 0.0, 0.0], &[1.0, 0.0, 0.0]), Some(1.0));
        // Two planes facing each other leave the slab between them.
        let slab = [
            HalfSpace::new(&"x>1".parse().unwrap(), [0.0; 3]),
            HalfSpace::new(&"x<2".parse().unwrap(), [0.0; 3]),
        ];
        assert_eq!(
            clip_interval(&slab, &[0.0; 3], &[1.0, 0.0, 0.0], 0.0, 9.0),
            Some((1.0, 2.0))
        );
        let apart = [
            HalfSpace::new(&"x>2".parse().unwrap(), [0.0; 3]),
            HalfSpace::new(&"x<1".parse().unwrap(), [0.0; 3]),
        ];
        assert_eq!(
            clip_interval(&apart, &[0.0; 3], &[1.0, 0.0, 0.0], 0.0, 9.0),
            None
        );
    }
}
