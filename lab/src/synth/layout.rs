//! Where a scene's grids are: the world-aligned boxes of every level (see the module docs of
//! [`super`]), and the memory they would take, checked before anything is sampled.

use super::boxes::LATTICE_EPS;
use super::*;
use preprocess::vdb::write::NodeCounts;

pub(super) const WAKE_DOMAIN: Aabb = Aabb {
    min: [-2.0, -2.0, -2.0],
    max: [6.0, 2.0, 2.0],
};
pub(super) const WAKE_CORE: Aabb = Aabb {
    min: [-0.75, -0.75, -0.75],
    max: [5.0, 0.75, 0.75],
};
const UNIT_DOMAIN: Aabb = Aabb {
    min: [-1.0, -1.0, -1.0],
    max: [1.0, 1.0, 1.0],
};
/// The finest box of the `-nested` unit-domain scenes: the middle half of the domain per
/// axis, so that level boundaries cross the vortex of `lamb-oseen-nested` and
/// `burgers-nested` (its z faces cut the core, its x and y faces lie at 2 r_c).
const UNIT_CORE: Aabb = Aabb {
    min: [-0.5, -0.5, -0.5],
    max: [0.5, 0.5, 0.5],
};

/// Most levels of a scene (`--levels`, and the boxes of a layout).
pub(crate) const MAX_LEVELS: u32 = 10;

/// Most cells along an axis of a box: the bound of `--n0` (cells along the longest axis of
/// the coarsest grid), and of every axis of every box of a layout.
pub(crate) const MAX_CELLS_PER_AXIS: u32 = 1 << 16;

/// What a memory error names: the request, and how to make it smaller.
pub(crate) struct Request {
    pub what: String,
    pub hint: &'static str,
}

impl Request {
    /// A scene laid out by `--n0` and `--levels`.
    pub(crate) fn n0(scene: &str, n0: u32) -> Request {
        Request {
            what: format!("scene {scene:?} with n0 {n0}"),
            hint: "use a smaller --n0 or fewer --levels",
        }
    }

    /// A scene on the `boxes` boxes of a layout file.
    pub(crate) fn boxes(scene: &str, boxes: usize) -> Request {
        Request {
            what: format!("scene {scene:?} on {boxes} nested box(es)"),
            hint: "use smaller boxes, coarser cells or fewer levels",
        }
    }
}

/// A ball of solid: the voxels whose centres lie strictly inside it are left inactive, as a
/// solver leaves an obstacle's cells out of what it writes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    pub centre: [f64; 3],
    pub radius: f64,
}

impl Obstacle {
    /// Whether `p` lies strictly inside.
    pub fn contains(&self, p: [f64; 3]) -> bool {
        let d2: f64 = (0..3).map(|a| (p[a] - self.centre[a]).powi(2)).sum();
        d2 < self.radius * self.radius
    }
}

/// One grid of a scene layout: its name, voxel size, active index box (half-open) and the
/// obstacles whose voxels are not active.
#[derive(Debug, Clone, PartialEq)]
pub struct GridLayout {
    pub name: String,
    pub voxel_size: f64,
    /// First active voxel index per axis.
    pub lo: [i64; 3],
    /// One past the last active voxel index per axis.
    pub hi: [i64; 3],
    /// Voxels of the box whose centres lie inside one of these are inactive (empty for
    /// every `--n0` layout; see [`super::BoxLayout::obstacles`]).
    pub obstacles: Vec<Obstacle>,
}

impl GridLayout {
    /// Whether voxel `ijk` is active: inside the box and in no obstacle.
    pub(crate) fn is_active(&self, ijk: [i64; 3]) -> bool {
        (0..3).all(|a| ijk[a] >= self.lo[a] && ijk[a] < self.hi[a])
            && !self.obstacles.iter().any(|o| o.contains(self.centre(ijk)))
    }

    /// Voxels in the box (obstacles not subtracted), saturating at `u64::MAX` (an allowed
    /// `--n0` with ten levels has a finest box of 2^75 voxels, which a plain product would
    /// overflow).
    pub(crate) fn voxel_count(&self) -> u64 {
        saturating_product((0..3).map(|a| self.hi[a].saturating_sub(self.lo[a])))
    }

