//! Non-finite input values (NaN, ±inf): counted, then replaced by the average of the
//! finite active face neighbours in the same grid (or zero when there is none).
//! Replacement reads only the original values, so the result does not depend on order.

use rayon::prelude::*;

use crate::cells::CellSet;

/// A cell value: a scalar or a velocity vector.
pub(crate) trait CellValue: Copy + Default + Send + Sync {
    fn is_finite(&self) -> bool;
    fn add(self, o: Self) -> Self;
    fn scale(self, s: f64) -> Self;
}

impl CellValue for f64 {
    fn is_finite(&self) -> bool {
        f64::is_finite(*self)
    }
    fn add(self, o: Self) -> Self {
        self + o
    }
    fn scale(self, s: f64) -> Self {
        self * s
    }
}

impl CellValue for [f64; 3] {
    fn is_finite(&self) -> bool {
        self.iter().all(|c| c.is_finite())
    }
    fn add(self, o: Self) -> Self {
        [self[0] + o[0], self[1] + o[1], self[2] + o[2]]
    }
    fn scale(self, s: f64) -> Self {
        self.map(|c| c * s)
    }
}

/// First non-finite cell of a grid, for messages.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NonFiniteReport {
    pub count: u64,
    pub first: Option<[i32; 3]>,
}

/// Counts the non-finite active values of `set` (first one in slot order).
/// `value` gives the value of a slot; `release` is called every `every` slots and at the
/// end, so that values kept on disk let their pages go behind the pass.
pub(crate) fn count<T: CellValue>(
    set: &CellSet,
    value: impl Fn(usize) -> T,
    every: usize,
    release: impl Fn(),
) -> NonFiniteReport {
    let mut count = 0u64;
    let mut first = None;
    let mut next_release = every;
    for s in set.active_slots() {
        if s >= next_release {
            release();
            next_release = s + every;
        }
        if !value(s).is_finite() {
            count += 1;
            first.get_or_insert(s);
        }
    }
    release();
    NonFiniteReport {
        count,
        first: first.map(|s| set.ijk(s)),
    }
}

/// Replaces every non-finite active value by the mean of its finite active face
/// neighbours (zero when none). Returns how many values were replaced.
pub(crate) fn replace<T: CellValue>(set: &CellSet, values: &mut [T]) -> u64 {
    let bad: Vec<usize> = set
        .active_slots()
        .filter(|&s| !values[s].is_finite())
        .collect();
    let fixes: Vec<T> = bad
        .par_iter()
        .map(|&s| {
            let c = set.ijk(s);
            let mut sum = T::default();
            let mut n = 0u32;
            for a in 0..3 {
                for d in [-1, 1] {
                    let mut q = c;
                    q[a] = q[a].saturating_add(d);
                    if let Some(t) = set.active_slot(q) {
                        if values[t].is_finite() {
                            sum = sum.add(values[t]);
                            n += 1;
                        }
                    }
                }
            }
            let avg = sum.scale(1.0 / n.max(1) as f64);
            // No finite neighbour, or a mean that overflowed: zero.
            if n == 0 || !avg.is_finite() {
                T::default()
            } else {
                avg
            }
        })
        .collect();
    for (&s, v) in bad.iter().zip(fixes) {
        values[s] = v;
    }
    bad.len() as u64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{leaf_offset, Grid, Leaf, Transform, LEAF_VOXELS};

    #[test]
    fn replaced_by_mean_of_finite_neighbours() {
        let mut leaf = Leaf {
            origin: [0; 3],
            active: [0; 8],
            values: Box::new([0.0f64; LEAF_VOXELS]),
        };
        // A row x = 0..4 at y = z = 0 plus an isolated cell at (6, 6, 6).
        let cells = [
            ([0, 0, 0], 1.0),
            ([1, 0, 0], f64::NAN),
            ([2, 0, 0], 3.0),
            ([3, 0, 0], f64::INFINITY),
            ([6, 6, 6], f64::NAN),
        ];
        for (c, v) in cells {
            let n = leaf_offset(c[0], c[1], c[2]);
            leaf.active[n >> 6] |= 1 << (n & 63);
            leaf.values[n] = v;
        }
        let grid = Grid {
            name: "s".into(),
            transform: Transform {
                voxel_size: [1.0; 3],
                translation: [0.0; 3],
            },
            background: 0.0,
            leaves: vec![leaf],
            tiles: vec![],
        };
        let (set, mut vals) = CellSet::from_grid(grid, 0, |v| v).expect("small");
        assert_eq!(count(&set, |s| vals[s], 7, || ()).count, 3);
        assert_eq!(replace(&set, &mut vals), 3);
        let at = |c: [i32; 3]| vals[set.active_slot(c).expect("active")];
        assert_eq!(at([1, 0, 0]), 2.0); // mean of 1 and 3
        assert_eq!(at([3, 0, 0]), 3.0); // only finite neighbour: 3
        assert_eq!(at([6, 6, 6]), 0.0); // no neighbour
        assert_eq!(count(&set, |s| vals[s], 7, || ()).count, 0);
    }
}
