//! One grid's cell values, one per slot of its [`super::CellSet`], kept at the precision
//! the file stored them in.
//!
//! Most solver output is single precision. Its velocities widened to `f64` took 24 bytes a
//! cell, the largest share of a bake's peak; kept as `f32` they take 12 and are widened
//! where they are read, which is exact, so every derived value is what it was. Values that
//! are computed rather than read (a repaired non-finite value, a staggered grid's centred
//! velocity) are not `f32` numbers, and those grids are held wide.

use bytemuck::Zeroable;

/// A value the bake computes with (`f64`, `[f64; 3]`) and its single-precision form.
pub(crate) trait Widen: Copy + Default + Send + Sync {
    type Narrow: Copy + Default + Send + Sync + Zeroable;
    fn widen(v: Self::Narrow) -> Self;
}

impl Widen for f64 {
    type Narrow = f32;
    #[inline]
    fn widen(v: f32) -> f64 {
        f64::from(v)
    }
}

impl Widen for [f64; 3] {
    type Narrow = [f32; 3];
    #[inline]
    fn widen(v: [f32; 3]) -> [f64; 3] {
        v.map(f64::from)
    }
}

/// The values of one cell set, slot by slot.
#[derive(Debug, Clone)]
pub(crate) enum SlotValues<T: Widen> {
    /// As read from a single-precision grid.
    Narrow(Vec<T::Narrow>),
    Wide(Vec<T>),
}

impl<T: Widen> SlotValues<T> {
    /// The value of `slot`.
    #[inline]
    pub(crate) fn get(&self, slot: usize) -> T {
        match self {
            SlotValues::Narrow(v) => T::widen(v[slot]),
            SlotValues::Wide(v) => v[slot],
        }
    }

    pub(crate) fn len(&self) -> usize {
        match self {
            SlotValues::Narrow(v) => v.len(),
            SlotValues::Wide(v) => v.len(),
        }
    }

    /// The values to be written with values no `f32` holds: narrow ones are widened first
    /// (only grids that need a repair pay for the wide copy).
    pub(crate) fn wide_mut(&mut self) -> &mut Vec<T> {
        if let SlotValues::Narrow(v) = self {
            let wide: Vec<T> = v.iter().map(|&x| T::widen(x)).collect();
            *self = SlotValues::Wide(wide);
        }
        match self {
            SlotValues::Wide(v) => v,
            SlotValues::Narrow(_) => unreachable!("widened above"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn narrow_values_read_as_their_exact_widening_and_widen_once_for_writing() {
        let mut v: SlotValues<[f64; 3]> =
            SlotValues::Narrow(vec![[0.1, -2.5, f32::MAX], [1e-38, 3.0, -0.0]]);
        assert_eq!(v.get(0), [f64::from(0.1f32), -2.5, f64::from(f32::MAX)]);
        v.wide_mut()[1][0] = 0.1;
        assert!(matches!(v, SlotValues::Wide(_)));
        assert_eq!(v.get(1), [0.1, 3.0, -0.0]);
        assert_eq!(v.get(0)[0], f64::from(0.1f32));
        assert_eq!(v.len(), 2);
    }
}
