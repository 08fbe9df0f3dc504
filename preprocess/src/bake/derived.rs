//! Field stage: the value of every baked field at every cell of every brick.
//!
//! Bricks are computed in parallel, each writing straight into its own slice of every
//! field array (bricks lie one after the other, x fastest), so there are no per-brick
//! buffers to interleave afterwards; the values do not depend on the thread count.

use std::sync::atomic::{AtomicU64, Ordering};

use files::limits::{self, LimitError};
use rayon::prelude::*;

use crate::bricks::BrickBox;
use crate::derive::{gradient, speed, VelocityField};
use crate::fields::FieldKind;
use crate::measures;

use super::extra::ExtraGrid;
use super::{BakeOptions, Bricks, Cells, Input};

/// Baked fields: names, and the values of each (brick after brick, x fastest).
pub(super) struct FieldValues {
    pub(super) names: Vec<String>,
    pub(super) values: Vec<Vec<f32>>,
    /// Per field, for one resampled from an extra scalar grid: how many leaf cells have an
    /// active voxel of that grid around their centre (see [`super::extra_coverage`]).
    pub(super) covered: Vec<Option<u64>>,
}

/// The value of every field at every cell of every brick, derived from the velocity (Q,
/// vorticity, λ2 and helicity from one gradient per cell, speed, velocity components) or
/// resampled from an extra scalar grid; a scalar grid baked on its own is its only field.
/// Cells of a brick that are not leaf cells read as zero.
pub(super) fn derive_fields(
    cells: &Cells,
    bricks: &Bricks,
    opts: &BakeOptions,
) -> Result<FieldValues, LimitError> {
    match &cells.input {
        Input::Vector(sets, vals, faces) => {
            let kinds = opts
                .fields
                .clone()
                .unwrap_or(vec![FieldKind::Q, FieldKind::Speed]);
            let names: Vec<String> = kinds.iter().flat_map(FieldKind::names).collect();
            let needs_gradient = kinds.iter().any(FieldKind::needs_gradient);
            let field = VelocityField {
                sets,
                values: vals,
                faces,
            };
            // The grid of each extra scalar field, looked up once rather than per cell.
            let extras: Vec<Option<&ExtraGrid>> = kinds
                .iter()
                .map(|k| match k {
                    FieldKind::Scalar(n) => cells.extras.iter().find(|e| &e.name == n),
                    _ => None,
                })
                .collect();
            // Covered cells per extra field, summed brick by brick (the sum does not
            // depend on the order).
            let covered: Vec<AtomicU64> = kinds.iter().map(|_| AtomicU64::new(0)).collect();
            let values = per_brick(&bricks.boxes, names.len(), |b, out| {
                let set = &sets[b.set];
                let v = &vals[b.set];
                let mut hits = vec![0u64; kinds.len()];
                b.for_each_cell(set, |i, ijk, slot| {
                    let u = slot.map(|s| v.get(s)).unwrap_or_default();
                    // One gradient for every measure made from it.
                    let g = match slot.filter(|&s| needs_gradient && set.is_active(s)) {
                        Some(s) => gradient(&field, b.set, ijk, s, opts.stencil),
                        None => [[0.0; 3]; 3],
                    };
                    let mut f = 0;
                    for (ki, (k, extra)) in kinds.iter().zip(&extras).enumerate() {
                        match k {
                            FieldKind::Q => {
                                out[f][i] = measures::q(&g) as f32;
                                f += 1;
                            }
                            FieldKind::Speed => {
                                out[f][i] = speed(&u) as f32;
                                f += 1;
                            }
                            FieldKind::Vorticity => {
                                out[f][i] = measures::vorticity_magnitude(&g) as f32;
                                f += 1;
                            }
                            FieldKind::Lambda2 => {
                                out[f][i] = measures::lambda2(&g) as f32;
                                f += 1;
                            }
                            FieldKind::Helicity => {
                                out[f][i] = measures::helicity(&u, &g) as f32;
                                f += 1;
                            }
                            FieldKind::Velocity => {
                                for c in u {
                                    out[f][i] = c as f32;
                                    f += 1;
                                }
                            }
                            FieldKind::Scalar(_) => {
                                let p = set.centre(ijk);
                                let value = extra.map_or(0.0, |e| match e.sample(p) {
                                    Some(x) => {
                                        hits[ki] += 1;
                                        x
                                    }
                                    None => e.background(),
                                });
                                out[f][i] = value as f32;
                                f += 1;
                            }
                        }
                    }
                });
                for (c, h) in covered.iter().zip(hits) {
                    if h > 0 {
                        c.fetch_add(h, Ordering::Relaxed);
                    }
                }
            })?;
            let covered = kinds
                .iter()
                .zip(covered)
                .flat_map(|(k, c)| {
                    let c = matches!(k, FieldKind::Scalar(_)).then(|| c.into_inner());
                    vec![c; k.names().len()]
                })
                .collect();
            Ok(FieldValues {
                names,
                values,
                covered,
            })
        }
        Input::Scalar(sets, vals, name) => {
            let values = per_brick(&bricks.boxes, 1, |b, out| {
                let set = &sets[b.set];
                let v = &vals[b.set];
                b.for_each_cell(set, |i, _, slot| {
                    out[0][i] = slot.map(|s| v.get(s)).unwrap_or_default() as f32;
                });
            })?;
            Ok(FieldValues {
                names: vec![name.clone()],
                values,
                covered: vec![None],
            })
        }
    }
}

/// Runs `cell_values` on every brick in parallel with the brick's slice of each of the `nf`
/// field arrays (which it must fill), and returns the arrays: brick after brick, x fastest.
/// The arrays are allocated fallibly (they are the largest allocations after the cells).
fn per_brick(
    bricks: &[BrickBox],
    nf: usize,
    cell_values: impl Fn(&BrickBox, &mut [&mut [f32]]) + Sync,
) -> Result<Vec<Vec<f32>>, LimitError> {
    let total: usize = bricks.iter().map(|b| b.cells() as usize).sum();
    let mut fields: Vec<Vec<f32>> = (0..nf)
        .map(|_| limits::vec_of("the baked field values", total))
        .collect::<Result<_, _>>()?;
    // Cut every field into the bricks' slices, then regroup them per brick.
    let mut rest: Vec<&mut [f32]> = fields.iter_mut().map(Vec::as_mut_slice).collect();
    let mut slices: Vec<Vec<&mut [f32]>> = Vec::with_capacity(bricks.len());
    for b in bricks {
        let n = b.cells() as usize;
        slices.push(
            rest.iter_mut()
                .map(|r| {
                    let (head, tail) = std::mem::take(r).split_at_mut(n);
                    *r = tail;
                    head
                })
                .collect(),
        );
    }
    slices
        .into_par_iter()
        .zip(bricks)
        .for_each(|(mut out, b)| cell_values(b, &mut out));
    Ok(fields)
}
