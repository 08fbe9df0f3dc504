//! What `exact` reads of a region along one ray interval: its bricks converted once per
//! segment ([`DualBrick`]), which side of the iso value the cells of a dual cell lie on
//! (per interval, or brick by brick for a whole mask), and the cubic the reconstruction is
//! between two lattice planes ([`Cubic`]).

use super::tent::{cells_at, Axis};
use crate::volume::{StoredF32, Volume};

/// A brick of a region as `exact` reads it along one ray segment (see
/// [`Volume::dual_bricks`]): the numbers of [`BrickN`](crate::volume::BrickN) the
/// dual-cell test and the cubic use, with the row and slice strides.
#[derive(Debug, Clone, Copy)]
pub(crate) struct DualBrick {
    origin: [f64; 3],
    inv_w: f64,
    dims: [i64; 3],
    first: usize,
    nx: usize,
    nxy: usize,
}

/// `brick_axes` from the continuous cell index `u` already computed.
#[inline(always)]
fn dual_axes(b: &DualBrick, u: &[f64; 3]) -> Option<[Axis; 3]> {
    cells_at(u, &b.dims, b.inv_w)
}

/// What the cubic's polynomial part reads of one brick (a [`BrickN`](crate::volume::BrickN)
/// or a [`DualBrick`]).
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
    /// The same numbers as `Volume::cubic`, the tests' reference (same cells, same operations in the same
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
            let Some([ax, ay, az]) = super::tent::brick_axes(br, &pm) else {
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
            let Some(axes) = super::tent::brick_axes(br, &pm) else {
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
