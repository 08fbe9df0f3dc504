//! Non-finite input values (NaN, ±inf): counted, then replaced by the average of the
//! finite active face neighbours in the same grid (or zero when there is none).
//! Replacement reads only the original values, so the result does not depend on order.

use rayon::prelude::*;

use crate::cells::CellSet;

/// A cell value: a scalar or a velocity vector.
pub trait CellValue: Copy + Default + Send + Sync {
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
pub struct NonFiniteReport {
    pub count: u64,
    pub first: Option<[i32; 3]>,
}

/// Counts the non-finite active values of `set` (first one in slot order).
pub fn count<T: CellValue>(set: &CellSet, values: &[T]) -> NonFiniteReport {
    let bad: Vec<usize> = set
        .active_slots()
        .filter(|&s| !values[s].is_finite())
        .collect();
    NonFiniteReport {
        count: bad.len() as u64,
        first: bad.first().map(|&s| set.ijk(s)),
    }
}

/// Replaces every non-finite active value by the mean of its finite active face
/// neighbours (zero when none). Returns how many values were replaced.
pub fn replace<T: CellValue>(set: &CellSet, values: &mut [T]) -> u64 {
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
            if n == 0 {
                T::default()
            } else {
                sum.scale(1.0 / n as f64)
            }
        })
        .collect();
    for (&s, v) in bad.iter().zip(fixes) {
        values[s] = v;
    }
    bad.len() as u64
}
