//! Synthetic scenes: analytic flows sampled onto grids, as `qbricks-lab synth` writes them.
//!
//! # Layout
//! All grids share one world-aligned lattice: a grid of voxel size `h` has voxel `(i, j, k)`
//! centred at `((i + ½) h, (j + ½) h, (k + ½) h)` (transform: scale `h`, translation `h/2`),
//! so its cells are `[i h, (i + 1) h)` and every cell of a level is exactly covered by 2³
//! cells of the next finer level. Index coordinates are negative left of the world origin.
//!
//! * `wake`: `levels` nested boxes. The coarsest covers the scene domain
//!   x ∈ [-2, 6], y, z ∈ [-2, 2] with voxel size `8 / n0` (so `n0` voxels along x, the longest
//!   axis; the box snaps outward to the world-aligned lattice, so when 4 does not divide
//!   `n0` each side grows by less than one voxel). Each finer level halves the voxel size and covers a box interpolated
//!   linearly between the domain and the core box x ∈ [-0.75, 5], y, z ∈ [-0.75, 0.75]
//!   (sphere and ring train), snapped outward to the next coarser level's cells so that
//!   boxes nest exactly. Grids are named `vel_l0` (finest) … `vel_l{levels-1}` (coarsest)
//!   and returned in that order.
//! * `lamb-oseen-nested`, `burgers-nested`, `abc-nested`: those flows on `levels` nested
//!   boxes as for `wake`, between the domain [-1, 1]³ and the core box [-0.5, 0.5]³
//!   (`n0` voxels along an axis of the coarsest), for accuracy across level boundaries.
//! * any scene on the boxes of a layout file (`--boxes`, [`BoxLayout`]): the boxes as
//!   given, coarsest first in the file, each halving the cell width; grids named `vel_l0`
//!   (finest) … and returned in that order, as for `wake`; voxels inside the layout's
//!   obstacles (balls) are inactive on every level. `--n0` and `--levels` do not apply.
//! * `wake-single`, `lamb-oseen`, `burgers`, `abc`: one grid named `vel` over the scene
//!   domain (`wake-single`: the `wake` domain; the others: [-1, 1]³) with `n0` voxels along
//!   the longest axis; `levels` is ignored.
//!
//! Every voxel whose centre lies in a grid's box (and in none of a layout's obstacles) is
//! active and holds the exact velocity at its centre (f32); leaves at box edges have partial
//! active masks, inactive voxels hold the background (0, 0, 0), and blocks with no active
//! voxel are not stored. No tiles are written. Results are deterministic.

use format::Aabb;
use rayon::prelude::*;
use thiserror::Error;

use files::limits::{self, LimitError};

use crate::analytic::{self, Flow};

mod boxes;
mod layout;
#[cfg(test)]
mod tests;
mod write;

pub use boxes::{BoxLayout, LayoutError, LevelBox, Side, MAX_LAYOUT_BYTES, MAX_OBSTACLES};
use layout::check_write;
pub(crate) use layout::Request;
#[cfg(test)]
use layout::{check_memory, WAKE_CORE, WAKE_DOMAIN};
pub use layout::{scene_layout, GridLayout, Obstacle};
use preprocess::bake::memory::leaf_bytes;
use preprocess::grid::{leaf_offset, Grid, Leaf, Transform, Vec3, LEAF_DIM, LEAF_VOXELS};
use preprocess::vdb::write::source::{AnySource, GridSource, LeafShape};
use preprocess::vdb::write::{
    write_sources, Compression, MetaMap, MetaValue, WriteError, WriteOptions,
};
pub use write::{write_scene, write_scene_with, GridSummary, SynthOptions};

/// Most bytes of leaves a scene sampled into memory ([`scene_grids`]) may allocate
/// (velocity grids, plus the speed grids when asked for). Leaves are counted whole, as
/// `sample_grid` allocates them, partial leaves at box edges included: a voxel count alone
/// underestimates memory (a leaf of 3-vectors takes about 6.2 kB however few of its 512
/// voxels are active). `synth` itself does not hold its grids (it writes them a batch of
/// leaves at a time, see [`write_scene`]) and is bounded by [`MAX_FILE_BYTES`] instead.
pub(crate) const MAX_LEAF_BYTES: u64 = 4 << 30;

/// Most bytes a file `synth` writes may take (an upper bound: values stored raw), as the
/// bake's own bound on what it writes: 1 TiB, past any disk the project's machines have.
pub const MAX_FILE_BYTES: u64 = 1 << 40;

/// What `synth` holds per leaf while it writes: the leaf's shape twice (the grid's list and
/// the values' source), its place in the tree (B-tree entry, buffer order), its mask in the
/// file's topology block (written before the first value) and allocator rounding. Measured
/// 286 bytes (`abc --n0 1024`: 600 MB at the peak for 2.1 M leaves, one batch and the
/// program included), taken as 320.
const WRITE_BYTES_PER_LEAF: u64 = 320;

