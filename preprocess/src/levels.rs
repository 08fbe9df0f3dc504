//! Levels from voxel sizes: level 0 is the finest; every other size must be the finest
//! size times a power of two. Transforms are uniform scale plus translation (the grid type
//! cannot express rotation or shear; the reader refuses those).

use crate::error::BakeError;
use crate::grid::Transform;

/// Relative tolerance when comparing voxel sizes.
const SIZE_TOL: f64 = 1e-6;

/// Level of every grid (same order as `grids`) and the cell width of every level.
pub(crate) fn assign_levels(
    grids: &[(&str, Transform)],
) -> Result<(Vec<u32>, Vec<f64>), BakeError> {
    for (name, t) in grids {
        let v = t.voxel_size;
        if !v.iter().all(|x| x.is_finite() && *x > 0.0)
            || !t.translation.iter().all(|x| x.is_finite())
        {
            return Err(BakeError::BadTransform {
                grid: name.to_string(),
                found: format!("voxel size {v:?}, translation {:?}", t.translation),
            });
        }
        if (v[1] - v[0]).abs() > SIZE_TOL * v[0] || (v[2] - v[0]).abs() > SIZE_TOL * v[0] {
            return Err(BakeError::NonCubicVoxels {
                grid: name.to_string(),
                voxel_size: v,
            });
        }
    }
    let mut widths: Vec<f64> = grids.iter().map(|(_, t)| t.voxel_size[0]).collect();
    widths.sort_by(f64::total_cmp);
    widths.dedup_by(|a, b| (*a - *b).abs() <= SIZE_TOL * *b);
    let Some(&finest) = widths.first() else {
        return Ok((vec![], vec![]));
    };
    for (name, t) in grids {
        let r = t.voxel_size[0] / finest;
        let k = r.log2().round();
        if (r - k.exp2()).abs() > SIZE_TOL * r {
            return Err(BakeError::NonPowerOfTwo {
                grid: name.to_string(),
                voxel_size: t.voxel_size[0],
                finest,
            });
        }
    }
    let levels = grids
        .iter()
        .map(|(_, t)| {
            let w = t.voxel_size[0];
            widths
                .iter()
                .position(|x| (x - w).abs() <= SIZE_TOL * x)
                .unwrap_or(0) as u32
        })
        .collect();
    Ok((levels, widths))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(w: [f64; 3]) -> Transform {
        Transform {
            voxel_size: w,
            translation: [0.0; 3],
        }
    }

    #[test]
    fn ranks_and_refusals() {
        let (lv, w) = assign_levels(&[("a", t([2.0; 3])), ("b", t([0.5; 3])), ("c", t([2.0; 3]))])
            .expect("valid");
        assert_eq!(lv, vec![1, 0, 1]);
        assert_eq!(w, vec![0.5, 2.0]);
        assert!(matches!(
            assign_levels(&[("a", t([1.0; 3])), ("b", t([3.0; 3]))]),
            Err(BakeError::NonPowerOfTwo { .. })
        ));
        assert!(matches!(
            assign_levels(&[("a", t([1.0, 1.0, 2.0]))]),
            Err(BakeError::NonCubicVoxels { .. })
        ));
        assert!(matches!(
            assign_levels(&[("a", t([0.0; 3]))]),
            Err(BakeError::BadTransform { .. })
        ));
    }
}
