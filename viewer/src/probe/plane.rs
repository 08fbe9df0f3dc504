//! A plane sampled on a regular grid (`qbricks-view probe --plane`): the patch, where its
//! samples lie, and every chosen field at each of them, reconstructed as `probe` reports a
//! point (bit for bit: both read [`Volume::values_at`]).
//!
//! # The patch and its samples
//!
//! A patch is an origin corner `O` and two edge vectors `U` and `V` (world coordinates;
//! their lengths are the patch's extent, and they need not be orthogonal, only not
//! parallel). On a grid of `NU` × `NV` samples, sample `(i, j)` lies at the centre of its
//! cell:
//!
//! ```text
//! p(i, j) = O + (i + 0.5) / NU · U + (j + 0.5) / NV · V      0 ≤ i < NU, 0 ≤ j < NV
//! ```
//!
//! so the samples tile the patch the way an `NU` × `NV` image's pixels do (an image of them
//! shows exactly the patch, `extent` = the patch), and none lies on a far edge: a patch over
//! the data's bounds, whose far faces are outside the (half-open) data, has no column of
//! NaN there.
//!
//! # Layout
//!
//! Samples are kept row by row, `j` the slow index, then `i`, then the field:
//! value `[j][i][f]`, the C-order array of shape `(NV, NU, nfields)` that a `.npy` output
//! holds (row `j = 0` is the one along `O`…`O + U`).

use rayon::prelude::*;

use super::{parse_xyz, PointError};
use crate::volume::Volume;
use files::limits::LimitError;

/// Longer side of the grid when `--resolution` is not given (the shorter keeps the aspect).
pub const DEFAULT_LONGER_SIDE: u64 = 256;

/// A parallelogram patch of a plane: an origin corner and two edge vectors (world
/// coordinates). Built by [`Plane::new`], which refuses degenerate patches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub origin: [f64; 3],
    pub u: [f64; 3],
    pub v: [f64; 3],
}

/// Why a plane is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlaneError {
    #[error(
        "expected OX,OY,OZ:UX,UY,UZ:VX,VY,VZ (an origin and two edge vectors) or x=C, y=C, \
         z=C, found `{text}`"
    )]
    Form { text: String },
    /// The origin or one edge vector (`part`: `origin`, `U`, `V`).
    #[error("{part}: {error}")]
    Part {
        part: &'static str,
        error: PointError,
    },
    #[error("{axis}={text}: expected a finite coordinate")]
    Coordinate { axis: char, text: String },
    #[error("{part} {vector:?} has zero length")]
    ZeroAxis {
        part: &'static str,
        vector: [f64; 3],
    },
    #[error("U {u:?} and V {v:?} are parallel: they span no plane")]
    Parallel { u: [f64; 3], v: [f64; 3] },
    /// A corner of the patch overflows.
    #[error(
        "the patch's corner {corner:?} is not finite: coordinates too close to the largest f64"
    )]
    NotFinite { corner: [f64; 3] },
    /// `x=C` on data without extent along one of the other two axes.
    #[error("{axis}={at}: the data has no extent along {along}, so the plane has no area")]
    Flat { axis: char, at: f64, along: char },
}

/// A plane as given: explicit, or across one axis over the data's extent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlaneSpec {
    /// `OX,OY,OZ:UX,UY,UZ:VX,VY,VZ`.
    Explicit(Plane),
    /// `x=C`, `y=C` or `z=C` (`axis` 0, 1, 2): the data's bounds in the other two axes at
    /// that coordinate; `U` along the first of them in `x, y, z` order, `V` along the
    /// second (`z=C`: `U` along x, `V` along y; `y=C`: x, z; `x=C`: y, z).
    Axis { axis: usize, at: f64 },
}

const AXES: [char; 3] = ['x', 'y', 'z'];