    /// Leaves [`sample_grid`] allocates for this box (every 8³ block the box touches; with
    /// obstacles an upper bound, since blocks with no active voxel are dropped), saturating
    /// at `u64::MAX`.
    pub(crate) fn leaf_count(&self) -> u64 {
        self.block_count(i64::from(LEAF_DIM))
    }

    /// Blocks of `d`³ voxels, aligned to multiples of `d`, that the box touches.
    fn block_count(&self, d: i64) -> u64 {
        saturating_product((0..3).map(|a| {
            if self.hi[a] <= self.lo[a] {
                0
            } else {
                (self.hi[a] - 1).div_euclid(d) - self.lo[a].div_euclid(d) + 1
            }
        }))
    }

    /// The nodes a grid on this box has at most (no tiles): what bounds its file size.
    pub(crate) fn node_counts(&self) -> NodeCounts {
        NodeCounts {
            leaves: self.leaf_count(),
            lower: self.block_count(128),
            upper: self.block_count(4096),
            tiles: 0,
        }
    }

    pub(crate) fn transform(&self) -> Transform {
        Transform {
            voxel_size: [self.voxel_size; 3],
            translation: [0.5 * self.voxel_size; 3],
        }
    }

    /// World-space centre of voxel `ijk`.
    pub(crate) fn centre(&self, ijk: [i64; 3]) -> [f64; 3] {
        ijk.map(|i| (i as f64 + 0.5) * self.voxel_size)
    }
}

/// The grids (finest first) that [`scene_grids`] fills, without sampling anything; refused
/// when they would not fit in memory ([`check_memory`]).
pub fn scene_layout(scene: &str, n0: u32, levels: u32) -> Result<Vec<GridLayout>, SynthError> {
    let out = scene_boxes(scene, n0, levels)?;
    check_memory(&Request::n0(scene, n0), &out, false)?;
    Ok(out)
}

/// The grids (finest first) of `scene` laid out by `n0` and `levels`, with no bound on
/// their size.
pub(crate) fn scene_boxes(
    scene: &str,
    n0: u32,
    levels: u32,
) -> Result<Vec<GridLayout>, SynthError> {
    let (domain, core, multi) = match scene {
        "wake" => (WAKE_DOMAIN, WAKE_CORE, true),
        "wake-single" => (WAKE_DOMAIN, WAKE_CORE, false),
        "lamb-oseen" | "burgers" | "abc" | "ring-plume" => (UNIT_DOMAIN, UNIT_CORE, false),
        "lamb-oseen-nested" | "burgers-nested" | "abc-nested" => (UNIT_DOMAIN, UNIT_CORE, true),
        _ => {
            return Err(SynthError::UnknownScene {
                name: scene.to_string(),
            })
        }
    };
    check_range("n0", n0, 2, MAX_CELLS_PER_AXIS)?;
    let levels = if multi {
        check_range("levels", levels, 1, MAX_LEVELS)?;
        levels
    } else {
        1
    };
    let extent = (0..3)
        .map(|a| domain.max[a] - domain.min[a])
        .fold(0.0, f64::max);
    let coarse = extent / f64::from(n0);
    let eps = LATTICE_EPS;
    // Coarsest first; `c` counts levels from the coarsest.
    let mut out: Vec<GridLayout> = Vec::with_capacity(levels as usize);
    for c in 0..levels {
        let h = coarse / f64::from(1u32 << c);
        let (lo, hi) = if c == 0 {
            (
                domain.min.map(|v| (v / h + eps).floor() as i64),
                domain.max.map(|v| (v / h - eps).ceil() as i64),
            )
        } else {
            let t = f64::from(c) / f64::from(levels - 1);
            let parent = 2.0 * h;
            let mut lo = [0i64; 3];
            let mut hi = [0i64; 3];
            for a in 0..3 {
                let bmin = domain.min[a] + t * (core.min[a] - domain.min[a]);
                let bmax = domain.max[a] + t * (core.max[a] - domain.max[a]);
                lo[a] = 2 * (bmin / parent + eps).floor() as i64;
                hi[a] = 2 * (bmax / parent - eps).ceil() as i64;
            }
            (lo, hi)
        };
        let name = if multi {
            format!("vel_l{}", levels - 1 - c)
        } else if scene == "ring-plume" {
            // Named as Blender's Mantaflow names its cache grids.
            "velocity".to_string()
        } else {
            "vel".to_string()
        };
        out.push(GridLayout {
            name,
            voxel_size: h,
            lo,
            hi,
            obstacles: Vec::new(),
        });
    }
    out.reverse();
    Ok(out)
}

