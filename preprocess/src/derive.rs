//! Derived fields at cell centres: the velocity gradient (from which
//! [`crate::measures`] makes Q, λ2, vorticity and helicity) and speed.
//!
//! The gradient uses central differences (2·dx) on the cell's own grid; covered cells are
//! valid neighbours. Where a grid's own neighbour is missing (its edge or an inactive cell):
//! - [`Stencil::Central`] goes one-sided (second order when two cells are available,
//!   first order with one, zero with none);
//! - [`Stencil::CrossLevel`] takes the neighbour velocity at ±dx from the multi-level
//!   reconstruction [`reconstruct`] (the basis method, over all active cells of all grids,
//!   see [`CellChoice::Active`]) and keeps the central difference; where the
//!   reconstruction has no support it falls back to one-sided.
//!
//! # Staggered (MAC) grids
//! A grid of OpenVDB class `staggered` stores component `c` of voxel `i` on the *lower* face
//! of cell `i` along axis `c`, at index position `i − ½ e_c` (OpenVDB's
//! `StaggeredBoxSampler`/`StaggeredPointSampler` in `tools/Interpolation.h` read component
//! `c` at index point `p` by sampling the grid at `p + ½ e_c`). For such a grid
//! [`centre_from_faces`] gives the cell-centred velocity (mean of the two faces), which speed,
//! the velocity fields, the off-diagonal gradient terms and the cross-level reconstruction use;
//! the diagonal terms `∂u_c/∂x_c` come straight from the two faces of the cell
//! ([`gradient`] with [`VelocityField::faces`]): a compact central difference over one cell,
//! second order like the cell-centred stencil. Treating the faces as centres instead puts
//! every value half a cell off and makes Q first order.

use serde::Serialize;

use rayon::prelude::*;

use crate::cells::{CellSet, Keep, SlotValues, SlotView, Slots, BLOCK_CELLS};
use crate::error::BakeError;

/// Gradient stencil at grid edges and next to missing cells (`--stencil`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Stencil {
    /// Central differences; one-sided at grid edges and next to missing cells.
    #[default]
    Central,
    /// Central differences; at grid edges the neighbour velocity comes from the
    /// reconstructed multi-level field.
    CrossLevel,
}

/// Euclidean norm of a velocity.
pub fn speed(u: &[f64; 3]) -> f64 {
    (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt()
}

/// Velocity grids with their values (one per slot).
pub(crate) struct VelocityField<'a> {
    pub sets: &'a [CellSet],
    /// Cell-centred velocity per slot (for a staggered grid: [`centre_from_faces`]).
    pub values: Vec<SlotView<'a, [f64; 3]>>,
    /// Per grid: the face values of a staggered grid (as stored), `None` for a
    /// cell-centred one. May be shorter than `sets` (missing entries: cell-centred).
    pub faces: Vec<Option<SlotView<'a, [f64; 3]>>>,
}

impl<'a> VelocityField<'a> {
    pub(crate) fn new(
        sets: &'a [CellSet],
        values: &'a [SlotValues<[f64; 3]>],
        faces: &'a [Option<SlotValues<[f64; 3]>>],
    ) -> Self {
        VelocityField {
            sets,
            values: values.iter().map(SlotValues::view).collect(),
            faces: faces
                .iter()
                .map(|f| f.as_ref().map(SlotValues::view))
                .collect(),
        }
    }
}

