//! Basis-method reconstruction `B(P) = Σ H_C v_C / Σ H_C` over the cells of a region's
//! bricks, with its analytic gradient (quotient rule) from the same weights.
//!
//! Per brick only the ≤ 2 cells per axis whose tent can be non-zero are visited (the
//! brick's cell index is `floor(u)` and `floor(u) + 1` with `u` the continuous index), so
//! a sample costs at most 8 fetches per overlapping brick. Tent derivatives are taken from
//! the right (at a cell centre the cell on the far side enters with weight 0 and its
//! slope), so the gradient is the one-sided derivative on lattice planes and the exact
//! derivative everywhere else.

use crate::volume::{BrickN, StoredF32, Volume};

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

/// Per axis: up to two (cell index, tent weight, tent slope in world units).
#[derive(Clone, Copy, Default)]
struct Axis {
    n: usize,
    idx: [i64; 2],
    w: [f64; 2],
    dw: [f64; 2],
}

/// `u.floor()` as an integer without a library call (the baseline x86-64 target has no
/// SSE4.1 rounding instruction, and a call costs more than the rest of a dual-cell
/// lookup); exact for `|u| < 2^53`, which the callers check.
#[inline(always)]
pub(crate) fn floor_i64(u: f64) -> i64 {
    let t = u as i64;
    if (t as f64) > u {
        t - 1
    } else {
        t
    }
}

#[inline(always)]
fn axis_cells(u: f64, dim: i64, inv_w: f64) -> Axis {
    let mut ax = Axis::default();
    if !(u >= -1.0 && u < dim as f64) {
        return ax;
    }
    let i0 = floor_i64(u);
    let d = u - i0 as f64; // in [0, 1)
    if i0 >= 0 {
        ax.idx[ax.n] = i0;
        ax.w[ax.n] = 1.0 - d;
        ax.dw[ax.n] = -inv_w;
        ax.n += 1;
    }
    if i0 + 1 < dim {
        ax.idx[ax.n] = i0 + 1;
        ax.w[ax.n] = d;
        ax.dw[ax.n] = inv_w;
        ax.n += 1;
    }
    ax
}

#[inline(always)]
fn brick_axes(b: &BrickN, p: &[f64; 3]) -> Option<[Axis; 3]> {
    let u: [f64; 3] = std::array::from_fn(|a| (p[a] - b.origin[a]) * b.inv_w);
    cells_at(&u, &b.dims, b.inv_w)
}

/// A brick of a region as `exact` reads it along one ray segment (see
/// [`Volume::dual_bricks`]): the numbers of [`BrickN`] the dual-cell test and the cubic use,
/// with the row and slice strides.
#[derive(Debug, Clone, Copy)]
pub(crate) struct DualBrick {
    origin: [f64; 3],
    inv_w: f64,
    dims: [i64; 3],
    first: usize,
    nx: usize,
    nxy: usize,
}

/// [`brick_axes`] from the continuous cell index `u` already computed.
#[inline(always)]
fn dual_axes(b: &DualBrick, u: &[f64; 3]) -> Option<[Axis; 3]> {
    cells_at(u, &b.dims, b.inv_w)
}

/// The candidate cells on every axis at cell coordinates `u` of a brick of `dims` cells;
/// `None` when an axis has none.
#[inline(always)]
fn cells_at(u: &[f64; 3], dims: &[i64; 3], inv_w: f64) -> Option<[Axis; 3]> {
    let mut axes = [Axis::default(); 3];
    for a in 0..3 {
        axes[a] = axis_cells(u[a], dims[a], inv_w);
        if axes[a].n == 0 {
            return None;
        }
    }
    Some(axes)
}

/// What the cubic's polynomial part reads of one brick (a [`BrickN`] or a [`DualBrick`]).
struct BrickPart<'b> {
    origin: &'b [f64; 3],
    inv_w: f64,
    first: usize,
    nx: usize,
    nxy: usize,
}