#[derive(Debug, Error)]
pub enum SynthError {
    #[error(transparent)]
    Write(#[from] WriteError),
    #[error("unknown scene {name:?} (expected one of: {})", analytic::SCENE_NAMES.join(", "))]
    UnknownScene { name: String },
    #[error("{what} must be in {min}..={max}, found {found}")]
    OutOfRange {
        what: &'static str,
        min: u32,
        max: u32,
        found: u32,
    },
    /// Over [`MAX_LEAF_BYTES`], whatever the machine. `what` names the request
    /// (`scene "wake" with n0 128`), `hint` how to make it smaller.
    #[error(
        "{what} in {grids} grid(s) needs {leaves} leaves ({} MiB of grid memory), more than the limit of {} MiB; {hint}",
        bytes >> 20,
        limit >> 20
    )]
    TooLarge {
        what: String,
        grids: usize,
        leaves: u64,
        bytes: u64,
        limit: u64,
        hint: &'static str,
    },
    /// Within the fixed bounds but over what this machine (memory, or `ulimit -v`) or the
    /// output's disk leaves: the shared limits of every command.
    #[error("{error}; {hint}")]
    Memory {
        error: LimitError,
        hint: &'static str,
    },
    /// A `--boxes` layout that cannot be sampled.
    #[error(transparent)]
    Layout(#[from] LayoutError),
    /// Over [`MAX_FILE_BYTES`], whatever the machine.
    #[error(
        "{what} in {grids} grid(s) would write {leaves} leaves, up to {} GiB, more than the limit of {} GiB; {hint}",
        bytes >> 30,
        limit >> 30
    )]
    FileTooLarge {
        what: String,
        grids: usize,
        leaves: u64,
        bytes: u64,
        limit: u64,
        hint: &'static str,
    },
    /// A grid whose index box a VDB file cannot address (coordinates are `i32`).
    #[error("grid {grid:?}: index box {lo:?}..{hi:?} is past the 32-bit coordinates of a VDB file; move the boxes nearer the origin or use coarser cells")]
    IndexRange {
        grid: String,
        lo: [i64; 3],
        hi: [i64; 3],
    },
}

/// Samples scene `scene` onto its grids (see the module docs for the layout), finest first.
pub fn scene_grids(scene: &str, n0: u32, levels: u32) -> Result<Vec<Grid<Vec3>>, SynthError> {
    scene_grids_with(scene, n0, levels, false, 1)
}

/// As [`scene_grids`]; with `staggered`, as MAC grids (see [`sample_grid_with`]); `frame`
/// (1-based) picks the time of a time-dependent scene (`ring-plume`).
pub fn scene_grids_with(
    scene: &str,
    n0: u32,
    levels: u32,
    staggered: bool,
    frame: u64,
) -> Result<Vec<Grid<Vec3>>, SynthError> {
    let layouts = scene_layout(scene, n0, levels)?;
    sample_scene(scene, &layouts, staggered, frame)
}

/// Samples scene `scene` (at `frame`) onto `layouts`, in their order; with `staggered`, as
/// MAC grids (see [`sample_grid_with`]).
pub fn sample_scene(
    scene: &str,
    layouts: &[GridLayout],
    staggered: bool,
    frame: u64,
) -> Result<Vec<Grid<Vec3>>, SynthError> {
    let flow = analytic::scene_at(scene, frame).ok_or_else(|| SynthError::UnknownScene {
        name: scene.to_string(),
    })?;
    Ok(layouts
        .iter()
        .map(|layout| sample_grid_with(flow.as_ref(), layout, staggered))
        .collect())
}

/// Origins of the leaves that hold `layout`'s box.
fn leaf_origins(layout: &GridLayout) -> Vec<[i64; 3]> {
    let d = i64::from(LEAF_DIM);
    let first = layout.lo.map(|v| v.div_euclid(d) * d);
    let counts: Vec<i64> = (0..3)
        .map(|a| (layout.hi[a] - first[a] + d - 1).div_euclid(d).max(0))
        .collect();
    let mut origins = Vec::with_capacity((counts[0] * counts[1] * counts[2]) as usize);
    for x in 0..counts[0] {
        for y in 0..counts[1] {
            for z in 0..counts[2] {
                origins.push([first[0] + x * d, first[1] + y * d, first[2] + z * d]);
            }
        }
    }
    origins
}

/// Samples `flow` at the voxel centres of `layout`'s box.
pub fn sample_grid(flow: &dyn Flow, layout: &GridLayout) -> Grid<Vec3> {
    sample_grid_with(flow, layout, false)
}

