//! Extra scalar fields (`--fields density,…`): scalar grids of the file resampled at the
//! velocity's leaf-cell centres. Their own grids need not share the velocity's lattice, so
//! they are sampled, not copied.

use super::grids::{decoded_cells, located_cells, BakeGrid};
use crate::cells::{CellSet, Keep, SlotValues};
use crate::error::BakeError;
use crate::grid::AnyGrid;
use crate::vdb::AnyLocated;

use super::{fix_nonfinite, Cells};

/// A scalar grid baked as an extra field: its cells, values and background, finest first
/// among grids of the same name.
pub(super) struct ExtraGrid {
    pub(super) name: String,
    grids: Vec<(CellSet, SlotValues<f64>, f64)>,
}

impl ExtraGrid {
    /// Lets the pages of its values kept on disk go.
    pub(super) fn release_values(&self) {
        for (_, values, _) in &self.grids {
            values.release();
        }
    }

    /// Trilinear sample at world point `p` from the finest grid with an active voxel among
    /// the 8 around `p`; inactive or missing voxels count as the background (OpenVDB's
    /// reading of a sparse grid). `None` where no grid has an active voxel around `p`: the
    /// value there is [`ExtraGrid::background`], and the point is not covered (see
    /// [`extra_coverage`]). At a voxel centre (same lattice as the velocity) this is the
    /// voxel's value.
    pub(super) fn sample(&self, p: [f64; 3]) -> Option<f64> {
        for (set, vals, bg) in &self.grids {
            let t = set.transform.translation;
            let mut base = [0i32; 3];
            let mut frac = [0.0; 3];
            let mut ok = true;
            for a in 0..3 {
                let x = (p[a] - t[a]) / set.width;
                let mut fl = x.floor();
                let mut fr = x - fl;
                // Snap to the lattice so that a voxel centre reads exactly that voxel.
                if fr > 1.0 - 1e-9 {
                    fl += 1.0;
                    fr = 0.0;
                } else if fr < 1e-9 {
                    fr = 0.0;
                }
                if !(fl > f64::from(i32::MIN) + 2.0 && fl < f64::from(i32::MAX) - 2.0) {
                    ok = false;
                    break;
                }
                base[a] = fl as i32;
                frac[a] = fr;
            }
            if !ok {
                continue;
            }
            let (mut sum, mut any) = (0.0, false);
            for corner in 0..8 {
                let d = [corner & 1, (corner >> 1) & 1, corner >> 2];
                let w: f64 = (0..3)
                    .map(|a| if d[a] == 0 { 1.0 - frac[a] } else { frac[a] })
                    .product();
                if w == 0.0 {
                    continue;
                }
                let ijk = [0, 1, 2].map(|a| base[a] + d[a]);
                match set.active_slot(ijk) {
                    Some(s) => {
                        any = true;
                        sum += w * vals.get(s);
                    }
                    None => sum += w * bg,
                }
            }
            if any {
                return Some(sum);
            }
        }
        None
    }

    /// The value where no grid of the field has data: the finest grid's background.
    pub(super) fn background(&self) -> f64 {
        self.grids.first().map_or(0.0, |g| g.2)
    }
}