impl BrickPart<'_> {
    /// Adds this brick's share of `Σ H_C (v_C − iso)` and of `Σ H_C` over `[ta, ta + h]`
    /// (as cubics in `x`) to `c` and `wc`: `axes` are its candidate cells at the
    /// interval's midpoint, whose cell coordinates are `u`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn add_cubic(
        &self,
        vals: &[StoredF32],
        axes: &[Axis; 3],
        u: &[f64; 3],
        o: &[f64; 3],
        d: &[f64; 3],
        ta: f64,
        h: f64,
        iso: f64,
        c: &mut [f64; 4],
        wc: &mut [f64; 4],
    ) {
        // Tent of each candidate cell as a linear function `l0 + l1 x` of x.
        let mut lin = [[[0.0f64; 2]; 2]; 3];
        for a in 0..3 {
            let u0 = (o[a] + ta * d[a] - self.origin[a]) * self.inv_w;
            let du = h * d[a] * self.inv_w;
            for k in 0..axes[a].n {
                let i = axes[a].idx[k] as f64;
                // Sign of (u - i) over the interval, from the midpoint.
                lin[a][k] = if u[a] >= i {
                    [1.0 - (u0 - i), -du]
                } else {
                    [1.0 + (u0 - i), du]
                };
            }
        }
        let [ax, ay, az] = axes;
        for k in 0..az.n {
            let zoff = self.first + az.idx[k] as usize * self.nxy;
            let lz = lin[2][k];
            for j in 0..ay.n {
                let yoff = zoff + ay.idx[j] as usize * self.nx;
                let ly = lin[1][j];
                // Σ_i (v - iso) lx_i: a linear function.
                let (mut s0, mut s1) = (0.0, 0.0);
                let (mut w0, mut w1) = (0.0, 0.0);
                for i in 0..ax.n {
                    w0 += lin[0][i][0];
                    w1 += lin[0][i][1];
                    let v = vals[yoff + ax.idx[i] as usize].to_native() as f64 - iso;
                    s0 += v * lin[0][i][0];
                    s1 += v * lin[0][i][1];
                }
                // × ly × lz.
                let q = [s0 * ly[0], s0 * ly[1] + s1 * ly[0], s1 * ly[1]];
                c[0] += q[0] * lz[0];
                c[1] += q[0] * lz[1] + q[1] * lz[0];
                c[2] += q[1] * lz[1] + q[2] * lz[0];
                c[3] += q[2] * lz[1];
                let q = [w0 * ly[0], w0 * ly[1] + w1 * ly[0], w1 * ly[1]];
                wc[0] += q[0] * lz[0];
                wc[1] += q[0] * lz[1] + q[1] * lz[0];
                wc[2] += q[1] * lz[1] + q[2] * lz[0];
                wc[3] += q[2] * lz[1];
            }
        }
    }
}

/// Coefficients (in `x = (t - ta) / h`, `x ∈ [0, 1]`) of `g(t) = Σ H_C(t) (v_C - iso)` along a
/// ray over an interval lying in one dual cell of every lattice of the region — there `g`
/// is a cubic. `g` and `B - iso` have the same sign and the same roots where `Σ H > 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Cubic {
    pub c: [f64; 4],
    /// `Σ H_C` along the same interval (zero on the outer support boundary).
    pub weight: [f64; 4],
    /// Some contributing cell has `v ≥ iso` / `v < iso` (if not both, no root inside and
    /// the coefficients are not computed: all zero).
    pub(crate) any_above: bool,
    pub(crate) any_below: bool,
}

impl Cubic {
    #[inline]
    pub(crate) fn eval(&self, x: f64) -> f64 {
        ((self.c[3] * x + self.c[2]) * x + self.c[1]) * x + self.c[0]
    }

    /// `dg/dx`.
    #[inline]
    pub(crate) fn slope(&self, x: f64) -> f64 {
        (3.0 * self.c[3] * x + 2.0 * self.c[2]) * x + self.c[1]
    }

