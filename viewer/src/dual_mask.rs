//! Which dual cells of a region can hold one iso value: one bit per dual cell.
//!
//! A region is searched by `exact` because some of its cells lie on each side of the iso
//! value, but most of the dual cells a ray crosses there have all their corners on one
//! side (91 % on the n0-128 wake's benchmark view), and `exact` reads up to eight corners
//! per brick to find that out for each of them. When a region's bricks all share one cell
//! lattice, the answer is the same everywhere inside one dual cell of that lattice: every
//! brick's dual cell there is the same, and so are the corners read. So the answer is
//! computed once per dual cell, when the active tree for an iso value is built, and read
//! back as one bit per interval. The bits also cut the region into the parts where the
//! value can lie ([`DualMask::sub_boxes`]), which is all of the region the tree lists.
//!
//! An interval whose midpoint lies within round-off of a lattice plane does not trust the
//! bit (a brick's own cell coordinate could round to the neighbouring dual cell) and reads
//! its corners as before, so the skipped intervals are exactly those the corner test would
//! have rejected, and the roots are bit-identical.

use crate::lattice::Lattice;
use crate::reconstruct::{floor_i64, DualBrick};
use crate::volume::Volume;

/// Most dual cells a region's mask covers (beyond that the region reads its corners).
const MAX_CELLS: usize = 1 << 18;

/// Most (dual cell, brick) pairs one mask may test, so that a region far larger than the
/// bricks' cells (which a valid file may hold) reads its corners instead of stalling the
/// build of the active tree.
const MAX_WORK: usize = 1 << 21;

/// Most (dual cell, brick) pairs the masks of one active tree may test together (a
/// second or so): the regions past it, in the tree's order, read their corners. A
/// 5 M-cell wake needs about a million at its busiest iso values.
pub(crate) const MAX_TREE_WORK: usize = 1 << 25;

/// How close (in cells) to a lattice plane a midpoint may be for its bit to be trusted.
const PLANE_MARGIN: f64 = 1e-6;

/// Edge, in dual cells, of the blocks a region's mask is cut into for the active tree
/// ([`DualMask::sub_boxes`]): smaller blocks hug the surface more closely but give the
/// tree more leaves to walk.
pub(crate) const BLOCK: usize = 8;

/// A part of a region that `exact` must search ([`DualMask::sub_boxes`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct SubBox {
    /// Local frame.
    pub(crate) min: [f64; 3],
    pub(crate) max: [f64; 3],
    /// The block it lies in (block coordinates inside the mask): boxes of different
    /// blocks are separated by the planes between the blocks.
    pub(crate) block: [u32; 3],
}