/// Cell-centred velocity of a staggered grid from its face values (see the module docs):
/// component `c` of cell `i` is the mean of the faces `i − ½` (voxel `i`) and `i + ½`
/// (voxel `i + e_c`). Where the upper face's voxel is not active (grid edge, inactive
/// neighbour) the value is extrapolated linearly from the two lower faces (second order,
/// like the one-sided differences), or is the lower face alone when only it exists.
/// Inactive slots hold zero. They are kept as `keep` says, made a window of blocks at a
/// time, so that values on disk (these and the faces) let their pages go behind.
pub(crate) fn centre_from_faces(
    set: &CellSet,
    faces: &SlotValues<[f64; 3]>,
    keep: Keep<'_>,
) -> Result<Slots<[f64; 3]>, BakeError> {
    let what = format!("the cell-centred velocities of grid \"{}\"", set.name);
    let mut out: Slots<[f64; 3]> = Slots::zeroed(&what, faces.len(), keep)?;
    let span = keep.window_values(BLOCK_CELLS * 24) * BLOCK_CELLS;
    for start in (0..faces.len()).step_by(span) {
        let end = (start + span).min(faces.len());
        out.as_mut_slice()[start..end]
            .par_chunks_mut(BLOCK_CELLS)
            .enumerate()
            .for_each(|(k, block)| {
                for (n, v) in block.iter_mut().enumerate() {
                    let slot = start + k * BLOCK_CELLS + n;
                    if !set.is_active(slot) {
                        continue;
                    }
                    let ijk = set.ijk(slot);
                    let f = faces.get(slot);
                    for c in 0..3 {
                        v[c] = match set.active_neighbour(slot, ijk, c, 1) {
                            Some(up) => 0.5 * (f[c] + faces.get(up)[c]),
                            None => match set.active_neighbour(slot, ijk, c, -1) {
                                Some(down) => 1.5 * f[c] - 0.5 * faces.get(down)[c],
                                None => f[c],
                            },
                        };
                    }
                }
            });
        out.release(0..usize::MAX);
        faces.release();
    }
    Ok(out)
}

/// `∂u_a/∂x_a` at cell `ijk` (slot `slot`) of a staggered grid from its face values: the
/// difference of the cell's two faces over one cell; without the upper face, the
/// second-order one-sided difference over the faces `i − ½`, `i − 3/2`, `i − 5/2`
/// (weights 2, −3, 1), or the first-order one over two faces, or zero.
fn face_derivative(
    set: &CellSet,
    faces: &SlotView<'_, [f64; 3]>,
    slot: usize,
    ijk: [i32; 3],
    a: usize,
) -> f64 {
    let h = set.width;
    let face = |s: usize| faces.get(s)[a];
    let f0 = face(slot);
    if let Some(up) = set.active_neighbour(slot, ijk, a, 1) {
        return (face(up) - f0) / h;
    }
    match (
        set.active_neighbour(slot, ijk, a, -1),
        set.active_neighbour(slot, ijk, a, -2),
    ) {
        (Some(m), Some(mm)) => (2.0 * f0 - 3.0 * face(m) + face(mm)) / h,
        (Some(m), None) => (f0 - face(m)) / h,
        _ => 0.0,
    }
}

/// Below this total weight the reconstruction counts as "no data" (outer support edge).
const MIN_WEIGHT: f64 = 1e-9;

/// Which cells [`reconstruct`] blends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellChoice {
    /// Leaf cells only: the field the file stores and the viewer renders.
    Leaf,
    /// Every active cell, covered ones included: each grid's own trilinear interpolant,
    /// blended. Used by the cross-level stencil, because leaf-only blending next to a finer
    /// grid reduces to the nearest coarse value (first-order), whose difference over one
    /// fine cell gives an O(1) gradient error.
    Active,
}