/// Samples `flow` on `layout`'s box: at voxel centres, or with `staggered` as a MAC grid in
/// OpenVDB's convention (component `c` of voxel `i` at the lower face, centre − ½h·e_c).
/// The active voxels are the same either way, so the upper faces of the last cells along
/// each axis are not stored (as in a solver's MAC grid of the same size as its cell grid).
pub(crate) fn sample_grid_with(
    flow: &dyn Flow,
    layout: &GridLayout,
    staggered: bool,
) -> Grid<Vec3> {
    let leaves = leaf_shapes(layout)
        .par_iter()
        .map(|shape| Leaf {
            origin: shape.origin,
            active: shape.active,
            values: Box::new(velocity_values(flow, layout, shape, staggered)),
        })
        .collect();
    Grid {
        name: layout.name.clone(),
        transform: layout.transform(),
        background: [0.0; 3],
        leaves,
        tiles: Vec::new(),
    }
}

/// The leaves of `layout`'s box that hold an active voxel, in the order the grids list
/// them: every 8³ block the box touches, less those wholly inside an obstacle (not stored,
/// as OpenVDB prunes them).
pub(crate) fn leaf_shapes(layout: &GridLayout) -> Vec<LeafShape> {
    leaf_origins(layout)
        .par_iter()
        .map(|&origin| LeafShape {
            // Index boxes lie inside i32 (`check_index_range`).
            origin: origin.map(|v| v as i32),
            active: leaf_mask(layout, origin),
        })
        .filter(|shape| shape.active != [0; 8])
        .collect()
}

/// Which voxels of the leaf at `origin` are active.
fn leaf_mask(layout: &GridLayout, origin: [i64; 3]) -> [u64; 8] {
    let mut active = [0u64; 8];
    let inside = |a: usize, v: i64| v >= layout.lo[a] && v < layout.hi[a];
    for x in 0..8usize {
        let i = origin[0] + x as i64;
        if !inside(0, i) {
            continue;
        }
        for y in 0..8usize {
            let j = origin[1] + y as i64;
            if !inside(1, j) {
                continue;
            }
            for z in 0..8usize {
                let k = origin[2] + z as i64;
                if inside(2, k) && layout.is_active([i, j, k]) {
                    let n = leaf_offset(x, y, z);
                    active[n >> 6] |= 1u64 << (n & 63);
                }
            }
        }
    }
    active
}

/// Index coordinate of voxel `n` of the leaf `shape`.
fn voxel_ijk(shape: &LeafShape, n: usize) -> [i64; 3] {
    let o = shape.origin.map(i64::from);
    [
        o[0] + (n >> 6) as i64,
        o[1] + ((n >> 3) & 7) as i64,
        o[2] + (n & 7) as i64,
    ]
}

fn is_set(active: &[u64; 8], n: usize) -> bool {
    (active[n >> 6] >> (n & 63)) & 1 == 1
}

/// The velocity at the leaf's active voxels (see [`sample_grid_with`]); inactive voxels
/// hold the background (0, 0, 0).
pub(crate) fn velocity_values(
    flow: &dyn Flow,
    layout: &GridLayout,
    shape: &LeafShape,
    staggered: bool,
) -> [Vec3; LEAF_VOXELS] {
    std::array::from_fn(|n| {
        if !is_set(&shape.active, n) {
            return [0.0; 3];
        }
        let p = layout.centre(voxel_ijk(shape, n));
        if staggered {
            std::array::from_fn(|c| {
                let mut f = p;
                f[c] -= 0.5 * layout.voxel_size;
                flow.velocity(f)[c] as f32
            })
        } else {
            let u = flow.velocity(p);
            [u[0] as f32, u[1] as f32, u[2] as f32]
        }
    })
}

/// `f` at the leaf's active voxel centres, 0 elsewhere.
pub(crate) fn scalar_values(
    layout: &GridLayout,
    shape: &LeafShape,
    f: &(impl Fn([f64; 3]) -> f64 + ?Sized),
) -> [f32; LEAF_VOXELS] {
    std::array::from_fn(|n| {
        if is_set(&shape.active, n) {
            f(layout.centre(voxel_ijk(shape, n))) as f32
        } else {
            0.0
        }
    })
}

/// `|u|` of each velocity, as [`speed_grid`] takes it.
pub(crate) fn speeds(values: &[Vec3; LEAF_VOXELS]) -> [f32; LEAF_VOXELS] {
    std::array::from_fn(|n| {
        let [x, y, z] = values[n];
        (x * x + y * y + z * z).sqrt()
    })
}

/// The speed grid's name for a velocity grid `name` (`vel…` → `speed…`).
pub(crate) fn speed_name(name: &str) -> String {
    match name.strip_prefix("vel") {
        Some(rest) => format!("speed{rest}"),
        None => format!("{name}_speed"),
    }
}

/// `|u|` of a velocity grid, same leaves and active masks, named `speed…` for `vel…`.
pub fn speed_grid(grid: &Grid<Vec3>) -> Grid<f32> {
    Grid {
        name: speed_name(&grid.name),
        transform: grid.transform,
        background: 0.0,
        leaves: grid
            .leaves
            .iter()
            .map(|l| Leaf {
                origin: l.origin,
                active: l.active,
                values: Box::new(speeds(&l.values)),
            })
            .collect(),
        tiles: Vec::new(),
    }
}
