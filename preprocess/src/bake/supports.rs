//! Brick supports for the regions: each brick's box from its lattice, with coordinates
//! that meet across lattices snapped to one value, so that boxes which touch in exact
//! arithmetic touch in floating point too and no sliver regions appear between them.

use format::Aabb;

use crate::bricks::BrickBox;
use crate::cells::CellSet;

/// Brick supports (first centre − w .. first centre + dims·w), with coordinates that agree
/// up to rounding across lattices snapped to one value, so that no sliver regions appear.
pub(super) fn snapped_supports(sets: &[CellSet], bricks: &[BrickBox], finest: f64) -> Vec<Aabb> {
    let raw: Vec<Aabb> = bricks
        .iter()
        .map(|b| {
            let s = &sets[b.set];
            let lo = [0, 1, 2].map(|a| b.lo[a] as i64 - 1);
            let hi = [0, 1, 2].map(|a| b.lo[a] as i64 + b.dims[a] as i64);
            Aabb {
                min: s.transform.index_to_world(lo.map(|c| c as f64)),
                max: s.transform.index_to_world(hi.map(|c| c as f64)),
            }
        })
        .collect();
    let tol = 1e-7 * finest;
    let mut canon: [Vec<f64>; 3] = Default::default();
    for (a, c) in canon.iter_mut().enumerate() {
        c.extend(raw.iter().flat_map(|b| [b.min[a], b.max[a]]));
        c.sort_by(f64::total_cmp);
        // Keep the first value of every run of values closer than `tol` to their neighbour.
        let mut out: Vec<f64> = Vec::with_capacity(c.len());
        let mut last = f64::NEG_INFINITY;
        for &x in c.iter() {
            if x - last > tol {
                out.push(x);
            }
            last = x;
        }
        *c = out;
    }
    let snap = |a: usize, x: f64| -> f64 {
        let c = &canon[a];
        let i = c.partition_point(|&v| v <= x);
        if i == 0 {
            x
        } else {
            c[i - 1]
        }
    };
    raw.iter()
        .map(|b| Aabb {
            min: [0, 1, 2].map(|a| snap(a, b.min[a])),
            max: [0, 1, 2].map(|a| snap(a, b.max[a])),
        })
        .collect()
}
