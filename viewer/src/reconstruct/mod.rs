//! Basis-method reconstruction `B(P) = Σ H_C v_C / Σ H_C` over the cells of a region's
//! bricks, with its analytic gradient (quotient rule) from the same weights.
//!
//! Per brick only the ≤ 2 cells per axis whose tent can be non-zero are visited (the
//! brick's cell index is `floor(u)` and `floor(u) + 1` with `u` the continuous index), so
//! a sample costs at most 8 fetches per overlapping brick. Tent derivatives are taken from
//! the right (at a cell centre the cell on the far side enters with weight 0 and its
//! slope), so the gradient is the one-sided derivative on lattice planes and the exact
//! derivative everywhere else.

mod cubic;
mod tent;

pub(crate) use cubic::{Cubic, DualBrick};
use tent::brick_axes;
pub(crate) use tent::floor_i64;

use crate::volume::{NearRegions, RegionBox, Volume};

/// Below this weight sum a point is treated as outside the data (outer support boundary).
pub(crate) const MIN_WEIGHT: f64 = 1e-9;

/// Reconstruction of the iso field (value and gradient) and optionally a colour field.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Eval {
    pub value: f64,
    pub grad: [f64; 3],
    pub colour: f64,
    /// `Σ H_C` (1 inside a complete single-level lattice).
    pub weight: f64,
}

/// All fields at a point (probe).
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    pub values: Vec<f32>,
    /// Gradient of the field asked for.
    pub gradient: [f64; 3],
}

