//! Which grids of a file a bake reads: the ones named by `--grid`, or by default every vec3
//! grid, or the grids of the one scalar name when the file has no vec3 grid. Kept apart from
//! the pipeline because it decides on names and kinds only, before any voxel is read.

use super::grids::BakeGrid;
use crate::error::BakeError;
pub use crate::grid::GridKind;

/// Indices (file order) of the grids to bake among `grids` (name, kind): every grid named
/// in `names`, or by default all vec3 grids, or the scalar grid(s) of the one scalar name
/// when there is no vec3 grid.
pub fn select_grids(grids: &[(&str, GridKind)], names: &[String]) -> Result<Vec<usize>, BakeError> {
    let quoted = |v: Vec<&str>| {
        v.iter()
            .map(|n| format!("\"{n}\""))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if !names.is_empty() {
        for n in names {
            if !grids.iter().any(|(g, _)| g == n) {
                return Err(BakeError::GridNotFound {
                    name: n.clone(),
                    available: quoted(grids.iter().map(|g| g.0).collect()),
                });
            }
        }
        let chosen: Vec<usize> = (0..grids.len())
            .filter(|&i| names.iter().any(|n| n == grids[i].0))
            .collect();
        if let Some(&i) = chosen.iter().find(|&&i| grids[i].1 == GridKind::Other) {
            return Err(BakeError::UnsupportedGrid {
                grid: grids[i].0.to_string(),
            });
        }
        let v = chosen.iter().find(|&&i| grids[i].1 == GridKind::Vector);
        let s = chosen.iter().find(|&&i| grids[i].1 == GridKind::Scalar);
        if let (Some(&v), Some(&s)) = (v, s) {
            return Err(BakeError::MixedKinds {
                vector: format!("\"{}\"", grids[v].0),
                scalar: format!("\"{}\"", grids[s].0),
            });
        }
        let mut snames: Vec<&str> = chosen
            .iter()
            .filter(|&&i| grids[i].1 == GridKind::Scalar)
            .map(|&i| grids[i].0)
            .collect();
        snames.dedup();
        snames.sort_unstable();
        snames.dedup();
        if snames.len() > 1 {
            return Err(BakeError::SeveralScalarGrids {
                names: quoted(snames),
            });
        }
        return Ok(chosen);
    }
    let vectors: Vec<usize> = (0..grids.len())
        .filter(|&i| grids[i].1 == GridKind::Vector)
        .collect();
    if !vectors.is_empty() {
        return Ok(vectors);
    }
    let scalars: Vec<usize> = (0..grids.len())
        .filter(|&i| grids[i].1 == GridKind::Scalar)
        .collect();
    let mut snames: Vec<&str> = scalars.iter().map(|&i| grids[i].0).collect();
    snames.sort_unstable();
    snames.dedup();
    match snames.len() {
        0 => Err(BakeError::NoGrids),
        1 => Ok(scalars),
        _ => Err(BakeError::AmbiguousScalar {
            names: quoted(snames),
        }),
    }
}

pub(super) fn select(grids: Vec<BakeGrid>, names: &[String]) -> Result<Vec<BakeGrid>, BakeError> {
    let kinds: Vec<(&str, GridKind)> = grids.iter().map(|g| (g.name(), g.kind())).collect();
    let keep = select_grids(&kinds, names)?;
    Ok(grids
        .into_iter()
        .enumerate()
        .filter(|(i, _)| keep.contains(i))
        .map(|(_, g)| g)
        .collect())
}