impl PlaneSpec {
    /// Parses `OX,OY,OZ:UX,UY,UZ:VX,VY,VZ` (checked by [`Plane::new`]) or `x=C`, `y=C`,
    /// `z=C` (either case).
    pub fn parse(s: &str) -> Result<PlaneSpec, PlaneError> {
        let form = || PlaneError::Form {
            text: s.to_string(),
        };
        if let Some((name, at)) = s.split_once('=') {
            let name = name.trim().to_ascii_lowercase();
            let axis = AXES
                .iter()
                .position(|a| name.len() == 1 && name.starts_with(*a))
                .ok_or_else(form)?;
            let at = match at.trim().parse::<f64>() {
                Ok(c) if c.is_finite() => c,
                _ => {
                    return Err(PlaneError::Coordinate {
                        axis: AXES[axis],
                        text: at.trim().to_string(),
                    })
                }
            };
            return Ok(PlaneSpec::Axis { axis, at });
        }
        let parts: Vec<&str> = s.split(':').collect();
        let [o, u, v] = parts[..] else {
            return Err(form());
        };
        let part = |part: &'static str, text: &str| {
            parse_xyz(text).map_err(|error| PlaneError::Part { part, error })
        };
        Plane::new(part("origin", o)?, part("U", u)?, part("V", v)?).map(PlaneSpec::Explicit)
    }

    /// The patch, given the data's world bounds (used by the `x=C` form only).
    pub fn resolve(&self, world_min: [f64; 3], world_max: [f64; 3]) -> Result<Plane, PlaneError> {
        let (axis, at) = match *self {
            PlaneSpec::Explicit(p) => return Ok(p),
            PlaneSpec::Axis { axis, at } => (axis, at),
        };
        let [a, b] = match axis {
            0 => [1, 2],
            1 => [0, 2],
            _ => [0, 1],
        };
        let mut origin = world_min;
        origin[axis] = at;
        let edge = |k: usize| {
            let mut e = [0.0; 3];
            e[k] = world_max[k] - world_min[k];
            e
        };
        for k in [a, b] {
            if world_max[k] - world_min[k] <= 0.0 {
                return Err(PlaneError::Flat {
                    axis: AXES[axis],
                    at,
                    along: AXES[k],
                });
            }
        }
        Plane::new(origin, edge(a), edge(b))
    }
}

/// Largest absolute component of `a` (0 for the zero vector).
fn max_abs(a: [f64; 3]) -> f64 {
    a.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// Euclidean length without overflow or underflow for any finite vector.
pub fn length(a: [f64; 3]) -> f64 {
    let m = max_abs(a);
    if m == 0.0 {
        return 0.0;
    }
    m * a.iter().map(|x| (x / m) * (x / m)).sum::<f64>().sqrt()
}

impl Plane {
    /// The patch with corner `origin` and edges `u`, `v`: refused when a component is not
    /// finite, an edge has zero length, the edges are parallel (the sine of their angle
    /// below 1e-9), or a corner overflows.
    pub fn new(origin: [f64; 3], u: [f64; 3], v: [f64; 3]) -> Result<Plane, PlaneError> {
        for (part, a) in [("origin", origin), ("U", u), ("V", v)] {
            if let Some(x) = a.iter().find(|x| !x.is_finite()) {
                return Err(PlaneError::Part {
                    part,
                    error: PointError::NotFinite {
                        number: x.to_string(),
                    },
                });
            }
        }
        for (part, a) in [("U", u), ("V", v)] {
            if max_abs(a) == 0.0 {
                return Err(PlaneError::ZeroAxis { part, vector: a });
            }
        }
        // Scaled to unit largest component, so that neither huge nor tiny edges overflow.
        let (su, sv) = (max_abs(u), max_abs(v));
        let (un, vn) = (u.map(|x| x / su), v.map(|x| x / sv));
        let cross = [
            un[1] * vn[2] - un[2] * vn[1],
            un[2] * vn[0] - un[0] * vn[2],
            un[0] * vn[1] - un[1] * vn[0],
        ];
        if length(cross) <= 1e-9 * length(un) * length(vn) {
            return Err(PlaneError::Parallel { u, v });
        }
        for (s, t) in [(1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            let corner: [f64; 3] = std::array::from_fn(|k| origin[k] + s * u[k] + t * v[k]);
            if !corner.iter().all(|x| x.is_finite()) {
                return Err(PlaneError::NotFinite { corner });
            }
        }
        Ok(Plane { origin, u, v })
    }

    /// Sample `(i, j)` of a grid of `res` samples: the centre of its cell (see the module
    /// docs).
    pub fn point(&self, res: Resolution, i: u32, j: u32) -> [f64; 3] {
        let s = (f64::from(i) + 0.5) / f64::from(res.nu);
        let t = (f64::from(j) + 0.5) / f64::from(res.nv);
        std::array::from_fn(|k| self.origin[k] + s * self.u[k] + t * self.v[k])
    }
}

/// Samples along `U` (`nu`) and along `V` (`nv`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Resolution {
    pub nu: u32,
    pub nv: u32,
}

impl Resolution {
    /// Number of samples.
    pub fn count(&self) -> u64 {
        u64::from(self.nu) * u64::from(self.nv)
    }
}

/// A resolution as given: both sides, or the longer one with the patch's aspect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResolutionSpec {
    /// `NU,NV`.
    Exact(u64, u64),
    /// `N`: `N` along the longer edge, the shorter in proportion to the edges' lengths
    /// (rounded, at least 1).
    Longer(u64),
}

