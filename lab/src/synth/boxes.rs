//! Nested boxes given level by level (`qbricks-lab synth SCENE --boxes FILE.json`): any
//! layout of the kind AMR codes write, not only the one `--n0`/`--levels` interpolate.
//!
//! A layout lists its boxes coarsest first, each with its cell width and its world box:
//!
//! ```json
//! { "boxes": [
//!     { "cell": 0.0625,   "min": [-2, -2, -2],          "max": [6, 2, 2] },
//!     { "cell": 0.03125,  "min": [-1, -1.25, -1.25],    "max": [4, 1.25, 1.25] },
//!     { "cell": 0.015625, "min": [-0.75, -0.75, -0.75], "max": [2, 0.75, 0.75] } ] }
//! ```
//!
//! The grids are placed as every `synth` grid is (see [`super`]): cell-centred, translation
//! half a cell, so a box from `min` to `max` holds the cells `[i h, (i + 1) h)` with
//! `min = lo h` and `max = hi h`. Box `k` of `n` becomes the grid `vel_l{n-1-k}` (level 0 is
//! the finest, as everywhere else in qbricks), and the grids are returned finest first, as
//! [`super::scene_layout`] returns them.
//!
//! `"obstacles": [{"centre": [x, y, z], "radius": r}, …]` (optional) lists balls of solid:
//! every voxel whose centre lies strictly inside one is inactive on every level, as a solver
//! leaves an obstacle's cells out of the file (OpenVDB then prunes blocks with no active
//! voxel, and so does `synth`).
//!
//! A layout is refused, with the box, axis and side named, unless: there are 1 to
//! [`MAX_LEVELS`] boxes; every cell width is finite and positive and each box's width is
//! half the one before; every coordinate lies on its own box's cells; every box holds at
//! least one cell and at most [`MAX_CELLS_PER_AXIS`] cells along each axis (the `--n0`
//! bound); each box lies inside the one before it (faces may touch; a face between the
//! coarser box's cells is allowed, its coarse cells are then partly covered, which the bake
//! handles); every box lies within the bake's reach of the origin
//! ([`preprocess::error::MAX_REACH`] finest cells); and there are at most
//! [`MAX_OBSTACLES`] obstacles, each with a finite centre and a finite positive radius. The
//! leaves the boxes take are checked against the same limits as any other scene's: sampled
//! into memory, [`super::MAX_LEAF_BYTES`] and the machine's memory; written by `synth`,
//! [`super::MAX_FILE_BYTES`], the machine's memory for the leaves' shapes and the disk.

use serde::{Deserialize, Serialize};
use thiserror::Error;

use preprocess::error::MAX_REACH;

use super::layout::{check_memory, Request, MAX_CELLS_PER_AXIS, MAX_LEVELS};
use super::{GridLayout, Obstacle, SynthError};

/// Largest layout file read: ten boxes take well under a kilobyte; the rest is room for a
/// description.
pub const MAX_LAYOUT_BYTES: u64 = 1 << 20;

/// Most obstacles of a layout: every voxel is tested against each, so their number
/// multiplies the sampling time; a scene needs a few.
pub const MAX_OBSTACLES: usize = 16;

/// How far from a whole number of cells (in cells) a coordinate may be and still lie on
/// its box's cells: decimal widths such as 0.1 are not exact in binary, so `0.3 / 0.1`
/// is 2.9999999999999996. The same tolerance places `wake`'s boxes.
pub(super) const LATTICE_EPS: f64 = 1e-9;

/// One box of a [`BoxLayout`]: its cell width and its world box, both in world units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LevelBox {
    /// Cell width (the grid's voxel size).
    pub cell: f64,
    /// Lowest corner: a multiple of `cell` on every axis.
    pub min: [f64; 3],
    /// Highest corner: a multiple of `cell` on every axis.
    pub max: [f64; 3],
}

/// Nested boxes, coarsest first (see the module docs), as read from a layout file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxLayout {
    /// Free text for people (where the layout comes from); not used.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
    /// Coarsest first; each box halves the cell width and lies inside the one before.
    pub boxes: Vec<LevelBox>,
    /// Balls of solid whose voxels are inactive on every level, as a solver leaves an
    /// obstacle's cells out of its output (the wake's sphere: centre 0, radius 0.5).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub obstacles: Vec<Obstacle>,
}

/// Which face of a box a coordinate is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    Min,
    Max,
}

impl std::fmt::Display for Side {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Side::Min => "min",
            Side::Max => "max",
        })
    }
}

