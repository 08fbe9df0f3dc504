//! How far from the origin baked data may lie: every voxel of a baked grid within
//! [`MAX_REACH`] voxels of the finest baked size of the origin (see
//! [`crate::error::MAX_BAKE_REACH_LOG2`] for why). A grid
//! translated to 1e300 with voxels of 0.1 has every voxel centre at the same double; baked,
//! it becomes bricks and regions of zero size that the viewer cannot frame. Such a grid is
//! refused before anything is made of it, naming the grid, its reach and voxel size. The
//! same bound keeps every stored coordinate finite, which the file format requires.

use super::grids::{with_topology, BakeGrid};
use crate::error::{BakeError, MAX_REACH};
use crate::grid::{AnyGrid, Grid, LeafTopology};
use crate::vdb::{AnyLocated, Located};

/// Refuses the first grid one of whose voxels (as a box, half a voxel around its centre)
/// lies more than [`MAX_REACH`] finest voxels (`finest` wide) from the origin.
pub(super) fn check_reach(grids: &[BakeGrid], finest: f64) -> Result<(), BakeError> {
    for g in grids {
        let reach = with_topology!(g, g => reach_of(g));
        let Some(reach) = reach else {
            continue;
        };
        // Too far, or beyond f64 altogether (infinite; NaN only if a transform were not
        // finite, which the levels refuse before): refused.
        let out = reach / finest;
        if out.is_nan() || out > MAX_REACH {
            let t = g.transform();
            return Err(BakeError::FarFromOrigin {
                grid: g.name().to_string(),
                reach,
                voxel_size: t.voxel_size[0],
                finest,
            });
        }
    }
    Ok(())
}

/// Largest |world coordinate| of the boxes of `g`'s leaves and tiles (whole leaves: an
/// upper bound by at most 8 voxels, without visiting voxels), or `None` for an empty grid.
fn reach_of<V: Copy, L: LeafTopology>(g: &Grid<V, L>) -> Option<f64> {
    let boxes = g
        .leaves
        .iter()
        .map(|l| (l.origin(), 8i64))
        .chain(g.tiles.iter().map(|t| (t.origin, i64::from(t.size))));
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for (origin, size) in boxes {
        for a in 0..3 {
            lo[a] = lo[a].min(i64::from(origin[a]));
            hi[a] = hi[a].max(i64::from(origin[a]) + size.max(1) - 1);
        }
    }
    if lo[0] > hi[0] {
        return None;
    }
    let t = g.transform;
    let mut reach = 0.0f64;
    for a in 0..3 {
        let w = t.voxel_size[a];
        for i in [lo[a] as f64 - 0.5, hi[a] as f64 + 0.5] {
            reach = reach.max((w * i + t.translation[a]).abs());
        }
    }
    Some(reach)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Leaf, Transform, LEAF_VOXELS};

    fn grid(w: f64, t: f64, origin: [i32; 3]) -> BakeGrid {
        BakeGrid::Decoded(AnyGrid::Vec3s(Grid {
            name: "vel".into(),
            transform: Transform {
                voxel_size: [w; 3],
                translation: [t; 3],
            },
            background: [0.0; 3],
            leaves: vec![Leaf {
                origin,
                active: [u64::MAX; 8],
                values: Box::new([[0.0; 3]; LEAF_VOXELS]),
            }],
            tiles: vec![],
        }))
    }

    #[test]
    fn grids_far_out_for_their_voxel_size_are_refused_with_their_reach() {
        assert!(check_reach(&[grid(0.1, 0.0, [0; 3])], 0.1).is_ok());
        // Index coordinates far out are fine where the finest voxels are large enough...
        assert!(check_reach(&[grid(1.0, 0.0, [1 << 25; 3])], 1.0).is_ok());
        // ... but not in voxels of a much finer level.
        assert!(check_reach(&[grid(1.0, 0.0, [1 << 25; 3])], 1e-3).is_err());
        // 2^26 finest voxels is the limit.
        let edge = (1u64 << 26) as f64 * 0.5;
        assert!(check_reach(&[grid(0.5, edge - 100.0, [0; 3])], 0.5).is_ok());
        assert!(check_reach(&[grid(0.5, edge + 100.0, [0; 3])], 0.5).is_err());
        let e = check_reach(&[grid(0.1, 1e300, [0; 3])], 0.1).expect_err("far");
        assert_eq!(
            e.to_string(),
            "grid \"vel\" (voxel size 0.1): voxels reach 1e300 from the origin, 1.0e301 voxels \
             of the finest size 0.1 out: too far for double precision to place cells exactly \
             (the bake takes 2^26, about 6.7e7, finest voxels); translate the grid towards the \
             origin"
        );
        // A reach beyond f64 (the file could not even store it) is refused too.
        assert!(check_reach(&[grid(1e303, 0.0, [1 << 20; 3])], 1e303).is_err());
    }
}
