//! Grids of the same voxel size that overlap. Leaf-cell classification drops a cell only
//! where *finer* grids cover it, so where two grids of one level overlap both keep their
//! cells, and the reconstruction (a weighted mean of the cells around a point) averages
//! them. That is harmless when they agree (one grid split into tiles that share a border)
//! and a silently wrong answer when they do not, so a disagreement is a warning naming both
//! grids, the size of the overlap and the largest difference.
//!
//! A cell of one grid overlaps the other where its centre lies in one of the other's leaf
//! cells; on one lattice that is the cell at the same place, on lattices offset by a
//! fraction of a cell the nearest one (and their values, taken half a cell or less apart,
//! then differ as much as the field does over that distance).

use rayon::prelude::*;

use crate::cells::{CellSet, SlotValues, Widen};
use crate::error::grid_labels;

use super::Input;

/// Values closer than this, relative to their size, are equal: what storing both as f32
/// (as the file does) cannot tell apart anyway.
const SAME: f64 = 4.0 * f32::EPSILON as f64;

/// One warning per pair of same-level grids whose leaf cells overlap with different
/// values, in grid order.
pub(super) fn same_level_overlaps(input: &Input) -> Vec<String> {
    match input {
        Input::Vector(sets, vals, _) => warnings(
            sets,
            vals,
            |a: &[f64; 3], b: &[f64; 3]| (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt(),
            |v| v.iter().map(|c| c.abs()).fold(0.0, f64::max),
        ),
        Input::Scalar(sets, vals, _) => {
            warnings(sets, vals, |a: &f64, b: &f64| (a - b).abs(), |v| v.abs())
        }
    }
}

/// Overlap of one grid's leaf cells with another's.
#[derive(Default)]
struct Overlap {
    /// Leaf cells of the first grid whose centre lies in a leaf cell of the second.
    cells: u64,
    /// Of those, the ones whose values differ.
    differing: u64,
    /// Largest difference and where (index coordinate in the first grid).
    largest: f64,
    at: [i32; 3],
}

fn warnings<T: Widen>(
    sets: &[CellSet],
    vals: &[SlotValues<T>],
    diff: impl Fn(&T, &T) -> f64 + Sync,
    size: impl Fn(&T) -> f64 + Sync,
) -> Vec<String> {
    let labels = grid_labels(sets.iter().map(|s| s.name.as_str()));
    let mut out = Vec::new();
    for i in 0..sets.len() {
        for j in i + 1..sets.len() {
            let (a, b) = (&sets[i], &sets[j]);
            if a.level != b.level || !boxes_meet(a, b) {
                continue;
            }
            let o = overlap(a, &vals[i], b, &vals[j], &diff, &size);
            if o.differing == 0 {
                continue;
            }
            out.push(format!(
                "grids {} and {} (voxel size {}) overlap in {} cells, {} of them with different values (largest difference {}, at voxel {:?} of {}); the file keeps both and the viewer averages them there",
                labels[i], labels[j], a.width, o.cells, o.differing, number(o.largest), o.at, labels[i]
            ));
        }
    }
    out
}

/// `x` as people write it: plain from 0.001 to a million, else with an exponent.
fn number(x: f64) -> String {
    if (1e-3..1e6).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// Whether the world boxes of the blocks of `a` and `b` meet (a quick test before the cells).
fn boxes_meet(a: &CellSet, b: &CellSet) -> bool {
    let bounds = |s: &CellSet| {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for o in &s.blocks {
            let l = s.centre(*o);
            let h = s.centre(o.map(|c| c.saturating_add(7)));
            for k in 0..3 {
                lo[k] = lo[k].min(l[k] - 0.5 * s.width);
                hi[k] = hi[k].max(h[k] + 0.5 * s.width);
            }
        }
        (lo, hi)
    };
    let ((alo, ahi), (blo, bhi)) = (bounds(a), bounds(b));
    (0..3).all(|k| alo[k] < bhi[k] && blo[k] < ahi[k])
}

/// The overlap of `a`'s leaf cells with `b`'s, block by block in parallel (summed in block
/// order, so the result does not depend on the thread count).
fn overlap<T: Widen>(
    a: &CellSet,
    av: &SlotValues<T>,
    b: &CellSet,
    bv: &SlotValues<T>,
    diff: &(impl Fn(&T, &T) -> f64 + Sync),
    size: &(impl Fn(&T) -> f64 + Sync),
) -> Overlap {
    // Index in `b` of the cell holding world coordinate `x` along axis `k`.
    let index_in_b = |k: usize, x: f64| -> Option<i32> {
        let i = ((x - b.transform.translation[k]) / b.transform.voxel_size[k]).round();
        (i >= f64::from(i32::MIN) && i <= f64::from(i32::MAX)).then_some(i as i32)
    };
    let per_block: Vec<Overlap> = (0..a.blocks.len())
        .into_par_iter()
        .map(|blk| {
            let mut o = Overlap::default();
            let origin = a.blocks[blk];
            // Skip blocks where `b` has nothing.
            let lo = a.centre(origin);
            let hi = a.centre(origin.map(|c| c.saturating_add(7)));
            let range: Option<Vec<(i32, i32)>> = (0..3)
                .map(|k| Some((index_in_b(k, lo[k])?, index_in_b(k, hi[k])?)))
                .collect();
            let Some(r) = range else {
                return o;
            };
            let blo = [r[0].0, r[1].0, r[2].0];
            let bhi = [r[0].1, r[1].1, r[2].1];
            if b.any_active_in(blo, bhi, 64) == Some(false) {
                return o;
            }
            for n in 0..crate::cells::BLOCK_CELLS {
                let slot = blk * crate::cells::BLOCK_CELLS + n;
                if !a.is_leaf(slot) {
                    continue;
                }
                let ijk = a.ijk(slot);
                let c = a.centre(ijk);
                let (Some(x), Some(y), Some(z)) = (
                    index_in_b(0, c[0]),
                    index_in_b(1, c[1]),
                    index_in_b(2, c[2]),
                ) else {
                    continue;
                };
                let Some(s) = b.leaf_slot([x, y, z]) else {
                    continue;
                };
                o.cells += 1;
                let (u, v) = (av.get(slot), bv.get(s));
                let d = diff(&u, &v);
                if d > SAME * size(&u).max(size(&v)) {
                    o.differing += 1;
                    if d > o.largest {
                        o.largest = d;
                        o.at = ijk;
                    }
                }
            }
            o
        })
        .collect();
    per_block
        .into_iter()
        .fold(Overlap::default(), |mut acc, o| {
            acc.cells += o.cells;
            acc.differing += o.differing;
            if o.largest > acc.largest {
                acc.largest = o.largest;
                acc.at = o.at;
            }
            acc
        })
}