/// Axis names for messages.
const AXES: [&str; 3] = ["x", "y", "z"];

/// Why a layout is refused. `index` is the box's (or obstacle's) position in the file's
/// list (boxes coarsest first), from 0; `axis` is 0, 1, 2 for x, y, z.
#[derive(Debug, Error, PartialEq)]
pub enum LayoutError {
    #[error("not a box layout: {0} (expected {{\"boxes\": [{{\"cell\": W, \"min\": [x, y, z], \"max\": [x, y, z]}}, …]}}, coarsest first)")]
    Json(String),
    #[error("{found} boxes, expected 1 to {max} (one per level, coarsest first)")]
    BoxCount { found: usize, max: u32 },
    #[error("boxes[{index}]: cell width {cell} is not a finite positive number")]
    BadCell { index: usize, cell: f64 },
    #[error("boxes[{index}]: cell width {cell}, expected {expected} (half of boxes[{}]'s: list the boxes coarsest first, each refining the one before by 2)", index - 1)]
    NotHalved {
        index: usize,
        cell: f64,
        expected: f64,
    },
    #[error("boxes[{index}]: {} {side} is {value}, not a finite number", AXES[*axis])]
    NotFinite {
        index: usize,
        axis: usize,
        side: Side,
        value: f64,
    },
    #[error("boxes[{index}]: {} {side} {value} does not lie on the box's cells (a multiple of the cell width {cell}; the nearest are {} and {})", AXES[*axis], (value / cell).floor() * cell, (value / cell).ceil() * cell)]
    OffLattice {
        index: usize,
        axis: usize,
        side: Side,
        value: f64,
        cell: f64,
    },
    #[error("boxes[{index}]: {} from {min} to {max} holds no cell (max must be above min)", AXES[*axis])]
    Empty {
        index: usize,
        axis: usize,
        min: f64,
        max: f64,
    },
    #[error("boxes[{index}]: {} from {min} to {max} holds {cells} cells, more than the {max_cells} a box may hold along an axis", AXES[*axis])]
    TooManyCells {
        index: usize,
        axis: usize,
        min: f64,
        max: f64,
        cells: i64,
        max_cells: u32,
    },
    #[error("boxes[{index}]: {} {side} {value} is outside boxes[{}] ({} from {parent_min} to {parent_max}): every box must lie inside the one before", AXES[*axis], index - 1, AXES[*axis])]
    NotNested {
        index: usize,
        axis: usize,
        side: Side,
        value: f64,
        parent_min: f64,
        parent_max: f64,
    },
    #[error("{found} obstacles, at most {max} (every voxel is tested against each)")]
    ObstacleCount { found: usize, max: usize },
    #[error("obstacles[{index}]: centre {centre:?} and radius {radius} must be finite, the radius positive")]
    BadObstacle {
        index: usize,
        centre: [f64; 3],
        radius: f64,
    },
    #[error("boxes[{index}]: reaches {reach:e} from the origin, {:.3e} cells of the finest width {finest} out: more than the bake takes ({MAX_REACH:.1e}); move the boxes towards the origin", reach / finest)]
    TooFar {
        index: usize,
        reach: f64,
        finest: f64,
    },
}

impl BoxLayout {
    /// Parses a layout file's text (nothing is checked beyond the JSON; see
    /// [`BoxLayout::grids`]).
    pub fn from_json(text: &str) -> Result<BoxLayout, LayoutError> {
        serde_json::from_str(text).map_err(|e| LayoutError::Json(e.to_string()))
    }

    /// The layout as compact JSON (what `synth` records in the file's metadata).
    pub fn to_json(&self) -> String {
        // A struct of strings, numbers and arrays always serialises.
        serde_json::to_string(self).unwrap_or_default()
    }

    /// The layout of grids `grids` (finest first, as [`super::scene_layout`] returns them):
    /// the inverse of [`BoxLayout::grids`] for every layout it accepts.
    pub fn of_grids(grids: &[GridLayout]) -> BoxLayout {
        BoxLayout {
            description: String::new(),
            boxes: grids
                .iter()
                .rev()
                .map(|g| LevelBox {
                    cell: g.voxel_size,
                    min: g.lo.map(|v| v as f64 * g.voxel_size),
                    max: g.hi.map(|v| v as f64 * g.voxel_size),
                })
                .collect(),
            obstacles: grids
                .first()
                .map(|g| g.obstacles.clone())
                .unwrap_or_default(),
        }
    }