impl Volume<'_> {
    /// Reconstructs field `f` (value and gradient) and optionally field `fc` at the local
    /// point `p` inside region `r`. `None` where the weights vanish.
    #[inline]
    pub fn eval(&self, r: usize, p: [f64; 3], f: usize, fc: Option<usize>) -> Option<Eval> {
        let (mut sh, mut shv, mut shc) = (0.0f64, 0.0f64, 0.0f64);
        let mut dh = [0.0f64; 3];
        let mut dhv = [0.0f64; 3];
        for b in self.region_brick_ids(r) {
            let br = &self.brick(b.to_native());
            let Some([ax, ay, az]) = brick_axes(br, &p) else {
                continue;
            };
            let nx = br.dims[0] as usize;
            let nxy = nx * br.dims[1] as usize;
            for k in 0..az.n {
                let zoff = br.first + az.idx[k] as usize * nxy;
                for j in 0..ay.n {
                    let yoff = zoff + ay.idx[j] as usize * nx;
                    let wyz = ay.w[j] * az.w[k];
                    let dy = ay.dw[j] * az.w[k];
                    let dz = ay.w[j] * az.dw[k];
                    for i in 0..ax.n {
                        let idx = yoff + ax.idx[i] as usize;
                        let v = self.value(f, idx) as f64;
                        let h = ax.w[i] * wyz;
                        let g = [ax.dw[i] * wyz, ax.w[i] * dy, ax.w[i] * dz];
                        sh += h;
                        shv += h * v;
                        for a in 0..3 {
                            dh[a] += g[a];
                            dhv[a] += g[a] * v;
                        }
                        if let Some(fc) = fc {
                            shc += h * self.value(fc, idx) as f64;
                        }
                    }
                }
            }
        }
        if sh < MIN_WEIGHT {
            return None;
        }
        let inv = 1.0 / sh;
        let value = shv * inv;
        Some(Eval {
            value,
            grad: std::array::from_fn(|a| (dhv[a] - value * dh[a]) * inv),
            colour: shc * inv,
            weight: sh,
        })
    }

    /// Value of field `f` only (no gradient) at local `p` in region `r`.
    #[inline]
    pub fn eval_value(&self, r: usize, p: [f64; 3], f: usize) -> Option<f64> {
        let (mut sh, mut shv) = (0.0f64, 0.0f64);
        let vals = self.values[f];
        for b in self.region_brick_ids(r) {
            let br = &self.brick(b.to_native());
            let Some([ax, ay, az]) = brick_axes(br, &p) else {
                continue;
            };
            let nx = br.dims[0] as usize;
            let nxy = nx * br.dims[1] as usize;
            for k in 0..az.n {
                let zoff = br.first + az.idx[k] as usize * nxy;
                for j in 0..ay.n {
                    let yoff = zoff + ay.idx[j] as usize * nx;
                    let wyz = ay.w[j] * az.w[k];
                    for i in 0..ax.n {
                        let h = ax.w[i] * wyz;
                        sh += h;
                        shv += h * vals[yoff + ax.idx[i] as usize].to_native() as f64;
                    }
                }
            }
        }
        (sh >= MIN_WEIGHT).then(|| shv / sh)
    }

    /// Gradient of field `f` for shading at local `p`: central differences of the
    /// reconstruction `B` over one cell width of the file's finest level.
    ///
    /// The analytic gradient of `B` (what [`Volume::eval`] returns, and what root finding
    /// needs) is piecewise: its slope jumps at every cell face, so shading with it shows
    /// every cell as a facet, and across the half-cell band at a level boundary where one
    /// layer of coarse cells alone contributes, its normal component is exactly zero (a
    /// dark seam). `B` itself is continuous, so a difference quotient of it over one fixed
    /// width is continuous too (a width that changed with the local level would jump at
    /// level boundaries), and a whole fine cell steps over the flat band, which is about
    /// half a fine cell wide.
    /// A side that leaves the data falls back to a one-sided difference; `None` when
    /// neither side of any axis is inside.
    pub fn shading_gradient(&self, p: [f64; 3], f: usize) -> Option<[f64; 3]> {
        self.shading_gradient_near(None, p, f, &mut NearRegions::default())
    }

    /// [`Self::shading_gradient`] with the region the caller found `p` in and a box
    /// within it (a ray hit knows them), which saves a KD descent when the box holds `p`;
    /// any other hint is ignored. Neighbour points in the box need no descent either, nor
    /// those in a region `kept` holds (the caller's earlier points nearby), nor `p` itself
    /// there when no hint holds it; the regions of the others are kept there.
    pub(crate) fn shading_gradient_near(
        &self,
        region: Option<RegionBox>,
        p: [f64; 3],
        f: usize,
        kept: &mut NearRegions,
    ) -> Option<[f64; 3]> {
        let b0 = match region {
            Some(h) if (h.region as usize) < self.region_count() && h.holds(&p) => h,
            _ => self.region_box_kept(p, kept)?,
        };
        let r0 = b0.region as usize;
        let h = self.finest_w;
        // The neighbour points outside `r0` are found from `p`'s own descent.
        let mut descent = None;
        let mut at = |q: [f64; 3]| -> Option<f64> {
            let r = if b0.holds(&q) {
                r0
            } else {
                self.region_near_kept(&mut descent, p, q, kept)? as usize
            };
            self.eval_value(r, q, f)
        };
        // The centre value only serves the one-sided fallback, which is rare: it is
        // evaluated on first need (one reconstruction less per shaded point).
        let mut centre = None;
        let mut g = [0.0; 3];
        let mut any = false;
        for a in 0..3 {
            let mut q = p;
            q[a] = p[a] + h;
            let hi = at(q);
            q[a] = p[a] - h;
            let lo = at(q);
            g[a] = match (lo, hi) {
                (Some(l), Some(u)) => (u - l) / (2.0 * h),
                (None, None) => continue,
                (lo, hi) => {
                    let Some(c) = *centre.get_or_insert_with(|| at(p)) else {
                        continue;
                    };
                    match (lo, hi) {
                        (None, Some(u)) => (u - c) / h,
                        (Some(l), _) => (c - l) / h,
                        _ => continue,
                    }
                }
            };
            any = true;
        }
        any.then_some(g)
    }

    /// Value at any local point (region found by KD descent).
    pub fn value_at(&self, p: [f64; 3], f: usize) -> Option<f64> {
        let r = self.region_at(p)?;
        self.eval_value(r as usize, p, f)
    }

    /// Every field and the gradient of field `grad_field` at the **world** point `p`;
    /// `None` outside the data.
    pub fn sample(&self, p_world: [f64; 3], grad_field: usize) -> Option<Sample> {
        let p = self.to_local(p_world);
        let r = self.region_at(p)? as usize;
        let e = self.eval(r, p, grad_field, None)?;
        let values = (0..self.fields.len())
            .map(|f| self.probed_value(r, p, f))
            .collect();
        Some(Sample {
            values,
            gradient: e.grad,
        })
    }

    /// The fields `fields` at the **world** point `p`, as [`Volume::sample`] reports them
    /// (bit for bit: the same region, the same sums, rounded to `f32` alike), into `out`
    /// (one value per field). `false` outside the data, where `out` is left as it was: no
    /// region holds `p`, or the weights vanish there (they vanish for every field alike).
    pub fn values_at(&self, p_world: [f64; 3], fields: &[usize], out: &mut [f32]) -> bool {
        let p = self.to_local(p_world);
        let Some(r) = self.region_at(p) else {
            return false;
        };
        let r = r as usize;
        let (Some(first), Some(&f0)) = (out.first_mut(), fields.first()) else {
            return false;
        };
        // Where the weights vanish, `Volume::sample` (its `eval`) reports nothing at all.
        let Some(v) = self.eval_value(r, p, f0) else {
            return false;
        };
        *first = v as f32;
        for (o, &f) in out.iter_mut().zip(fields).skip(1) {
            *o = self.probed_value(r, p, f);
        }
        true
    }

    /// Field `f` at local `p` in region `r` as a probe reports it: the reconstruction
    /// rounded to `f32`, NaN where the weights vanish.
    fn probed_value(&self, r: usize, p: [f64; 3], f: usize) -> f32 {
        self.eval_value(r, p, f).map_or(f32::NAN, |v| v as f32)
    }
}