/// The dual cells of one region's lattice that can hold the iso value.
#[derive(Debug, Clone)]
pub(crate) struct DualMask {
    /// The lattice's cell width, its inverse and one cell centre (local frame).
    w: f64,
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
        let (lo, n) = Self::extent(lattice, min, max)?;
        let cells = n[0] * n[1] * n[2];
        if cells > MAX_CELLS || cells.saturating_mul(bricks.len()) > MAX_WORK {
            return None;
        }
        // Which sides of the value each dual cell's corners reach, brick by brick (the
        // same cells `Volume::dual_cell_sides` reads at the dual cell's centre, where every
        // brick of the lattice picks the same corners anywhere inside it).
        let mut sides = vec![0u8; cells];
        let mut scratch = Vec::new();
        for br in bricks {
            vol.dual_sides_of_brick(
                br,
                &origin,
                inv_w,
                &lo,
                &n,
                f,
                iso,
                &mut sides,
                &mut scratch,
            );
        }
        let mut bits = vec![0u64; cells.div_ceil(64)];
        for (i, &s) in sides.iter().enumerate() {
            if s == 3 {
                bits[i / 64] |= 1 << (i % 64);
            }
        }
        Some(DualMask {
            w,
            inv_w,
            origin,
            lo,
            n,
            bits,
        })
    }

    /// The first dual cell and the number of dual cells per axis of the mask of the box
    /// `min..max` on `lattice`; `None` when the box is not finite, absurdly large, or
    /// absurdly far from the lattice's origin (a valid file may place a brick anywhere;
    /// cell indices then stay far inside `i64`, as [`DualMask::may_cross`] needs).
    fn extent(lattice: &Lattice, min: &[f64; 3], max: &[f64; 3]) -> Option<([i64; 3], [usize; 3])> {
        let &(_, inv_w, origin) = lattice;
        let mut lo = [0i64; 3];
        let mut n = [0usize; 3];
        for a in 0..3 {
            let (u0, u1) = ((min[a] - origin[a]) * inv_w, (max[a] - origin[a]) * inv_w);
            let near = |u: f64| u.abs() < 1e15;
            if !(near(u0) && near(u1) && u0 <= u1 && u1 - u0 < 1e6) {
                return None;
            }
            lo[a] = u0.floor() as i64;
            n[a] = (u1.floor() as i64 - lo[a] + 1) as usize;
        }
        n[0].checked_mul(n[1])?.checked_mul(n[2])?;
        Some((lo, n))
    }

    /// What building the mask of the box `min..max` of a region of `bricks` bricks costs,
    /// in (dual cell, brick) pairs (`usize::MAX` when it would not be built).
    pub(crate) fn work(lattice: &Lattice, min: &[f64; 3], max: &[f64; 3], bricks: usize) -> usize {
        Self::extent(lattice, min, max)
            .map(|(_, n)| n[0] * n[1] * n[2])
            .filter(|&cells| cells <= MAX_CELLS)
            .map_or(usize::MAX, |cells| cells.saturating_mul(bricks))
    }

    /// The parts of the region box `min..max` (the box the mask was built for) that
    /// `exact` must search, one per block of [`BLOCK`]³ dual cells: the box around the
    /// block's dual cells that can hold the value or touch one that can (a midpoint within
    /// round-off of a plane may read the corners of the dual cell beside it, see
    /// [`DualMask::may_cross`]). Everywhere else in the region every interval reads corners
    /// on one side of the value, so a ray that crosses none of these boxes needs no
    /// interval there. The faces between dual cells are computed from whole cell indices,
    /// so two boxes that touch share their face coordinate exactly and a ray leaves one
    /// where it enters the other. Empty when no dual cell can hold the value.
    pub(crate) fn sub_boxes(&self, min: &[f64; 3], max: &[f64; 3]) -> Vec<SubBox> {
        let n = self.n;
        let nb: [usize; 3] = n.map(|k| k.div_ceil(BLOCK));
        // Per block, the inclusive range of its marked dual cells (mask indices).
        let mut marked: Vec<([usize; 3], [usize; 3])> =
            vec![([usize::MAX; 3], [0; 3]); nb[0] * nb[1] * nb[2]];
        for (wi, &word) in self.bits.iter().enumerate() {
            let mut word = word;
            while word != 0 {
                let i = wi * 64 + word.trailing_zeros() as usize;
                word &= word - 1;
                let cell = [i % n[0], i / n[0] % n[1], i / (n[0] * n[1])];
                // The cell and its neighbours, and the blocks they lie in.
                let lo = cell.map(|c| c.saturating_sub(1));
                let hi: [usize; 3] = std::array::from_fn(|a| (cell[a] + 1).min(n[a] - 1));
                for bz in lo[2] / BLOCK..=hi[2] / BLOCK {
                    for by in lo[1] / BLOCK..=hi[1] / BLOCK {
                        for bx in lo[0] / BLOCK..=hi[0] / BLOCK {
                            let b = [bx, by, bz];
                            let m = &mut marked[bx + nb[0] * (by + nb[1] * bz)];
                            for a in 0..3 {
                                m.0[a] = m.0[a].min(lo[a].max(b[a] * BLOCK));
                                m.1[a] = m.1[a].max(hi[a].min(b[a] * BLOCK + BLOCK - 1));
                            }
                        }
                    }
                }
            }
        }
        let face = |a: usize, k: usize| self.origin[a] + (self.lo[a] + k as i64) as f64 * self.w;
        let mut out = Vec::new();
        for (i, &(lo, hi)) in marked.iter().enumerate() {
            if lo[0] == usize::MAX {
                continue;
            }
            let bmin: [f64; 3] = std::array::from_fn(|a| face(a, lo[a]).max(min[a]));
            let bmax: [f64; 3] = std::array::from_fn(|a| face(a, hi[a] + 1).min(max[a]));
            // A box that only touches the region (a dual cell past its face) holds no
            // interval the region's segment would have had.
            if (0..3).any(|a| bmin[a] > bmax[a] || (bmin[a] == bmax[a] && min[a] < max[a])) {
                continue;
            }
            out.push(SubBox {
                min: bmin,
                max: bmax,
                block: [i % nb[0], i / nb[0] % nb[1], i / (nb[0] * nb[1])].map(|b| b as u32),
            });
        }
        out
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
            let fl = floor_i64(u);
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
    use crate::lattice::Lattices;

    /// The mask built brick by brick is, bit for bit, the corner test of
    /// `Volume::dual_cell_sides` at every dual cell's centre: on per-cell noise (bricks of
    /// up to 3 cells, so many dual cells on brick edges), on a smooth field in bricks of up
    /// to 24 cells, and on data placed at 1e6, for iso values inside and outside the data,
    /// and a NaN one.
    #[test]
    fn masks_are_the_corner_test_at_every_dual_cell() {
        use crate::lattice::Lattices;
        let noise = |p: [f64; 3]| {
            let k = p.map(|x| (2.0 * x).floor() as i64);
            let h = ((k[0] * 73_856_093) ^ (k[1] * 19_349_663) ^ (k[2] * 83_492_791))
                .wrapping_mul(0x2545_f491_4f6c_dd1d_u64 as i64);
            ((h >> 40) & 0xff) as f64 / 255.0
        };
        let smooth = |p: [f64; 3]| (0.3 * p[0]).sin() + (0.2 * p[1]).cos() * p[2] / 16.0;
        let files = [
            crate::testvol::nested(8, [0.5, -3.0, 2.0], &[("n", &noise)], 3),
            crate::testvol::nested(16, [0.0; 3], &[("s", &smooth)], 24),
            crate::testvol::nested(8, [1e6, -1e6, 1e6], &[("n", &noise)], 5),
        ];
        let (mut masks, mut set) = (0, 0);
        for file in files {
            let view = crate::testvol::open(&file).expect("opens");
            let vol = Volume::new(&view).expect("volume");
            let mut bricks = Vec::new();
            for iso in [0.5, 0.9, 0.0, -5.0, f64::NAN] {
                for r in 0..vol.region_count() {
                    let l = Lattices::of(&vol, r);
                    let [lattice] = l.as_slice() else { continue };
                    let reg = vol.region(r);
                    vol.dual_bricks(r, &mut bricks);
                    let Some(mask) =
                        DualMask::build(&vol, &bricks, lattice, &reg.min, &reg.max, 0, iso)
                    else {
                        continue;
                    };
                    let mut i = 0;
                    for k in 0..mask.n[2] {
                        for j in 0..mask.n[1] {
                            for x in 0..mask.n[0] {
                                let idx = [
                                    x as i64 + mask.lo[0],
                                    j as i64 + mask.lo[1],
                                    k as i64 + mask.lo[2],
                                ];
                                let p: [f64; 3] = std::array::from_fn(|a| {
                                    mask.origin[a] + (idx[a] as f64 + 0.5) * mask.w
                                });
                                let (above, below) = vol.dual_cell_sides(&bricks, &p, 0, iso);
                                let bit = mask.bits[i / 64] >> (i % 64) & 1 == 1;
                                assert_eq!(
                                    bit,
                                    above && below,
                                    "region {r}, iso {iso}, dual cell {idx:?}"
                                );
                                set += usize::from(bit);
                                i += 1;
                            }
                        }
                    }
                    masks += 1;
                }
            }
        }
        assert!(masks > 1000 && set > 5000, "{masks} masks, {set} bits set");
    }

    /// The parts of a region: every dual cell that can hold the value, and every cell
    /// beside one, lies in exactly one part (so in no two: they do not overlap); each part
    /// lies inside its block and the region box; an empty mask has no parts, a sparse one
    /// leaves most of the region out; parts that touch share the face coordinate exactly.
    #[test]
    fn parts_cover_the_cells_that_can_hold_the_value_and_their_neighbours() {
        let mut seed = 3u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as usize
        };
        for case in 0..40 {
            let n = [1 + rnd() % 21, 1 + rnd() % 19, 1 + rnd() % 23];
            let cells = n[0] * n[1] * n[2];
            let mut mask = DualMask {
                w: 0.25,
                inv_w: 4.0,
                origin: [0.125, -3.0, 1e3],
                lo: [-4, 7, 0],
                n,
                bits: vec![0; cells.div_ceil(64)],
            };
            let set = match case {
                0 => 0,
                1..=5 => 1,
                _ => 1 + rnd() % (cells / 20 + 1),
            };
            for _ in 0..set {
                let i = rnd() % cells;
                mask.bits[i / 64] |= 1 << (i % 64);
            }
            let face = |a: usize, k: i64| mask.origin[a] + (mask.lo[a] + k) as f64 * mask.w;
            // The region: the mask's dual cells, cut by a quarter cell on the low faces.
            let min: [f64; 3] = std::array::from_fn(|a| face(a, 0) + 0.25 * mask.w);
            let max: [f64; 3] = std::array::from_fn(|a| face(a, n[a] as i64));
            let parts = mask.sub_boxes(&min, &max);
            if set == 0 {
                assert!(parts.is_empty());
                continue;
            }
            let bit = |c: [usize; 3]| {
                let i = c[0] + n[0] * (c[1] + n[1] * c[2]);
                mask.bits[i / 64] >> (i % 64) & 1 == 1
            };
            let mut covered_volume = 0.0;
            for p in &parts {
                for a in 0..3 {
                    let b = i64::from(p.block[a]) * BLOCK as i64;
                    assert!(
                        p.min[a] >= face(a, b).max(min[a])
                            && p.max[a] <= face(a, b + BLOCK as i64).min(max[a])
                    );
                    assert!(p.min[a] < p.max[a]);
                }
                covered_volume += (0..3).map(|a| p.max[a] - p.min[a]).product::<f64>();
            }
            for z in 0..n[2] {
                for y in 0..n[1] {
                    for x in 0..n[0] {
                        let c = [x, y, z];
                        let near = (0..27).any(|k| {
                            let o = [k % 3, k / 3 % 3, k / 9];
                            let q: [Option<usize>; 3] = std::array::from_fn(|a| {
                                (c[a] + o[a]).checked_sub(1).filter(|&v| v < n[a])
                            });
                            matches!(q, [Some(a), Some(b), Some(c)] if bit([a, b, c]))
                        });
                        // A point inside the cell (and inside the region).
                        let p: [f64; 3] =
                            std::array::from_fn(|a| face(a, c[a] as i64) + 0.6 * mask.w);
                        let holding = parts
                            .iter()
                            .filter(|b| (0..3).all(|a| p[a] >= b.min[a] && p[a] < b.max[a]))
                            .count();
                        assert!(holding <= 1, "case {case}: cell {c:?} in {holding} parts");
                        if near {
                            assert_eq!(holding, 1, "case {case}: cell {c:?} near a marked one");
                        }
                    }
                }
            }
            // One marked cell: its part holds it and its neighbours, nothing more.
            if parts.len() == 1 && mask.bits.iter().map(|b| b.count_ones()).sum::<u32>() == 1 {
                assert!(
                    covered_volume <= 27.0 * mask.w.powi(3) + 1e-12,
                    "case {case}"
                );
            }
            // Touching parts share their faces bit for bit.
            for p in &parts {
                for q in &parts {
                    for a in 0..3 {
                        if (p.max[a] - q.min[a]).abs() < 1e-9 {
                            assert_eq!(p.max[a].to_bits(), q.min[a].to_bits());
                        }
                    }
                }
            }
        }
    }

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
        // A box 1e20 cells from the lattice's origin (fuzz: a brick moved far away; its
        // cell indices overflowed `i64` arithmetic).
        let far = |x: f64| [reg.min, reg.max].map(|p| p.map(|v| v + x));
        for x in [1e20, -1e20, 3e15] {
            let [min, max] = far(x);
            assert!(build(min, max).is_none(), "{x}");
        }
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