/// Cell sets of the scalar grids baked as extra fields (non-finite values handled as for
/// the velocity), one entry per field name.
pub(super) fn extra_fields(
    names: &[String],
    mut grids: Vec<BakeGrid>,
    keep: Keep<'_>,
    strict: bool,
    warnings: &mut Vec<String>,
) -> Result<Vec<ExtraGrid>, BakeError> {
    let mut out = Vec::with_capacity(names.len());
    for name in names {
        let mine: Vec<BakeGrid>;
        (mine, grids) = grids.into_iter().partition(|g| g.name() == name);
        let mut sets = Vec::with_capacity(mine.len());
        let mut vals = Vec::with_capacity(mine.len());
        let mut bgs = Vec::with_capacity(mine.len());
        for g in mine {
            let (set, v, bg) = match g {
                BakeGrid::Decoded(AnyGrid::Float(g)) => {
                    let bg = f64::from(g.background);
                    let (s, v) = decoded_cells(g, 0, |v| v, keep)?;
                    (s, SlotValues::Narrow(v), bg)
                }
                BakeGrid::Decoded(AnyGrid::Double(g)) => {
                    let bg = g.background;
                    let (s, v) = decoded_cells(g, 0, |v| v, keep)?;
                    (s, SlotValues::Wide(v), bg)
                }
                BakeGrid::Located(AnyLocated::Float(g)) => {
                    let bg = f64::from(g.grid.background);
                    let (s, v) = located_cells(g, 0, |v| v, keep)?;
                    (s, SlotValues::Narrow(v), bg)
                }
                BakeGrid::Located(AnyLocated::Double(g)) => {
                    let bg = g.grid.background;
                    let (s, v) = located_cells(g, 0, |v| v, keep)?;
                    (s, SlotValues::Wide(v), bg)
                }
                _ => continue,
            };
            sets.push(set);
            vals.push(v);
            bgs.push(if bg.is_finite() { bg } else { 0.0 });
        }
        fix_nonfinite(&sets, &mut vals, keep, strict, warnings)?;
        let mut sorted: Vec<(CellSet, SlotValues<f64>, f64)> = sets
            .into_iter()
            .zip(vals)
            .zip(bgs)
            .map(|((s, v), b)| (s, v, b))
            .collect();
        sorted.sort_by(|a, b| a.0.width.total_cmp(&b.0.width));
        out.push(ExtraGrid {
            name: name.clone(),
            grids: sorted,
        });
    }
    Ok(out)
}

/// How much of the velocity an extra field covers: `covered` of the `leaf_cells` leaf cells
/// (per field of `names`, `None` for fields derived from the velocity) have an active voxel of the
/// field's grid among the 8 around their centre. A field that covers some of them but not
/// all is baked, with a warning giving the share (the rest read its background, as OpenVDB
/// reads a sparse grid: right for a fog volume that is only active where there is smoke,
/// wrong for a grid that was meant to cover the velocity); one that covers none is refused,
/// since every value would be the background (most likely a grid in another place or of
/// another transform than meant).
pub(super) fn extra_coverage(
    cells: &Cells,
    (names, covered): (&[String], &[Option<u64>]),
    sets: &[CellSet],
    leaf_cells: u64,
    warnings: &mut Vec<String>,
) -> Result<(), BakeError> {
    for (name, covered) in names.iter().zip(covered) {
        let (Some(covered), Some(extra)) = (covered, cells.extras.iter().find(|e| &e.name == name))
        else {
            continue;
        };
        if *covered == leaf_cells {
            continue;
        }
        let background = extra.background();
        if *covered == 0 {
            let extra_sets: Vec<&CellSet> = extra.grids.iter().map(|g| &g.0).collect();
            return Err(BakeError::FieldNotCovered {
                field: name.clone(),
                cells: leaf_cells,
                background,
                extra: world_box(&extra_sets),
                velocity: world_box(&sets.iter().collect::<Vec<_>>()),
            });
        }
        let share = 100.0 * *covered as f64 / leaf_cells as f64;
        // One decimal, never rounded up to a full 100.0 %.
        let share = if share > 99.9 && *covered < leaf_cells {
            "over 99.9".to_string()
        } else {
            format!("{share:.1}")
        };
        warnings.push(format!(
            "field \"{name}\": grid \"{name}\" covers {share} % of the velocity's leaf cells ({covered} of {leaf_cells}); the others read its background {background}"
        ));
    }
    Ok(())
}

/// The world box of the active cells of `sets` (cell boxes, not centres), as
/// `[x, y, z]..[x, y, z]`, for messages; `nothing` when there is no active cell.
fn world_box(sets: &[&CellSet]) -> String {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for set in sets {
        for slot in set.active_slots() {
            let c = set.centre(set.ijk(slot));
            for a in 0..3 {
                lo[a] = lo[a].min(c[a] - 0.5 * set.width);
                hi[a] = hi[a].max(c[a] + 0.5 * set.width);
            }
        }
    }
    if lo[0] > hi[0] {
        return "nothing".to_string();
    }
    format!("{lo:?}..{hi:?}")
}