    /// Checks the layout (see the module docs) and returns its grids, finest first, named
    /// `vel_l0` (finest) … `vel_l{n-1}`, without sampling anything. `scene` only names the
    /// request in a memory error.
    pub fn grids(&self, scene: &str) -> Result<Vec<GridLayout>, SynthError> {
        let grids = self.check()?;
        check_memory(&Request::boxes(scene, grids.len()), &grids, false)?;
        Ok(grids)
    }

    /// Every check but the memory's; grids finest first.
    pub(crate) fn check(&self) -> Result<Vec<GridLayout>, LayoutError> {
        let n = self.boxes.len();
        if n == 0 || n > MAX_LEVELS as usize {
            return Err(LayoutError::BoxCount {
                found: n,
                max: MAX_LEVELS,
            });
        }
        if self.obstacles.len() > MAX_OBSTACLES {
            return Err(LayoutError::ObstacleCount {
                found: self.obstacles.len(),
                max: MAX_OBSTACLES,
            });
        }
        for (index, o) in self.obstacles.iter().enumerate() {
            if !(o.centre.iter().all(|c| c.is_finite()) && o.radius.is_finite() && o.radius > 0.0) {
                return Err(LayoutError::BadObstacle {
                    index,
                    centre: o.centre,
                    radius: o.radius,
                });
            }
        }
        let coarse = self.boxes[0].cell;
        // NaN until box 0's width is checked, which happens before any coordinate is.
        let finest = coarse / f64::from(1u32 << (n - 1));
        let mut out: Vec<GridLayout> = Vec::with_capacity(n);
        for (index, b) in self.boxes.iter().enumerate() {
            if !(b.cell.is_finite() && b.cell > 0.0) {
                return Err(LayoutError::BadCell {
                    index,
                    cell: b.cell,
                });
            }
            // Exact powers of two of the coarsest width, as `wake`'s levels are.
            let h = coarse / f64::from(1u32 << index);
            if index > 0 && (b.cell - h).abs() > LATTICE_EPS * h {
                return Err(LayoutError::NotHalved {
                    index,
                    cell: b.cell,
                    expected: h,
                });
            }
            let mut lo = [0i64; 3];
            let mut hi = [0i64; 3];
            for a in 0..3 {
                for (side, value) in [(Side::Min, b.min[a]), (Side::Max, b.max[a])] {
                    if !value.is_finite() {
                        return Err(LayoutError::NotFinite {
                            index,
                            axis: a,
                            side,
                            value,
                        });
                    }
                    let k = value / h;
                    // Beyond the reach, cell indices need not fit anything: refuse first.
                    if value.abs() / finest > MAX_REACH {
                        return Err(LayoutError::TooFar {
                            index,
                            reach: value.abs(),
                            finest,
                        });
                    }
                    if (k - k.round()).abs() > LATTICE_EPS {
                        return Err(LayoutError::OffLattice {
                            index,
                            axis: a,
                            side,
                            value,
                            cell: h,
                        });
                    }
                    let k = k.round() as i64;
                    match side {
                        Side::Min => lo[a] = k,
                        Side::Max => hi[a] = k,
                    }
                }
                let cells = hi[a] - lo[a];
                if cells < 1 {
                    return Err(LayoutError::Empty {
                        index,
                        axis: a,
                        min: b.min[a],
                        max: b.max[a],
                    });
                }
                if cells > i64::from(MAX_CELLS_PER_AXIS) {
                    return Err(LayoutError::TooManyCells {
                        index,
                        axis: a,
                        min: b.min[a],
                        max: b.max[a],
                        cells,
                        max_cells: MAX_CELLS_PER_AXIS,
                    });
                }
                if let Some(parent) = out.last() {
                    // The parent's cells are two of ours.
                    let (plo, phi) = (2 * parent.lo[a], 2 * parent.hi[a]);
                    for (side, v, outside) in [
                        (Side::Min, b.min[a], lo[a] < plo),
                        (Side::Max, b.max[a], hi[a] > phi),
                    ] {
                        if outside {
                            return Err(LayoutError::NotNested {
                                index,
                                axis: a,
                                side,
                                value: v,
                                parent_min: parent.lo[a] as f64 * parent.voxel_size,
                                parent_max: parent.hi[a] as f64 * parent.voxel_size,
                            });
                        }
                    }
                }
            }
            out.push(GridLayout {
                name: format!("vel_l{}", n - 1 - index),
                voxel_size: h,
                lo,
                hi,
                obstacles: self.obstacles.clone(),
            });
        }
        out.reverse();
        Ok(out)
    }
}
