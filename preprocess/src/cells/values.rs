//! One grid's cell values, one per slot of its [`super::CellSet`], kept at the precision
//! the file stored them in.
//!
//! Most solver output is single precision. Its velocities widened to `f64` took 24 bytes a
//! cell, the largest share of a bake's peak; kept as `f32` they take 12 and are widened
//! where they are read, which is exact, so every derived value is what it was. Values that
//! are computed rather than read (a repaired non-finite value, a staggered grid's centred
//! velocity) are not `f32` numbers, and those grids are held wide.

use std::ops::Range;
use std::path::Path;

use bytemuck::Pod;
use files::limits;
use files::scratch::ScratchValues;

use crate::error::BakeError;

/// A value the bake computes with (`f64`, `[f64; 3]`) and its single-precision form.
pub(crate) trait Widen: Pod + Default + Send + Sync {
    type Narrow: Pod + Default + Send + Sync;
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

/// Where the values of a cell set are kept: in memory up to `above` bytes, past it in an
/// unnamed scratch file in `dir` (the system's temporary directory when `None`), read
/// through a shared mapping whose pages every pass lets go behind itself. A billion cells
/// of single-precision velocity are 12 GiB: kept on disk, the bake holds only the part of
/// them it is working on.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Keep<'a> {
    pub dir: Option<&'a Path>,
    pub above: u64,
    /// Bytes written or read before the pages of values on disk are let go.
    pub window: u64,
    /// The bake keeps within a budget (`--memory`): a pass that writes values on disk all
    /// over them does so without readahead, which would map far more than a window
    /// between two releases (see `ScratchValues::read_ahead`); without a budget it is
    /// faster with.
    pub bounded: bool,
}

#[cfg(test)]
impl Keep<'_> {
    /// Everything in memory (small inputs, tests).
    pub(crate) const MEMORY: Keep<'static> = Keep {
        dir: None,
        above: u64::MAX,
        window: u64::MAX,
        bounded: false,
    };
}

/// Values of `size` bytes a pass over values on disk reads before it lets their pages go,
/// given a window of `window` bytes: at least one. The one rule every pass uses (cells,
/// their centred or widened copies, non-finite counts, fields; [`Keep::window_values`],
/// `Spill::window_values`).
pub(crate) fn window_values(window: u64, size: usize) -> usize {
    (window as usize / size.max(1)).max(1)
}

impl Keep<'_> {
    /// Values of `size` bytes a pass reads before it lets their pages go.
    pub(crate) fn window_values(&self, size: usize) -> usize {
        window_values(self.window, size)
    }
}

/// Values of one cell set, in memory or mapped from a scratch file.
#[derive(Debug)]
pub(crate) enum Slots<T> {
    Memory(Vec<T>),
    Mapped(ScratchValues<T>),
}

impl<T: Pod> Slots<T> {
    /// `n` zero values, kept as `keep` says (`what` names them in messages): a scratch
    /// file is sized, not written, so its pages, like those of a zeroed vector, cost
    /// nothing until they are written.
    pub(crate) fn zeroed(what: &str, n: usize, keep: Keep<'_>) -> Result<Slots<T>, BakeError> {
        let bytes = (n as u64).saturating_mul(std::mem::size_of::<T>() as u64);
        if bytes <= keep.above {
            return Ok(Slots::Memory(limits::zeroed_vec_of(what, n)?));
        }
        let dir = keep.dir.map_or_else(std::env::temp_dir, Path::to_path_buf);
        files::output::check_space_in(format!("{what}, kept on disk while baked"), &dir, bytes)?;
        let scratch = |source| BakeError::Scratch {
            what: what.to_string(),
            dir: dir.clone(),
            source,
        };
        let file = tempfile::tempfile_in(&dir).map_err(scratch)?;
        files::scratch::reserve(&file, bytes).map_err(scratch)?;
        Ok(Slots::Mapped(
            ScratchValues::map(&file, n).map_err(scratch)?,
        ))
    }

    #[inline]
    pub(crate) fn as_slice(&self) -> &[T] {
        match self {
            Slots::Memory(v) => v,
            Slots::Mapped(m) => m.as_slice(),
        }
    }

    pub(crate) fn as_mut_slice(&mut self) -> &mut [T] {
        match self {
            Slots::Memory(v) => v,
            Slots::Mapped(m) => m.as_mut_slice(),
        }
    }

