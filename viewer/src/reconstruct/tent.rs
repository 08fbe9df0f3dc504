//! The tents of one brick at a point: per axis, the at most two cells whose tent is not
//! zero there, with its weight and slope. What every reconstruction sums over.

use crate::volume::BrickN;

/// Per axis: up to two (cell index, tent weight, tent slope in world units).
#[derive(Clone, Copy, Default)]
pub(super) struct Axis {
    pub(super) n: usize,
    pub(super) idx: [i64; 2],
    pub(super) w: [f64; 2],
    pub(super) dw: [f64; 2],
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
pub(super) fn axis_cells(u: f64, dim: i64, inv_w: f64) -> Axis {
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
pub(super) fn brick_axes(b: &BrickN, p: &[f64; 3]) -> Option<[Axis; 3]> {
    let u: [f64; 3] = std::array::from_fn(|a| (p[a] - b.origin[a]) * b.inv_w);
    cells_at(&u, &b.dims, b.inv_w)
}

/// The candidate cells on every axis at cell coordinates `u` of a brick of `dims` cells;
/// `None` when an axis has none.
#[inline(always)]
pub(super) fn cells_at(u: &[f64; 3], dims: &[i64; 3], inv_w: f64) -> Option<[Axis; 3]> {
    let mut axes = [Axis::default(); 3];
    for a in 0..3 {
        axes[a] = axis_cells(u[a], dims[a], inv_w);
        if axes[a].n == 0 {
            return None;
        }
    }
    Some(axes)
}