    #[inline]
    pub(crate) fn weight_at(&self, x: f64) -> f64 {
        ((self.weight[3] * x + self.weight[2]) * x + self.weight[1]) * x + self.weight[0]
    }
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
        self.shading_gradient_near(None, p, f)
    }

    /// [`Self::shading_gradient`] with the region the caller found `p` in (a ray hit knows
    /// it), which saves a KD descent when it holds `p`; any other hint is ignored.
    pub(crate) fn shading_gradient_near(
        &self,
        region: Option<u32>,
        p: [f64; 3],
        f: usize,
    ) -> Option<[f64; 3]> {
        let holds = |r: usize, q: &[f64; 3]| {
            let reg = self.region(r);
            (0..3).all(|a| q[a] >= reg.min[a] && q[a] < reg.max[a])
        };
        let r0 = match region {
            Some(r) if (r as usize) < self.region_count() && holds(r as usize, &p) => r as usize,
            _ => self.region_at(p)? as usize,
        };
        let h = self.finest_w;
        // The neighbour points outside `r0` are found from `p`'s own descent.
        let mut descent = None;
        let mut at = |q: [f64; 3]| -> Option<f64> {
            let r = if holds(r0, &q) {
                r0
            } else {
                let near = descent.get_or_insert_with(|| self.descent(p));
                self.region_near(near, q)? as usize
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
            .map(|f| self.eval_value(r, p, f).map_or(f32::NAN, |v| v as f32))
            .collect();
        Some(Sample {
            values,
            gradient: e.grad,
        })
    }

    /// The bricks of region `r` as [`Volume::cubic_in`] reads them, into `out` (cleared
    /// first): `exact` converts them from the file once per region segment instead of once
    /// per interval.
    pub(crate) fn dual_bricks(&self, r: usize, out: &mut Vec<DualBrick>) {
        out.clear();
        out.extend(self.region_brick_ids(r).iter().map(|b| {
            let br = self.brick(b.to_native());
            let nx = br.dims[0] as usize;
            DualBrick {
                origin: br.origin,
                inv_w: br.inv_w,
                dims: br.dims,
                first: br.first,
                nx,
                nxy: nx * br.dims[1] as usize,
            }
        }));
    }

    /// Whether some cell that the dual cells at local point `pm` read (over `bricks`, as
    /// [`Volume::cubic_in`] picks them) has `v ≥ iso`, and whether some has `v < iso`;
    /// stops reading once both are seen.
    #[inline(always)]
    pub(crate) fn dual_cell_sides(
        &self,
        bricks: &[DualBrick],
        pm: &[f64; 3],
        f: usize,
        iso: f64,
    ) -> (bool, bool) {
        let (mut any_above, mut any_below) = (false, false);
        let vals = self.values[f];
        for br in bricks {
            let u: [f64; 3] = std::array::from_fn(|a| (pm[a] - br.origin[a]) * br.inv_w);
            let inner = (0..3).all(|a| u[a] >= 0.0 && u[a] < (br.dims[a] - 1) as f64);
            if inner {
                // floor(u) ≥ 0 and floor(u) + 1 < dim on every axis: all eight corners, in
                // the order the general loops visit them (the order does not matter to
                // the test, only to the sums below, which keep the general loops).
                let i = u.map(|x| x as usize);
                let base = br.first + i[0] + i[1] * br.nx + i[2] * br.nxy;
                let (nx, nxy) = (br.nx, br.nxy);
                for off in [0, nx, nxy, nxy + nx] {
                    let a = vals[base + off].to_native() as f64 - iso;
                    let b = vals[base + off + 1].to_native() as f64 - iso;
                    any_above |= (a >= 0.0) | (b >= 0.0);
                    any_below |= (a < 0.0) | (b < 0.0);
                }
            } else {
                let Some([ax, ay, az]) = dual_axes(br, &u) else {
                    continue;
                };
                for k in 0..az.n {
                    let zoff = br.first + az.idx[k] as usize * br.nxy;
                    for j in 0..ay.n {
                        let yoff = zoff + ay.idx[j] as usize * br.nx;
                        for i in 0..ax.n {
                            let v = vals[yoff + ax.idx[i] as usize].to_native() as f64 - iso;
                            any_above |= v >= 0.0;
                            any_below |= v < 0.0;
                        }
                    }
                }
            }
            if any_above && any_below {
                // Both sides seen: the polynomial is needed whatever the other bricks hold.
                break;
            }
        }
        (any_above, any_below)
    }

    /// ORs into `sides` what [`Volume::dual_cell_sides`] reads of the brick `br` at the
    /// centre of every dual cell of a box of `n` dual cells from index `lo` of the lattice
    /// (inverse width `inv_w`, a cell centre at `origin`) that `br`'s cells lie on (whole
    /// cells apart): bit 0 for a cell with `v ≥ iso`, bit 1 for one with `v < iso`, one
    /// byte per dual cell, x fastest. Brick by brick instead of dual cell by dual cell:
    /// each cell's side is found once, then spread to the up to eight dual cells that
    /// read it (the cells of a dual cell are the brick's cells `m − o` and `m − o + 1` on
    /// each axis, for a brick whose first cell is `o` cells on from the box's first dual
    /// cell, as many of them as the brick has). `scratch` is reused between calls.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn dual_sides_of_brick(
        &self,
        br: &DualBrick,
        origin: &[f64; 3],
        inv_w: f64,
        lo: &[i64; 3],
        n: &[usize; 3],
        f: usize,
        iso: f64,
        sides: &mut [u8],
        scratch: &mut Vec<u8>,
    ) {
        let vals = self.values[f];
        // Per axis: the brick's first cell from the box's first dual cell, and the dual
        // cells of the box that read one of its cells.
        let (mut off, mut m0, mut m1) = ([0i64; 3], [0i64; 3], [0i64; 3]);
        for a in 0..3 {
            let o = ((br.origin[a] - origin[a]) * inv_w).round();
            if !o.is_finite() || o.abs() > 1e15 {
                return;
            }
            off[a] = o as i64 - lo[a];
            m0[a] = (off[a] - 1).max(0);
            m1[a] = (off[a] + br.dims[a] - 1).min(n[a] as i64 - 1);
            if m0[a] > m1[a] {
                return;
            }
        }
        // The sides of the cells those dual cells read, with the cells the brick does not
        // have as 0: buffer cell `i` is brick cell `m0 − off + i`.
        let s: [usize; 3] = std::array::from_fn(|a| (m1[a] - m0[a] + 2) as usize);
        scratch.clear();
        scratch.resize(s[0] * s[1] * s[2], 0);
        let cell = |a: usize, i: usize| {
            let c = m0[a] - off[a] + i as i64;
            (0..br.dims[a]).contains(&c).then_some(c as usize)
        };
        for k in 0..s[2] {
            let Some(cz) = cell(2, k) else { continue };
            for j in 0..s[1] {
                let Some(cy) = cell(1, j) else { continue };
                let row = br.first + cy * br.nx + cz * br.nxy;
                for i in 0..s[0] {
                    let Some(cx) = cell(0, i) else { continue };
                    let v = vals[row + cx].to_native() as f64 - iso;
                    scratch[i + s[0] * (j + s[1] * k)] =
                        u8::from(v >= 0.0) | u8::from(v < 0.0) << 1;
                }
            }
        }
        // Dual cell `m` reads buffer cells `m − m0` and `m − m0 + 1` on each axis.
        let (sx, sxy) = (s[0], s[0] * s[1]);
        for mz in m0[2]..=m1[2] {
            for my in m0[1]..=m1[1] {
                let b = (my - m0[1]) as usize * sx + (mz - m0[2]) as usize * sxy;
                let out = mz as usize * n[0] * n[1] + my as usize * n[0];
                for mx in m0[0]..=m1[0] {
                    let i = b + (mx - m0[0]) as usize;
                    let or = scratch[i]
                        | scratch[i + 1]
                        | scratch[i + sx]
                        | scratch[i + sx + 1]
                        | scratch[i + sxy]
                        | scratch[i + sxy + 1]
                        | scratch[i + sxy + sx]
                        | scratch[i + sxy + sx + 1];
                    sides[out + mx as usize] |= or;
                }
            }
        }
    }

    /// The cubic `g(x) = Σ H_C (v_C - iso)` along `o + t d` for `t = ta + x (tb - ta)`,
    /// valid when `[ta, tb]` lies inside one dual cell of every lattice of the region whose
    /// bricks are `bricks` (from [`Volume::dual_bricks`]; cells are collected at the
    /// interval's midpoint).
    ///
    /// The same numbers as [`Volume::cubic`] (same cells, same operations in the same
    /// order), with the brick conversions hoisted out and, where all eight corners of a
    /// brick's dual cell exist (everywhere but its outer cell layer), the dual-cell test
    /// read as eight fixed offsets instead of the general per-axis loops. `straddles`:
    /// the caller already knows that the cells read lie on both sides of `iso` (a dual-cell
    /// mask said so), so they are not tested again.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(crate) fn cubic_in(
        &self,
        bricks: &[DualBrick],
        o: &[f64; 3],
        d: &[f64; 3],
        ta: f64,
        tb: f64,
        f: usize,
        iso: f64,
        straddles: bool,
    ) -> Cubic {
        let tm = 0.5 * (ta + tb);
        let pm: [f64; 3] = std::array::from_fn(|a| o[a] + tm * d[a]);
        let (any_above, any_below) = if straddles {
            (true, true)
        } else {
            self.dual_cell_sides(bricks, &pm, f, iso)
        };
        let vals = self.values[f];
        if !(any_above && any_below) {
            return Cubic {
                c: [0.0; 4],
                weight: [0.0; 4],
                any_above,
                any_below,
            };
        }
        let h = tb - ta;
        let mut c = [0.0f64; 4];
        let mut wc = [0.0f64; 4];
        for br in bricks {
            let u: [f64; 3] = std::array::from_fn(|a| (pm[a] - br.origin[a]) * br.inv_w);
            let Some(axes) = dual_axes(br, &u) else {
                continue;
            };
            let part = BrickPart {
                origin: &br.origin,
                inv_w: br.inv_w,
                first: br.first,
                nx: br.nx,
                nxy: br.nxy,
            };
            part.add_cubic(vals, &axes, &u, o, d, ta, h, iso, &mut c, &mut wc);
        }
        Cubic {
            c,
            weight: wc,
            any_above,
            any_below,
        }
    }

    /// The cubic `g(x) = Σ H_C (v_C - iso)` along `o + t d` for `t = ta + x (tb - ta)`,
    /// valid when `[ta, tb]` lies inside one dual cell of every lattice of region `r`
    /// (cells are collected at the interval's midpoint).
    ///
    /// The straightforward evaluation (bricks read from the file per call) that
    /// [`Volume::cubic_in`] must reproduce bit for bit.
    #[cfg(test)]
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn cubic(
        &self,
        r: usize,
        o: &[f64; 3],
        d: &[f64; 3],
        ta: f64,
        tb: f64,
        f: usize,
        iso: f64,
    ) -> Cubic {
        let h = tb - ta;
        let tm = 0.5 * (ta + tb);
        let pm: [f64; 3] = std::array::from_fn(|a| o[a] + tm * d[a]);
        // Dual-cell bound test first (values only): most intervals lie on one side of
        // iso and need no polynomial at all.
        let (mut any_above, mut any_below) = (false, false);
        let vals = self.values[f];
        for b in self.region_brick_ids(r) {
            let br = &self.brick(b.to_native());
            let Some([ax, ay, az]) = brick_axes(br, &pm) else {
                continue;
            };
            let nx = br.dims[0] as usize;
            let nxy = nx * br.dims[1] as usize;
            for k in 0..az.n {
                let zoff = br.first + az.idx[k] as usize * nxy;
                for j in 0..ay.n {
                    let yoff = zoff + ay.idx[j] as usize * nx;
                    for i in 0..ax.n {
                        let v = vals[yoff + ax.idx[i] as usize].to_native() as f64 - iso;
                        any_above |= v >= 0.0;
                        any_below |= v < 0.0;
                    }
                }
            }
            if any_above && any_below {
                // Both sides seen: the polynomial is needed whatever the other bricks hold.
                break;
            }
        }
        if !(any_above && any_below) {
            return Cubic {
                c: [0.0; 4],
                weight: [0.0; 4],
                any_above,
                any_below,
            };
        }
        let mut c = [0.0f64; 4];
        let mut wc = [0.0f64; 4];
        for b in self.region_brick_ids(r) {
            let br = &self.brick(b.to_native());
            let Some(axes) = brick_axes(br, &pm) else {
                continue;
            };
            let u: [f64; 3] = std::array::from_fn(|a| (pm[a] - br.origin[a]) * br.inv_w);
            let nx = br.dims[0] as usize;
            let part = BrickPart {
                origin: &br.origin,
                inv_w: br.inv_w,
                first: br.first,
                nx,
                nxy: nx * br.dims[1] as usize,
            };
            part.add_cubic(vals, &axes, &u, o, d, ta, h, iso, &mut c, &mut wc);
        }
        Cubic {
            c,
            weight: wc,
            any_above,
            any_below,
        }
    }
}