    /// Whether faults on mapped values read ahead (see
    /// [`files::scratch::ScratchValues::read_ahead`]); nothing for values in memory.
    pub(crate) fn read_ahead(&self, on: bool) {
        if let Slots::Mapped(m) = self {
            m.read_ahead(on);
        }
    }

    /// Lets the pages of mapped values in `range` go (they stay in the file); nothing for
    /// values in memory.
    pub(crate) fn release(&self, range: Range<usize>) {
        if let Slots::Mapped(m) = self {
            m.release(range);
        }
    }
}

/// The values of one cell set, slot by slot.
#[derive(Debug)]
pub(crate) enum SlotValues<T: Widen> {
    /// As read from a single-precision grid.
    Narrow(Slots<T::Narrow>),
    Wide(Slots<T>),
}

/// The values of one cell set as slices: what the hot loops read ([`SlotValues::view`]),
/// so that a value costs one branch, not a look at where the values are kept too.
#[derive(Debug, Clone, Copy)]
pub(crate) enum SlotView<'a, T: Widen> {
    Narrow(&'a [T::Narrow]),
    Wide(&'a [T]),
}

impl<T: Widen> SlotView<'_, T> {
    /// The value of `slot`.
    #[inline]
    pub(crate) fn get(&self, slot: usize) -> T {
        match self {
            SlotView::Narrow(v) => T::widen(v[slot]),
            SlotView::Wide(v) => v[slot],
        }
    }
}

impl<T: Widen> SlotValues<T> {
    pub(crate) fn view(&self) -> SlotView<'_, T> {
        match self {
            SlotValues::Narrow(v) => SlotView::Narrow(v.as_slice()),
            SlotValues::Wide(v) => SlotView::Wide(v.as_slice()),
        }
    }

    /// The value of `slot`.
    #[inline]
    pub(crate) fn get(&self, slot: usize) -> T {
        match self {
            SlotValues::Narrow(v) => T::widen(v.as_slice()[slot]),
            SlotValues::Wide(v) => v.as_slice()[slot],
        }
    }

    pub(crate) fn len(&self) -> usize {
        match self {
            SlotValues::Narrow(v) => v.as_slice().len(),
            SlotValues::Wide(v) => v.as_slice().len(),
        }
    }

    /// Lets the pages of values kept on disk go (see [`Slots::release`]): every slot.
    pub(crate) fn release(&self) {
        match self {
            SlotValues::Narrow(v) => v.release(0..usize::MAX),
            SlotValues::Wide(v) => v.release(0..usize::MAX),
        }
    }

    /// The values to be written with values no `f32` holds: narrow ones are widened first,
    /// kept as `keep` says (only grids that need a repair pay for the wide copy; made a
    /// window at a time, so that values on disk let their pages go behind).
    pub(crate) fn wide_mut(&mut self, what: &str, keep: Keep<'_>) -> Result<&mut [T], BakeError> {
        if let SlotValues::Narrow(v) = self {
            let n = v.as_slice().len();
            let mut wide: Slots<T> = Slots::zeroed(what, n, keep)?;
            let span = keep.window_values(std::mem::size_of::<T>());
            for start in (0..n).step_by(span) {
                let end = (start + span).min(n);
                let from = &v.as_slice()[start..end];
                for (w, &x) in wide.as_mut_slice()[start..end].iter_mut().zip(from) {
                    *w = T::widen(x);
                }
                wide.release(0..usize::MAX);
                v.release(0..usize::MAX);
            }
            *self = SlotValues::Wide(wide);
        }
        match self {
            SlotValues::Wide(v) => Ok(v.as_mut_slice()),
            SlotValues::Narrow(_) => unreachable!("widened above"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn narrow_values_read_as_their_exact_widening_and_widen_once_for_writing() {
        let mut v: SlotValues<[f64; 3]> = SlotValues::Narrow(Slots::Memory(vec![
            [0.1, -2.5, f32::MAX],
            [1e-38, 3.0, -0.0],
        ]));
        assert_eq!(v.get(0), [f64::from(0.1f32), -2.5, f64::from(f32::MAX)]);
        v.wide_mut("test values", Keep::MEMORY).expect("small")[1][0] = 0.1;
        assert!(matches!(v, SlotValues::Wide(_)));
        assert_eq!(v.get(1), [0.1, 3.0, -0.0]);
        assert_eq!(v.get(0)[0], f64::from(0.1f32));
        assert_eq!(v.len(), 2);
    }
}