impl Default for ResolutionSpec {
    fn default() -> Self {
        ResolutionSpec::Longer(DEFAULT_LONGER_SIDE)
    }
}

/// Why a `--resolution` is not one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("expected NU,NV or N (whole numbers of samples), found `{text}`")]
pub struct ResolutionError {
    pub text: String,
}

impl ResolutionSpec {
    /// Parses `NU,NV` or `N`.
    pub fn parse(s: &str) -> Result<ResolutionSpec, ResolutionError> {
        let bad = || ResolutionError {
            text: s.to_string(),
        };
        let num = |t: &str| t.trim().parse::<u64>().map_err(|_| bad());
        match s.split_once(',') {
            Some((u, v)) => Ok(ResolutionSpec::Exact(num(u)?, num(v)?)),
            None => Ok(ResolutionSpec::Longer(num(s)?)),
        }
    }

    /// The grid for `plane`, each side within [`files::limits::plane_resolution`].
    pub fn resolve(self, plane: &Plane) -> Result<Resolution, LimitError> {
        let (nu, nv) = match self {
            ResolutionSpec::Exact(nu, nv) => (nu, nv),
            ResolutionSpec::Longer(n) => {
                files::limits::plane_resolution(n, 1)?;
                let (lu, lv) = (length(plane.u), length(plane.v));
                let shorter = |ratio: f64| ((n as f64 * ratio).round() as u64).max(1);
                if lu >= lv {
                    (n, shorter(lv / lu))
                } else {
                    (shorter(lu / lv), n)
                }
            }
        };
        let [nu, nv] = files::limits::plane_resolution(nu, nv)?;
        Ok(Resolution { nu, nv })
    }
}

/// Bytes a sampled plane holds per sample and field (an `f32`); the outputs are streamed.
pub const BYTES_PER_VALUE: u64 = 4;

/// Refuses a plane of `res` samples of `fields` fields whose values need more than
/// [`files::limits::memory_limit`], before any of it is allocated.
pub fn check_memory(res: Resolution, fields: usize) -> Result<(), LimitError> {
    let need = res
        .count()
        .saturating_mul(fields as u64)
        .saturating_mul(BYTES_PER_VALUE);
    files::limits::check_memory(
        format!("a {}x{} plane of {fields} field(s)", res.nu, res.nv),
        need,
    )
}

/// A sampled plane.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneSamples {
    pub plane: Plane,
    pub resolution: Resolution,
    /// The sampled fields' names, in the order of the values of a sample.
    pub fields: Vec<String>,
    /// `[j][i][f]` (see the module docs); NaN outside the data.
    pub values: Vec<f32>,
    /// Samples outside the data (all their values NaN).
    pub outside: u64,
}