/// Multi-level reconstruction `B(P) = Σ H_C(P) v_C / Σ H_C(P)` over the chosen cells of
/// all grids, with tents `H_C(P) = Π max(0, 1 − |P − c| / w)`. `None` where no tent
/// reaches P.
pub(crate) fn reconstruct(f: &VelocityField, p: [f64; 3], choice: CellChoice) -> Option<[f64; 3]> {
    let mut sum = [0.0; 3];
    let mut wsum = 0.0;
    for (set, vals) in f.sets.iter().zip(&f.values) {
        let w = set.width;
        let t = set.transform.translation;
        let mut base = [0i64; 3];
        let mut frac = [0.0; 3];
        for a in 0..3 {
            let x = (p[a] - t[a]) / w;
            let fl = x.floor();
            if !(fl > i32::MIN as f64 + 2.0 && fl < i32::MAX as f64 - 2.0) {
                return None;
            }
            base[a] = fl as i64;
            frac[a] = x - fl;
        }
        for dz in 0..2 {
            let wz = if dz == 0 { 1.0 - frac[2] } else { frac[2] };
            for dy in 0..2 {
                let wy = if dy == 0 { 1.0 - frac[1] } else { frac[1] };
                for dx in 0..2 {
                    let wx = if dx == 0 { 1.0 - frac[0] } else { frac[0] };
                    let h = wx * wy * wz;
                    if h <= 0.0 {
                        continue;
                    }
                    let ijk = [
                        (base[0] + dx) as i32,
                        (base[1] + dy) as i32,
                        (base[2] + dz) as i32,
                    ];
                    let slot = match choice {
                        CellChoice::Leaf => set.leaf_slot(ijk),
                        CellChoice::Active => set.active_slot(ijk),
                    };
                    if let Some(s) = slot {
                        let v = vals.get(s);
                        for c in 0..3 {
                            sum[c] += h * v[c];
                        }
                        wsum += h;
                    }
                }
            }
        }
    }
    (wsum > MIN_WEIGHT).then(|| sum.map(|s| s / wsum))
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Velocity gradient `g[i][j] = ∂uᵢ/∂xⱼ` at the active cell `ijk` of grid `s`, held in
/// `slot` (the caller has looked it up already).
pub(crate) fn gradient(
    f: &VelocityField,
    s: usize,
    ijk: [i32; 3],
    slot: usize,
    stencil: Stencil,
) -> [[f64; 3]; 3] {
    let set = &f.sets[s];
    let vals = &f.values[s];
    let h = set.width;
    let u0 = vals.get(slot);
    let at = |a: usize, d: i32| set.active_neighbour(slot, ijk, a, d).map(|t| vals.get(t));
    let mut g = [[0.0; 3]; 3];
    for a in 0..3 {
        let up = set.active_neighbour(slot, ijk, a, 1);
        let down = set.active_neighbour(slot, ijk, a, -1);
        if let (Some(p), Some(m)) = (up, down) {
            // Interior cell (nearly all of them): the central difference straight from the
            // value array, without the `Option` copies of the general case below, which
            // cost more than the arithmetic.
            let (p, m) = (vals.get(p), vals.get(m));
            for i in 0..3 {
                g[i][a] = (p[i] - m[i]) / (2.0 * h);
            }
            continue;
        }
        let mut plus = up.map(|t| vals.get(t));
        let mut minus = down.map(|t| vals.get(t));
        if stencil == Stencil::CrossLevel && (plus.is_none() || minus.is_none()) {
            let centre = set.centre(ijk);
            let mut p = centre;
            if plus.is_none() {
                p[a] = centre[a] + h;
                plus = reconstruct(f, p, CellChoice::Active);
            }
            if minus.is_none() {
                p[a] = centre[a] - h;
                minus = reconstruct(f, p, CellChoice::Active);
            }
        }
        let d = match (minus, plus) {
            (Some(m), Some(p)) => sub(p, m).map(|c| c / (2.0 * h)),
            (None, Some(p)) => match at(a, 2) {
                Some(pp) => [0, 1, 2].map(|c| (-3.0 * u0[c] + 4.0 * p[c] - pp[c]) / (2.0 * h)),
                None => sub(p, u0).map(|c| c / h),
            },
            (Some(m), None) => match at(a, -2) {
                Some(mm) => [0, 1, 2].map(|c| (3.0 * u0[c] - 4.0 * m[c] + mm[c]) / (2.0 * h)),
                None => sub(u0, m).map(|c| c / h),
            },
            (None, None) => [0.0; 3],
        };
        for i in 0..3 {
            g[i][a] = d[i];
        }
    }
    if let Some(Some(faces)) = f.faces.get(s) {
        for (a, row) in g.iter_mut().enumerate() {
            row[a] = face_derivative(set, faces, slot, ijk, a);
        }
    }
    g
}