fn saturating_product(extents: impl Iterator<Item = i64>) -> u64 {
    extents.fold(1u64, |acc, e| acc.saturating_mul(e.max(0).unsigned_abs()))
}

/// Refuses a scene whose leaves (velocity, plus speed when `speed_grids`) would take more than
/// [`MAX_LEAF_BYTES`], whatever the machine, before anything is sampled. Returns the leaf
/// count and bytes.
pub(crate) fn check_memory(
    request: &Request,
    layouts: &[GridLayout],
    speed_grids: bool,
) -> Result<(u64, u64), SynthError> {
    check_index_range(layouts)?;
    let per_leaf = leaf_bytes::<Vec3>() + if speed_grids { leaf_bytes::<f32>() } else { 0 };
    let leaves = layouts
        .iter()
        .fold(0u64, |acc, l| acc.saturating_add(l.leaf_count()));
    let bytes = leaves.saturating_mul(per_leaf);
    if bytes > MAX_LEAF_BYTES {
        return Err(SynthError::TooLarge {
            what: request.what.clone(),
            grids: layouts.len(),
            leaves,
            bytes,
            limit: MAX_LEAF_BYTES,
            hint: request.hint,
        });
    }
    Ok((leaves, bytes))
}

/// Refuses a scene `synth` cannot write, before anything is sampled: index boxes past a
/// VDB file's `i32` coordinates, a file over [`MAX_FILE_BYTES`] (bounded with every value
/// stored raw: a velocity grid and `scalars` float grids on each layout), and shapes the
/// machine's memory cannot hold while the values stream ([`files::limits::check_memory`]).
/// Returns the file's bound.
pub(super) fn check_write(
    request: &Request,
    layouts: &[GridLayout],
    scalars: u64,
) -> Result<u64, SynthError> {
    check_index_range(layouts)?;
    let leaves = layouts
        .iter()
        .fold(0u64, |acc, l| acc.saturating_add(l.leaf_count()));
    let bytes = layouts.iter().fold(0u64, |acc, l| {
        let nodes = l.node_counts();
        acc.saturating_add(nodes.bound(12))
            .saturating_add(scalars.saturating_mul(nodes.bound(4)))
    });
    if bytes > MAX_FILE_BYTES {
        return Err(SynthError::FileTooLarge {
            what: request.what.clone(),
            grids: layouts.len(),
            leaves,
            bytes,
            limit: MAX_FILE_BYTES,
            hint: request.hint,
        });
    }
    limits::check_memory(
        format!(
            "{} in {} grid(s) ({leaves} leaves, written a batch at a time)",
            request.what,
            layouts.len()
        ),
        leaves.saturating_mul(WRITE_BYTES_PER_LEAF),
    )
    .map_err(|error| SynthError::Memory {
        error,
        hint: request.hint,
    })?;
    Ok(bytes)
}

/// Refuses a grid whose leaves would not have `i32` origins.
pub(super) fn check_index_range(layouts: &[GridLayout]) -> Result<(), SynthError> {
    let fits =
        |v: i64| v >= i64::from(i32::MIN) && v <= i64::from(i32::MAX) - 2 * i64::from(LEAF_DIM);
    for l in layouts {
        if !(l.lo.iter().chain(&l.hi).all(|&v| fits(v))) {
            return Err(SynthError::IndexRange {
                grid: l.name.clone(),
                lo: l.lo,
                hi: l.hi,
            });
        }
    }
    Ok(())
}

fn check_range(what: &'static str, found: u32, min: u32, max: u32) -> Result<(), SynthError> {
    if (min..=max).contains(&found) {
        Ok(())
    } else {
        Err(SynthError::OutOfRange {
            what,
            min,
            max,
            found,
        })
    }
}