impl PlaneSamples {
    /// The values of sample `(i, j)`, one per field.
    pub fn sample(&self, i: u32, j: u32) -> &[f32] {
        let nf = self.fields.len();
        let at = (j as usize * self.resolution.nu as usize + i as usize) * nf;
        &self.values[at..at + nf]
    }

    /// Where sample `(i, j)` lies (world coordinates).
    pub fn point(&self, i: u32, j: u32) -> [f64; 3] {
        self.plane.point(self.resolution, i, j)
    }
}

/// Why a plane could not be sampled.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SampleError {
    #[error("{0}")]
    Limit(#[from] LimitError),
    #[error("no field to sample")]
    NoFields,
    #[error("field {index} is not in the file ({count} fields)")]
    NoSuchField { index: usize, count: usize },
}

/// Samples `fields` (indices into `vol.fields`, in the order wanted) at every sample of
/// `plane` on a grid of `res`, rows in parallel; the result does not depend on the number
/// of threads. The sides ([`files::limits::plane_resolution`]) and the memory
/// ([`check_memory`]) are checked, and the memory allocated fallibly, first.
pub fn sample(
    vol: &Volume,
    plane: &Plane,
    res: Resolution,
    fields: &[usize],
) -> Result<PlaneSamples, SampleError> {
    let nf = fields.len();
    if nf == 0 {
        return Err(SampleError::NoFields);
    }
    if let Some(&index) = fields.iter().find(|&&f| f >= vol.fields.len()) {
        return Err(SampleError::NoSuchField {
            index,
            count: vol.fields.len(),
        });
    }
    // A resolution built by hand, not by `ResolutionSpec::resolve`, is checked too.
    files::limits::plane_resolution(res.nu.into(), res.nv.into())?;
    check_memory(res, nf)?;
    let n = usize::try_from(res.count().saturating_mul(nf as u64)).unwrap_or(usize::MAX);
    let what = format!("a {}x{} plane of {nf} field(s)", res.nu, res.nv);
    let mut values = files::limits::vec_of::<f32>(what, n)?;
    let outside = values
        .par_chunks_mut(res.nu as usize * nf)
        .enumerate()
        .map(|(j, row)| {
            let mut outside = 0u64;
            for (i, cell) in row.chunks_mut(nf).enumerate() {
                let p = plane.point(res, i as u32, j as u32);
                if !vol.values_at(p, fields, cell) {
                    cell.fill(f32::NAN);
                    outside += 1;
                }
            }
            outside
        })
        .sum();
    Ok(PlaneSamples {
        plane: *plane,
        resolution: res,
        fields: fields.iter().map(|&f| vol.fields[f].name.clone()).collect(),
        values,
        outside,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_degenerate_patches_are_refused() {
        let p = PlaneSpec::parse("1,2,3:4,0,0:0,5,0").expect("explicit");
        assert_eq!(
            p,
            PlaneSpec::Explicit(Plane {
                origin: [1.0, 2.0, 3.0],
                u: [4.0, 0.0, 0.0],
                v: [0.0, 5.0, 0.0]
            })
        );
        assert_eq!(
            PlaneSpec::parse("Z=-0.5").expect("axis"),
            PlaneSpec::Axis { axis: 2, at: -0.5 }
        );
        let err = |s: &str| PlaneSpec::parse(s).expect_err(s).to_string();
        assert_eq!(
            err("0,0,0:0,0,0:0,1,0"),
            "U [0.0, 0.0, 0.0] has zero length"
        );
        assert_eq!(
            err("0,0,0:1,2,3:-2,-4,-6"),
            "U [1.0, 2.0, 3.0] and V [-2.0, -4.0, -6.0] are parallel: they span no plane"
        );
        assert_eq!(
            err("0,0,nan:1,0,0:0,1,0"),
            "origin: expected a finite number, found `nan`"
        );
        assert_eq!(
            err("0,0,0:1,0,0:0,inf,0"),
            "V: expected a finite number, found `inf`"
        );
        assert_eq!(err("0,0,0:1,0,0"), "expected OX,OY,OZ:UX,UY,UZ:VX,VY,VZ (an origin and two edge vectors) or x=C, y=C, z=C, found `0,0,0:1,0,0`");
        assert!(err("w=1").starts_with("expected OX,OY,OZ"));
        assert!(err("xy=1").starts_with("expected OX,OY,OZ"));
        assert_eq!(err("z=nan"), "z=nan: expected a finite coordinate");
        assert_eq!(err("y="), "y=: expected a finite coordinate");
        assert!(err("1e308,0,0:1e308,0,0:0,1,0").starts_with("the patch's corner"));
        // Huge and tiny edges: neither overflow nor underflow decides parallelism.
        assert!(PlaneSpec::parse("0,0,0:1e300,0,0:0,1e300,0").is_ok());
        assert!(PlaneSpec::parse("0,0,0:1e-300,0,0:0,1e-300,0").is_ok());
        assert!(PlaneSpec::parse("0,0,0:1e-300,1e-300,0:1e300,1e300,0").is_err());
    }

    #[test]
    fn an_axis_plane_spans_the_data_in_the_other_two_axes() {
        let (lo, hi) = ([-1.0, 0.0, 2.0], [3.0, 1.0, 4.0]);
        let plane = |s: &str| PlaneSpec::parse(s).expect(s).resolve(lo, hi).expect(s);
        assert_eq!(
            plane("z=3"),
            Plane {
                origin: [-1.0, 0.0, 3.0],
                u: [4.0, 0.0, 0.0],
                v: [0.0, 1.0, 0.0]
            }
        );
        assert_eq!(
            plane("y=0.5"),
            Plane {
                origin: [-1.0, 0.5, 2.0],
                u: [4.0, 0.0, 0.0],
                v: [0.0, 0.0, 2.0]
            }
        );
        assert_eq!(
            plane("x=0"),
            Plane {
                origin: [0.0, 0.0, 2.0],
                u: [0.0, 1.0, 0.0],
                v: [0.0, 0.0, 2.0]
            }
        );
        let flat = PlaneSpec::parse("z=0")
            .expect("z")
            .resolve([0.0; 3], [1.0, 0.0, 1.0])
            .expect_err("flat");
        assert_eq!(
            flat.to_string(),
            "z=0: the data has no extent along y, so the plane has no area"
        );
    }

    #[test]
    fn samples_sit_at_cell_centres_and_the_longer_side_keeps_the_aspect() {
        let plane = Plane::new([1.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 2.0, 0.0]).expect("plane");
        let res = Resolution { nu: 4, nv: 2 };
        assert_eq!(plane.point(res, 0, 0), [1.5, 0.5, 0.0]);
        assert_eq!(plane.point(res, 3, 1), [4.5, 1.5, 0.0]);
        assert_eq!(plane.point(res, 2, 0), [3.5, 0.5, 0.0]);

        let r = |s: &str| ResolutionSpec::parse(s).expect(s).resolve(&plane);
        assert_eq!(r("256"), Ok(Resolution { nu: 256, nv: 128 }));
        assert_eq!(ResolutionSpec::default().resolve(&plane), r("256"));
        assert_eq!(r("3,7"), Ok(Resolution { nu: 3, nv: 7 }));
        let tall = Plane::new([0.0; 3], [1.0, 0.0, 0.0], [0.0, 0.0, 1000.0]).expect("tall");
        assert_eq!(
            ResolutionSpec::Longer(100).resolve(&tall),
            Ok(Resolution { nu: 1, nv: 100 })
        );
        assert_eq!(
            r("16385").expect_err("over").to_string(),
            "--resolution: expected 1..=16384, found 16385"
        );
        assert_eq!(
            r("4,0").expect_err("zero").to_string(),
            "--resolution: expected 1..=16384, found 0"
        );
        for bad in ["", "a", "-4", "2.5", "4,4,4", "4x4", "1e3"] {
            assert_eq!(
                ResolutionSpec::parse(bad).expect_err(bad).to_string(),
                format!("expected NU,NV or N (whole numbers of samples), found `{bad}`")
            );
        }
    }
}
