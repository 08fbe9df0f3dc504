//! Which dual cells of a region can hold one iso value: one bit per dual cell.
//!
//! A region is searched by `exact` because some of its cells lie on each side of the iso
//! value, but most of the dual cells a ray crosses there have all their corners on one
//! side (91 % on the n0-128 wake's benchmark view), and `exact` reads up to eight corners
//! per brick to find that out for each of them. When a region's bricks all share one cell
//! lattice, the answer is the same everywhere inside one dual cell of that lattice: every
//! brick's dual cell there is the same, and so are the corners read. So the answer is
//! computed once per dual cell, when the active tree for an iso value is built, and read
//! back as one bit per interval.
//!
//! An interval whose midpoint lies within round-off of a lattice plane does not trust the
//! bit (a brick's own cell coordinate could round to the neighbouring dual cell) and reads
//! its corners as before, so the skipped intervals are exactly those the corner test would
//! have rejected, and the roots are bit-identical.

use crate::reconstruct::DualBrick;
use crate::sampling::Lattice;
use crate::volume::Volume;

/// Most dual cells a region's mask covers (beyond that the region reads its corners).
const MAX_CELLS: usize = 1 << 18;

/// Most (dual cell, brick) pairs one mask may test: building it is a ray's work, so a
/// region far larger than the bricks' cells (which a valid file may hold) reads its
/// corners instead of stalling the ray that reaches it first.
const MAX_WORK: usize = 1 << 21;

/// How close (in cells) to a lattice plane a midpoint may be for its bit to be trusted.
const PLANE_MARGIN: f64 = 1e-6;

/// The dual cells of one region's lattice that can hold the iso value.
#[derive(Debug, Clone)]
pub(crate) struct DualMask {
    /// The lattice's cell width inverse and one cell centre (local frame).
    inv_w: f64,
    origin: [f64; 3],
    /// Dual-cell index (`floor` of the cell coordinate) of the mask's first cell, and the
    /// mask's size per axis.
    lo: [i64; 3],
    n: [usize; 3],
    /// One bit per dual cell, x fastest.
    bits: Vec<u64>,
}

impl DualMask {
    /// The mask of a region whose bricks (`bricks`, all of `lattice`) cover the local box
    /// `min..max`, for `iso` in field `f`; `None` when the box is not finite or the mask
    /// too large to build ([`MAX_CELLS`], [`MAX_WORK`]).
    pub(crate) fn build(
        vol: &Volume,
        bricks: &[DualBrick],
        lattice: &Lattice,
        min: &[f64; 3],
        max: &[f64; 3],
        f: usize,
        iso: f64,
    ) -> Option<DualMask> {
        let &(w, inv_w, origin) = lattice;
        let mut lo = [0i64; 3];
        let mut n = [0usize; 3];
        for a in 0..3 {
            let (u0, u1) = ((min[a] - origin[a]) * inv_w, (max[a] - origin[a]) * inv_w);
            if !(u0.is_finite() && u1.is_finite() && u0 <= u1 && u1 - u0 < 1e6) {
                return None;
            }
            lo[a] = u0.floor() as i64;
            n[a] = (u1.floor() as i64 - lo[a] + 1) as usize;
        }
        let cells = n[0].checked_mul(n[1])?.checked_mul(n[2])?;
        if cells > MAX_CELLS || cells.saturating_mul(bricks.len()) > MAX_WORK {
            return None;
        }
        let mut bits = vec![0u64; cells.div_ceil(64)];
        let mut i = 0;
        for k in 0..n[2] {
            for j in 0..n[1] {
                for x in 0..n[0] {
                    // The dual cell's centre: every brick of the lattice picks the same
                    // corners anywhere inside it.
                    let idx = [x as i64 + lo[0], j as i64 + lo[1], k as i64 + lo[2]];
                    let p: [f64; 3] =
                        std::array::from_fn(|a| origin[a] + (idx[a] as f64 + 0.5) * w);
                    let (above, below) = vol.dual_cell_sides(bricks, &p, f, iso);
                    if above && below {
                        bits[i / 64] |= 1 << (i % 64);
                    }
                    i += 1;
                }
            }
        }
        Some(DualMask {
            inv_w,
            origin,
            lo,
            n,
            bits,
        })
    }

    /// `Some(false)` when the interval with midpoint `pm` (local) reads only cells on one
    /// side of the iso value, `Some(true)` when it may cross it, `None` when the mask cannot
    /// tell (the midpoint is outside it or within round-off of a lattice plane).
    #[inline]
    pub(crate) fn may_cross(&self, pm: &[f64; 3]) -> Option<bool> {
        let mut i = 0usize;
        let mut stride = 1usize;
        for a in 0..3 {
            let u = (pm[a] - self.origin[a]) * self.inv_w;
            if u.is_nan() || u.abs() >= 1e15 {
                return None;
            }
            // floor(u) without a library call (the baseline target has no rounding
            // instruction); exact for |u| < 2^53.
            let t = u as i64;
            let fl = if (t as f64) > u { t - 1 } else { t };
            let frac = u - fl as f64;
            if !(PLANE_MARGIN..=1.0 - PLANE_MARGIN).contains(&frac) {
                return None;
            }
            let k = fl - self.lo[a];
            if k < 0 || k as usize >= self.n[a] {
                return None;
            }
            i += k as usize * stride;
            stride *= self.n[a];
        }
        Some(self.bits[i / 64] >> (i % 64) & 1 == 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Lattices;

    /// A box too large for a mask, or not finite, gets none (its region reads its
    /// corners); the region's own box gets one, which cannot tell a point outside it or on
    /// a lattice plane.
    #[test]
    fn masks_have_bounded_size_and_answer_only_inside() {
        let f = |p: [f64; 3]| p[0] + 0.5 * p[1] - 0.25 * p[2];
        let file = crate::testvol::nested(8, [0.0; 3], &[("f", &f)], 4);
        let view = crate::testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let r = (0..vol.region_count())
            .find(|&r| Lattices::of(&vol, r).as_slice().len() == 1)
            .expect("a region of one lattice");
        let lattices = Lattices::of(&vol, r);
        let lattice = &lattices.as_slice()[0];
        let mut bricks = Vec::new();
        vol.dual_bricks(r, &mut bricks);
        let reg = vol.region(r);
        let build = |min: [f64; 3], max: [f64; 3]| {
            DualMask::build(&vol, &bricks, lattice, &min, &max, 0, 3.0)
        };
        assert!(build([-1e4; 3], [1e4; 3]).is_none(), "2e4 cells a side");
        assert!(build([f64::NAN; 3], reg.max).is_none());
        assert!(build(reg.min, [f64::INFINITY; 3]).is_none());
        let mask = build(reg.min, reg.max).expect("the region's box");
        let (w, _, origin) = *lattice;
        // Far outside, and on a lattice plane (a cell centre coordinate) inside.
        assert_eq!(mask.may_cross(&[1e3; 3]), None);
        let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * (reg.min[a] + reg.max[a]));
        let mut on_plane = centre;
        on_plane[0] = origin[0] + ((centre[0] - origin[0]) / w).round() * w;
        assert_eq!(mask.may_cross(&on_plane), None);
    }
}
