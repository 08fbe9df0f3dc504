//! How much memory a bake needs, estimated from the grids' topology before any cell is
//! made, so that a bake the machine cannot hold is refused with its size through the one
//! shared limit ([`files::limits::check_memory`]) instead of dying in an allocation failure
//! half way through. A file of a few kilobytes can hold a single active tile of 640³
//! voxels: nothing about the file's size says what the bake will take, only its cells do.
//!
//! The estimate follows what the pipeline holds, stage by stage, and takes the largest:
//! - while a grid becomes cells, its decoded leaves ([`GridFootprint::decoded`]) are freed
//!   as its cells' values are written ([`crate::cells::CellSet::from_leaves`]): a grid
//!   read from a file is decoded a batch of leaves at a time, so only a batch is held; a
//!   decoded grid costs the larger of its leaves and its cells, not their sum;
//! - per slot of every 8³ block a cell set takes ([`GridFootprint::blocks`], 512 slots
//!   each, inactive slots included): the cells' values at the precision the file stored
//!   ([`slot_bytes`]: 12 bytes for a single-precision velocity, 24 for a double one), and
//!   the centred values made beside the faces of a staggered one; plus the masks;
//! - per active cell, once the fields are derived: 4 bytes for every baked field and
//!   [`CELL_BYTES`] for bricks, supports, regions, their ranges and what the allocator
//!   rounds up.
//!
//! Values past [`Spill::above`] (the fields together, each grid's cells on its own) stay in
//! scratch files and are read a part at a time: a chunk of fields, a window or two of
//! cells is held, not all. They still take address space, which `ulimit -v` bounds, so
//! that is checked too ([`mapped_bytes`]). With a budget (`--memory`), [`spill_within`]
//! chooses how much goes to disk, and what is left, the structure, must fit.
//!
//! Measured peaks (`/usr/bin/time -v`, maximum resident set, 2 threads) against it are in
//! docs/baking.md.

pub use crate::heap::return_freed;

use super::grids::{with_topology, BakeGrid};
use crate::cells::{BLOCK_CELLS, LEAF_BATCH};
use crate::error::BakeError;
use crate::grid::{AnyGrid, Grid, Leaf, LeafTopology, LEAF_DIM, LEAF_VOXELS};
use crate::vdb::{AnyLocated, Located};

use super::{BakeOptions, Spill};

/// Bytes per active cell besides the values and fields (bricks, supports, regions and
/// their value ranges, the KD-tree, allocator rounding): the measured residual (2.0 bytes
/// on a 512³ tile, since the regions are written straight into the file's arrays and
/// their boxes are derived when needed, not stored) with headroom for layouts with more
/// regions per cell (the independent layout has 1.5 times the 512³ tile's).
pub const CELL_BYTES: u64 = 3;
/// Bytes per brick with the regions, their brick lists and value ranges and the KD-tree
/// in scratch files ([`Spill::structure`]): what is left of the structure is the bricks,
/// their supports and the lists of support ids the region split holds along its recursion
/// (about 140 bytes a brick measured at a billion cells, 2.1 M bricks), with headroom.
pub const BRICK_BYTES_STRUCTURE_ON_DISK: u64 = 256;
/// Bytes per brick at least with the structure held: a brick's support makes about eight
/// regions (8.4 on the n0-128 wake, 6.3 on the independent layout, 8 at a billion cells)
/// of about 55 bytes each, beside the brick's own 140. Small bricks (many per cell) make
/// this more than [`CELL_BYTES`] a cell, which counts the usual layouts with headroom.
const BRICK_BYTES_STRUCTURE_HELD: u64 = 640;
/// Bytes the structure's arrays on disk hold resident at most: the pages written behind
/// the last window of each array of every part of the split being built at once, and the
/// arrays of parts still in memory (a few dozen parts of five arrays).
const STRUCTURE_ON_DISK_HELD: u64 = 16 << 20;
/// Bytes per brick while the fields are derived: about 80 measured, with headroom.
const BRICK_BYTES: u64 = 128;
/// Bytes of one baked field per cell (an `f32`).
pub const FIELD_BYTES: u64 = 4;
/// Bytes per block besides its values and masks' patterns: origin, index entry, and the
/// number of its pattern in each of the two masks (see `crate::cells::BlockMasks`).
const BLOCK_BYTES: u64 = 12 + 16 + 2 * 4;
/// Bytes of one mask pattern of a block partly set (wholly set or clear blocks share one).
const PATTERN_BYTES: u64 = 64;

/// Bytes per cell-set slot of a double-precision velocity (`[f64; 3]`).
pub const VELOCITY_SLOT_BYTES: u64 = 24;
/// Bytes per slot of a single-precision velocity, kept as it came (`[f32; 3]`).
pub const SINGLE_VELOCITY_SLOT_BYTES: u64 = 12;
/// Bytes per slot of a scalar grid, double (`f64`) or single (`f32`), baked on its own or
/// as an extra field.
pub const SCALAR_SLOT_BYTES: u64 = 8;
pub const SINGLE_SCALAR_SLOT_BYTES: u64 = 4;

/// Bytes per cell-set slot of `grid`'s values as stored (`SINGLE_SCALAR_SLOT_BYTES` …
/// `VELOCITY_SLOT_BYTES`).
pub fn slot_bytes(grid: &BakeGrid) -> u64 {
    grid.value_bytes()
}

/// Bytes per slot of values made beside the stored ones: a staggered grid's (one of
/// `staggered`) cell-centred velocities.
pub fn made_slot_bytes(grid: &BakeGrid, staggered: &[String]) -> u64 {
    if grid.is_vector() && staggered.iter().any(|s| s == grid.name()) {
        VELOCITY_SLOT_BYTES
    } else {
        0
    }
}

/// What one grid brings into a bake.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GridFootprint {
    /// Bytes of its decoded leaves (tiles take next to nothing).
    pub decoded: u64,
    /// 8³ blocks its cell set will take: at most this many (a block a leaf and a tile
    /// share is counted twice).
    pub blocks: u64,
    /// Of those, the blocks that may be partly active (at most this many): a leaf with
    /// inactive voxels, a leaf off the block lattice, a tile's blocks it covers in part.
    /// Only these hold an active mask pattern of their own.
    pub partial: u64,
    /// Whether another grid of the bake is finer: then any of its blocks may be partly
    /// covered, and hold a leaf mask pattern of its own.
    pub coarse: bool,
    /// The bricks its leaf cells make: an estimate from the topology
    /// ([`GridFootprint::with_bricks`]) until the bricks are made, then their count
    /// ([`Footprints::check_bricks`]).
    pub bricks: u64,
    /// Whether `bricks` is their count: then the structure held is counted by them too
    /// (small bricks make many regions), not only by the cells.
    pub bricks_made: bool,
    /// Active voxels, tiles counted as the voxels they cover.
    pub cells: u64,
    /// Whether its leaves are decoded a batch at a time as it becomes cells (a grid read
    /// from a file): then a batch of them is held, at most a window's worth.
    pub batched: bool,
    /// Bytes per slot of values the bake makes beside the stored ones
    /// ([`made_slot_bytes`]), kept like them.
    pub made: u64,
    /// For a grid decoded a batch at a time from a mapped file: the file's bytes per 1024
    /// bytes of decoded leaves (about 1024 uncompressed, far less zipped), since a batch is
    /// held beside the file's pages it came from.
    pub file_per_1024: u64,
}

impl GridFootprint {
    /// The footprint of `grid`: a located grid's leaves are decoded a batch at a time, so
    /// only a batch of them is ever held decoded.
    pub fn of(grid: &BakeGrid) -> GridFootprint {
        let mut f = with_topology!(grid, g => Self::of_grid(g));
        if grid.is_located() {
            let batch = (LEAF_BATCH as u64).saturating_mul(grid.value_bytes() * LEAF_VOXELS as u64);
            let file = grid.located_bytes().unwrap_or(0);
            f.file_per_1024 = file.saturating_mul(1024) / f.decoded.max(1);
            f.decoded = f.decoded.min(batch);
            f.batched = true;
        }
        f
    }

    pub fn of_grid<V: Copy, L: LeafTopology>(g: &Grid<V, L>) -> GridFootprint {
        let (mut blocks, mut partial) = (0u64, 0u64);
        let product = |n: [u64; 3]| n[0].saturating_mul(n[1]).saturating_mul(n[2]);
        for t in &g.tiles {
            // Per axis: the blocks the tile touches, and those it covers whole.
            let per_axis = |a: usize| {
                let lo = i64::from(t.origin[a]);
                let hi = (lo + i64::from(t.size)).min(i64::from(i32::MAX) + 1);
                if hi <= lo {
                    (0, 0)
                } else {
                    let touched = (hi - 1).div_euclid(8) - lo.div_euclid(8) + 1;
                    let whole = (hi.div_euclid(8) - (lo + 7).div_euclid(8)).max(0);
                    (touched as u64, whole as u64)
                }
            };
            let axes = [0, 1, 2].map(per_axis);
            let touched = product(axes.map(|a| a.0));
            let whole = product(axes.map(|a| a.1));
            blocks = blocks.saturating_add(touched);
            partial = partial.saturating_add(touched.saturating_sub(whole));
        }
        for l in &g.leaves {
            // A leaf off the block lattice straddles up to 8 blocks.
            let aligned = l.origin().iter().all(|c| c % LEAF_DIM == 0);
            blocks = blocks.saturating_add(if aligned { 1 } else { 8 });
            let full = l.active().iter().all(|&w| w == u64::MAX);
            partial = partial.saturating_add(match (aligned, full) {
                (true, true) => 0,
                (true, false) => 1,
                (false, _) => 8,
            });
        }
        GridFootprint {
            decoded: (g.leaves.len() as u64).saturating_mul(leaf_bytes::<V>()),
            blocks,
            partial,
            coarse: false,
            bricks: 0,
            bricks_made: false,
            cells: g.active_voxel_count(),
            batched: false,
            made: 0,
            file_per_1024: 0,
        }
        .with_bricks()
    }

    /// This footprint with its bricks estimated from the blocks: a block wholly active is
    /// about one brick (bricks are cut from tiles of 8³ cells anchored at the grid's corner,
    /// which a box of whole blocks has as many of as blocks), a block partly active up to
    /// eight (it straddles up to eight tiles), and a grid a finer one may cover in part
    /// one more a block for the cuts along the finer grid's edge (measured: 1.2 and 1.5 a
    /// block on the coarser levels of the benchmark layouts); never more than one a cell.
    /// Layouts that make more (whole blocks apart from each other, off the tiles) are found
    /// when the bricks are made ([`Footprints::check_bricks`]).
    pub fn with_bricks(self) -> GridFootprint {
        let covered = if self.coarse { self.blocks } else { 0 };
        GridFootprint {
            bricks: self
                .blocks
                .saturating_add(self.partial.saturating_mul(7))
                .saturating_add(covered)
                .min(self.cells),
            ..self
        }
    }

    /// The footprint of `n` leaves of `V` (no tiles), as `synth` samples a box: any of them
    /// may be partly active or covered (their masks are counted so), and they make about a
    /// brick each (a box of whole blocks but at its faces and obstacles).
    pub fn leaves<V>(n: u64, cells: u64) -> GridFootprint {
        GridFootprint {
            decoded: n.saturating_mul(leaf_bytes::<V>()),
            blocks: n,
            partial: n,
            coarse: true,
            bricks: n.min(cells),
            bricks_made: false,
            cells,
            batched: false,
            made: 0,
            file_per_1024: 0,
        }
    }
}

/// Bytes one decoded leaf of `V` takes: the entry in the grid's leaf list and its boxed
/// values.
pub fn leaf_bytes<V>() -> u64 {
    (std::mem::size_of::<Leaf<V>>() + std::mem::size_of::<[V; LEAF_VOXELS]>()) as u64
}

/// The estimated peak of a bake: `grids` with their bytes per slot of their cell sets as
/// stored (see the module docs), baked into `fields` fields, with the scalar grids `extras`
/// (and their bytes per slot) resampled as extra fields, values kept as `spill` says:
/// field values past `spill.above` bytes on disk, a chunk of them held; a grid's cell values
/// past `spill.above` bytes on disk, of which the passes over them (two at once: the grids
/// become cells in parallel) hold a window each. The largest of what the stages that
/// allocate most hold.
pub fn bake_bytes(
    grids: &[(GridFootprint, u64)],
    extras: &[(GridFootprint, u64)],
    fields: u64,
    spill: &Spill,
) -> u64 {
    // Values held in memory: those stored, and those made beside them, each unless kept
    // on disk.
    let values = |g: &(GridFootprint, u64)| {
        value_parts(g)
            .into_iter()
            .filter(|&b| b <= spill.above)
            .fold(0u64, u64::saturating_add)
    };
    // Every block's origin, index entry and pattern numbers; the active mask's patterns of
    // its blocks partly active, and the leaf mask's: the same blocks, or any block of a
    // grid a finer one may cover in part.
    let masks = |(f, _): &(GridFootprint, u64)| {
        let leaf_patterns = if f.coarse { f.blocks } else { f.partial };
        f.blocks.saturating_mul(BLOCK_BYTES).saturating_add(
            f.partial
                .saturating_add(leaf_patterns)
                .saturating_mul(PATTERN_BYTES),
        )
    };
    let sum = |list: &[(GridFootprint, u64)], each: &dyn Fn(&(GridFootprint, u64)) -> u64| {
        list.iter().map(each).fold(0u64, u64::saturating_add)
    };
    let mapped = mapped_values(grids, extras, spill).min(spill.window.saturating_mul(2));
    // The velocity (or scalar) grids become cells, the extra fields' grids still decoded
    // (a batch of leaves, for grids decoded as they become cells).
    // A batch of leaves decoded from a mapped file is held beside the file's pages it
    // came from until the batch is done (as many bytes again for an uncompressed file).
    let decoded = |(f, _): &(GridFootprint, u64)| match f.batched {
        true => {
            let batch = f.decoded.min(spill.window);
            batch.saturating_add(batch.saturating_mul(f.file_per_1024) / 1024)
        }
        false => f.decoded,
    };
    let converting = sum(grids, &|g| {
        values(g).max(decoded(g)).saturating_add(masks(g))
    })
    .saturating_add(sum(extras, &decoded))
    .saturating_add(mapped);
    // The extra fields' grids become cells beside the velocity's.
    let extra = sum(grids, &|g| values(g).saturating_add(masks(g)))
        .saturating_add(sum(extras, &|e| {
            values(e).max(decoded(e)).saturating_add(masks(e))
        }))
        .saturating_add(mapped);
    // The fields, bricks and regions beside all the cells; or, with the fields on disk,
    // a chunk of them beside the cells, then the bricks and regions with a chunk of the
    // fields (they stay on disk, read a part at a time, see `derived::FieldValues`).
    let field_bytes = fields.saturating_mul(FIELD_BYTES);
    // The structure: per cell with the regions held (their count follows the cells), per
    // brick with them on disk (what is left is the bricks' own).
    let structure_held = match spill.structure_on_disk() {
        false => 0,
        true => STRUCTURE_ON_DISK_HELD,
    };
    let structure = |(f, _): &(GridFootprint, u64)| match spill.structure_on_disk() {
        false if f.bricks_made => f
            .cells
            .saturating_mul(CELL_BYTES)
            .max(f.bricks.saturating_mul(BRICK_BYTES_STRUCTURE_HELD)),
        false => f.cells.saturating_mul(CELL_BYTES),
        true => f.bricks.saturating_mul(BRICK_BYTES_STRUCTURE_ON_DISK),
    };
    let cells = sum(grids, &|g| g.0.cells);
    let bricks = sum(grids, &|g| g.0.bricks);
    let held = sum(grids, &|g| values(g).saturating_add(masks(g)))
        .saturating_add(sum(extras, &|e| values(e).saturating_add(masks(e))))
        .saturating_add(mapped);
    let derived = if cells.saturating_mul(field_bytes) > spill.above {
        // The bricks are all that exists of the structure yet (about 80 bytes a brick).
        let chunk = spill.chunk.saturating_mul(field_bytes);
        let deriving = held
            .saturating_add(bricks.saturating_mul(BRICK_BYTES))
            .saturating_add(chunk);
        let after = sum(grids, &|g| masks(g).saturating_add(structure(g)))
            .saturating_add(chunk.max(spill.window))
            .saturating_add(structure_held);
        deriving.max(after)
    } else {
        held.saturating_add(cells.saturating_mul(field_bytes))
            .saturating_add(sum(grids, &structure))
    };
    converting.max(extra).max(derived)
}

/// Bytes of values a bake of `grids` (see [`bake_bytes`]) keeps in scratch files and maps:
/// the cell values past `spill.above` and the field values past it, and the structure when
/// it goes to disk (its arrays grow by doubling: twice what [`CELL_BYTES`] counts). They
/// take address space (`ulimit -v`) whether resident or not.
pub fn mapped_bytes(
    grids: &[(GridFootprint, u64)],
    extras: &[(GridFootprint, u64)],
    fields: u64,
    spill: &Spill,
) -> u64 {
    let cells: u64 = grids.iter().map(|g| g.0.cells).fold(0, u64::saturating_add);
    let field_values = cells.saturating_mul(fields.saturating_mul(FIELD_BYTES));
    let structure = match spill.structure_on_disk() {
        false => 0,
        true => cells.saturating_mul(2 * CELL_BYTES),
    };
    mapped_values(grids, extras, spill)
        .saturating_add(if field_values > spill.above {
            field_values
        } else {
            0
        })
        .saturating_add(structure)
}

/// A grid's values: those stored and those made beside them (a staggered grid's centred
/// velocities), each a set of values kept in memory or on disk as its size says.
fn value_parts((f, slot_bytes): &(GridFootprint, u64)) -> [u64; 2] {
    let slots = f.blocks.saturating_mul(BLOCK_CELLS as u64);
    [
        slots.saturating_mul(*slot_bytes),
        slots.saturating_mul(f.made),
    ]
}

/// Bytes of the grids' values kept on disk, as `spill` says.
fn mapped_values(
    grids: &[(GridFootprint, u64)],
    extras: &[(GridFootprint, u64)],
    spill: &Spill,
) -> u64 {
    grids
        .iter()
        .chain(extras)
        .flat_map(value_parts)
        .filter(|&b| b > spill.above)
        .fold(0u64, u64::saturating_add)
}

/// The spill a bake of `grids` (see [`bake_bytes`]) keeps within `budget` with, and its
/// estimate: [`Spill::within`] the budget, or, when that is over it, every value on disk;
/// `Err` with the least budget that would do when neither fits.
pub fn spill_within(
    grids: &[(GridFootprint, u64)],
    extras: &[(GridFootprint, u64)],
    fields: u64,
    budget: u64,
) -> Result<(Spill, u64), u64> {
    // Everything on disk: passes over values hold a sixteenth of the budget each (the
    // grids become cells two at once, each holding a batch of decoded leaves, the file's
    // pages they came from and a window of its cells), so that what is left of a small
    // budget is not spent on windows.
    let all_on_disk = |b: u64| {
        let within = Spill::within(b);
        Spill {
            above: 0,
            window: within.window.min(b / 16).max(1 << 20),
            ..within
        }
        .with_structure_on_disk()
    };
    let values_on_disk = |b: u64| Spill {
        above: 0,
        ..Spill::within(b)
    };
    for spill in [
        Spill::within(budget),
        values_on_disk(budget),
        all_on_disk(budget),
    ] {
        let need = bake_bytes(grids, extras, fields, &spill);
        if need <= budget {
            return Ok((spill, need));
        }
    }
    // The windows grow with the budget, slower than it: from what the structure alone
    // needs, a few steps up reach a budget the estimate fits in; the structure kept in
    // memory or on disk, whichever asks less (small bakes hold less than the fixed
    // resident share of arrays on disk).
    let least_with = |settings: &dyn Fn(u64) -> Spill, least: Spill| {
        let mut least = bake_bytes(grids, extras, fields, &least);
        for _ in 0..64 {
            let need = bake_bytes(grids, extras, fields, &settings(least));
            if need <= least {
                break;
            }
            least = need;
        }
        least
    };
    let held = Spill {
        structure: u64::MAX,
        ..Spill::least()
    };
    Err(least_with(&values_on_disk, held).min(least_with(
        &all_on_disk,
        Spill::least().with_structure_on_disk(),
    )))
}

/// The spill of a bake without a budget, and its estimate: the default settings, unless
/// they are over the machine's memory `limit` while the settings [`spill_within`] that
/// limit chooses are not (also with the scratch files they map within the address space
/// `left`, under `ulimit -v`): then the machine's limit is the budget, and the bake keeps
/// on disk what it must, as `--memory` of that limit would.
pub fn spill_without_budget(
    grids: &[(GridFootprint, u64)],
    extras: &[(GridFootprint, u64)],
    fields: u64,
    limit: u64,
    left: Option<u64>,
) -> (Spill, u64) {
    let default = Spill::default();
    let need = bake_bytes(grids, extras, fields, &default);
    if need <= limit {
        return (default, need);
    }
    match spill_within(grids, extras, fields, limit) {
        Ok((spill, within))
            if left.is_none_or(|left| {
                within.saturating_add(mapped_bytes(grids, extras, fields, &spill)) <= left
            }) =>
        {
            (spill, within)
        }
        _ => (default, need),
    }
}

/// Refuses, before any cell is made, a bake of `grids` (and of the scalar grids `extras`
/// as extra fields) whose estimated peak ([`bake_bytes`]) is over the shared memory limit,
/// or over the budget `opts.memory` even with its values on disk ([`spill_within`]).
/// Returns where the bake keeps its values (as `opts.spill` says, or within the budget),
/// and the footprints the estimate was made from, to check again once the bricks are made.
pub(super) fn check_bake_memory(
    grids: &[BakeGrid],
    extras: &[BakeGrid],
    opts: &BakeOptions,
    input_cells: u64,
) -> Result<(Spill, Footprints), BakeError> {
    let vector = grids.first().is_some_and(BakeGrid::is_vector);
    let fields = if vector {
        opts.fields.as_ref().map_or(2, |kinds| {
            kinds.iter().map(|k| k.names().len() as u64).sum::<u64>()
        })
    } else {
        1
    };
    let footprint = |g: &BakeGrid| {
        let f = GridFootprint {
            made: made_slot_bytes(g, &opts.staggered),
            ..GridFootprint::of(g)
        };
        (f, slot_bytes(g))
    };
    let mut per_grid: Vec<(GridFootprint, u64)> = grids.iter().map(footprint).collect();
    // A grid with a finer one beside it (as `classify_leaves` compares them).
    let finest = grids
        .iter()
        .map(|g| g.transform().voxel_size[0])
        .fold(f64::INFINITY, f64::min);
    for ((f, _), g) in per_grid.iter_mut().zip(grids) {
        *f = GridFootprint {
            coarse: finest < g.transform().voxel_size[0] * (1.0 - 1e-9),
            ..*f
        }
        .with_bricks();
    }
    let extras: Vec<(GridFootprint, u64)> = extras.iter().map(footprint).collect();
    let mut names: Vec<&str> = grids.iter().map(BakeGrid::name).collect();
    names.dedup();
    let names = names
        .iter()
        .map(|n| format!("\"{n}\""))
        .collect::<Vec<_>>()
        .join(", ");
    let grid_s = if names.contains(", ") {
        "grids"
    } else {
        "grid"
    };
    let what = format!("the bake of {input_cells} input cells ({grid_s} {names})");
    let (spill, need) = match opts.memory {
        None => {
            let default = Spill {
                dir: None,
                ..opts.spill.clone()
            } == Spill::default();
            let limit = files::limits::memory_limit().bytes;
            let left = files::limits::address_space_left();
            match default.then(|| spill_without_budget(&per_grid, &extras, fields, limit, left)) {
                Some((spill, need)) => (
                    Spill {
                        dir: opts.spill.dir.clone(),
                        ..spill
                    },
                    need,
                ),
                None => (
                    opts.spill.clone(),
                    bake_bytes(&per_grid, &extras, fields, &opts.spill),
                ),
            }
        }
        Some(budget) => match spill_within(&per_grid, &extras, fields, budget) {
            Ok((spill, need)) => (
                Spill {
                    dir: opts.spill.dir.clone(),
                    ..spill
                },
                need,
            ),
            Err(least) => {
                return Err(BakeError::OverBudget {
                    what,
                    budget,
                    least,
                    shared: opts.memory_shared,
                })
            }
        },
    };
    let mapped = mapped_bytes(&per_grid, &extras, fields, &spill);
    files::limits::check_memory(&what, need)?;
    files::limits::check_address_space(&what, need.saturating_add(mapped))?;
    let footprints = Footprints {
        grids: per_grid,
        extras,
        fields,
        what,
    };
    Ok((spill, footprints))
}

/// What a bake's memory estimate was made from ([`check_bake_memory`]).
#[derive(Debug, Clone)]
pub(super) struct Footprints {
    grids: Vec<(GridFootprint, u64)>,
    extras: Vec<(GridFootprint, u64)>,
    fields: u64,
    /// The bake as its messages name it.
    what: String,
}

impl Footprints {
    /// Checks a bake within a budget (`opts.memory`) again once its bricks are made, with
    /// their count in place of the estimate from the blocks ([`GridFootprint::with_bricks`]),
    /// and returns where it keeps its values from here on: as `spill` says, or with the
    /// regions and KD-tree on disk too where only that fits (they are not made yet, and
    /// the file is the same either way). A layout that makes far more bricks than its
    /// blocks suggest and fits neither way is refused here, before the fields and regions
    /// are made, naming the least budget that would do (one it passes both checks
    /// within), instead of going over the budget.
    pub(super) fn check_bricks(
        &self,
        bricks: u64,
        spill: &Spill,
        opts: &BakeOptions,
    ) -> Result<Spill, BakeError> {
        let Some(budget) = opts.memory else {
            return Ok(spill.clone());
        };
        let made = self.made(bricks);
        if let Some(fits) = self.fitting(&made, spill, budget) {
            return Ok(fits);
        }
        Err(BakeError::OverBudget {
            what: self.what.clone(),
            budget,
            least: self.least_with(bricks),
            shared: opts.memory_shared,
        })
    }

    /// `spill`, or it with the structure on disk, whichever fits `budget` with the bricks
    /// `made` (the first that does).
    fn fitting(&self, made: &[(GridFootprint, u64)], spill: &Spill, budget: u64) -> Option<Spill> {
        after_bricks(spill)
            .into_iter()
            .find(|s| bake_bytes(made, &self.extras, self.fields, s) <= budget)
    }

    /// The grids' footprints with `bricks` made in all.
    fn made(&self, bricks: u64) -> Vec<(GridFootprint, u64)> {
        let mut grids = self.grids.clone();
        for (i, (f, _)) in grids.iter_mut().enumerate() {
            f.bricks = if i == 0 { bricks } else { 0 };
            f.bricks_made = true;
        }
        grids
    }

    /// The least budget a bake that makes `bricks` bricks passes both checks within: the
    /// first ([`spill_within`], from the blocks' estimate) chooses where values are kept,
    /// the second ([`Footprints::check_bricks`]) must then fit with the bricks made.
    fn least_with(&self, bricks: u64) -> u64 {
        let made = self.made(bricks);
        let mut least = match spill_within(&made, &self.extras, self.fields, 0) {
            Ok((_, need)) | Err(need) => need,
        };
        // A larger budget may keep more in memory, which the bricks made may not fit; the
        // values held are bounded, so this ends.
        for _ in 0..64 {
            let need = match spill_within(&self.grids, &self.extras, self.fields, least) {
                Ok((spill, _)) => after_bricks(&spill)
                    .iter()
                    .map(|s| bake_bytes(&made, &self.extras, self.fields, s))
                    .min()
                    .unwrap_or(u64::MAX),
                Err(need) => need,
            };
            if need <= least {
                break;
            }
            least = need;
        }
        least
    }
}

/// Where a bake whose bricks are made may keep its values from there on, in the order
/// [`Footprints::check_bricks`] tries them: as chosen before, or with the regions and
/// KD-tree on disk too (they are not made yet).
fn after_bricks(spill: &Spill) -> [Spill; 2] {
    [spill.clone(), spill.clone().with_structure_on_disk()]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Tile, Transform};

    fn grid(tiles: Vec<Tile<[f32; 3]>>, leaves: Vec<Leaf<[f32; 3]>>) -> Grid<[f32; 3]> {
        Grid {
            name: "vel".into(),
            transform: Transform {
                voxel_size: [1.0; 3],
                translation: [0.0; 3],
            },
            background: [0.0; 3],
            leaves,
            tiles,
        }
    }

    #[test]
    fn a_tile_counts_the_blocks_it_covers_and_a_leaf_one() {
        let tiles = (0..5)
            .flat_map(|x| (0..5).flat_map(move |y| (0..5).map(move |z| [x, y, z])))
            .map(|o: [i32; 3]| Tile {
                origin: o.map(|c| c * 128),
                size: 128,
                value: [1.0, 0.0, 0.0],
            })
            .collect();
        let f = GridFootprint::of_grid(&grid(tiles, vec![]));
        assert_eq!(f.cells, 640 * 640 * 640);
        assert_eq!(f.blocks, 80 * 80 * 80);
        assert_eq!(
            f.partial, 0,
            "tiles on the block lattice cover their blocks whole"
        );
        assert_eq!(f.decoded, 0);
        let no_spill = Spill {
            above: u64::MAX,
            ..Spill::default()
        };
        // 640³ cells, two fields: about 35 bytes per cell (24 of velocity, 8 of fields, 3
        // of structure, the masks), 9.3 GB.
        let need = bake_bytes(&[(f, VELOCITY_SLOT_BYTES)], &[], 2, &no_spill);
        assert!(need > 35 * f.cells && need < 36 * f.cells, "{need}");

        let leaf = Leaf {
            origin: [8, 0, -8],
            active: [1, 0, 0, 0, 0, 0, 0, 0],
            values: Box::new([[0.0; 3]; LEAF_VOXELS]),
        };
        let f = GridFootprint::of_grid(&grid(vec![], vec![leaf]));
        // One active voxel still takes a whole block of slots.
        assert_eq!((f.blocks, f.partial, f.cells), (1, 1, 1));
        assert!(bake_bytes(&[(f, VELOCITY_SLOT_BYTES)], &[], 2, &no_spill) > 512 * 24);
    }

    /// Only blocks that may be partly active count a mask pattern of their own: a leaf
    /// with every voxel active holds none, one with a voxel off holds one, one off the
    /// block lattice may hold eight, and a tile one for each block it covers in part.
    #[test]
    fn blocks_partly_active_are_counted_from_the_topology() {
        let leaf = |origin: [i32; 3], active: [u64; 8]| Leaf {
            origin,
            active,
            values: Box::new([[0.0; 3]; LEAF_VOXELS]),
        };
        let mut one_off = [u64::MAX; 8];
        one_off[3] &= !(1 << 9);
        let leaves = vec![
            leaf([0, 0, 0], [u64::MAX; 8]),
            leaf([8, 0, 0], one_off),
            leaf([4, 0, 16], [u64::MAX; 8]),
        ];
        let f = GridFootprint::of_grid(&grid(vec![], leaves));
        assert_eq!((f.blocks, f.partial), (10, 9));
        // A tile of 12³ from (4, 4, 4) touches 2³ blocks and covers one whole (8..16 on
        // every axis); one of 16³ from (8, 8, 8) covers its 2³ whole.
        let tile = |origin: [i32; 3], size: u32| Tile {
            origin,
            size,
            value: [1.0, 0.0, 0.0],
        };
        let f = GridFootprint::of_grid(&grid(vec![tile([4; 3], 12), tile([8; 3], 16)], vec![]));
        assert_eq!((f.blocks, f.partial), (16, 7));
        // The masks of a grid with a finer one beside it may be cut anywhere: every block
        // counts a leaf pattern then.
        let whole = GridFootprint::of_grid(&grid(vec![tile([0; 3], 64)], vec![]));
        let no_spill = Spill {
            above: u64::MAX,
            ..Spill::default()
        };
        let fine = bake_bytes(&[(whole, VELOCITY_SLOT_BYTES)], &[], 2, &no_spill);
        let coarse = GridFootprint {
            coarse: true,
            ..whole
        };
        let coarse = bake_bytes(&[(coarse, VELOCITY_SLOT_BYTES)], &[], 2, &no_spill);
        assert_eq!(coarse - fine, whole.blocks * PATTERN_BYTES);
    }

    /// A billion cells (a 1024³ grid of single-precision velocity read from a file) fit a
    /// budget of 0.75 GiB only with the structure on disk too: its least with the structure
    /// in memory is over 3 GiB, with it on disk under 0.75 GiB (its blocks are all wholly
    /// active, about a brick each: with every block possibly partly active, more than three
    /// times that), and a budget between is kept with every value and the structure on
    /// disk.
    #[test]
    fn a_billion_cells_bake_within_a_budget_with_the_structure_on_disk() {
        let leaves = 1u64 << 21;
        let f = GridFootprint {
            batched: true,
            decoded: (LEAF_BATCH as u64) * leaf_bytes::<[f32; 3]>(),
            file_per_1024: 1024,
            partial: 0,
            coarse: false,
            ..GridFootprint::leaves::<[f32; 3]>(leaves, leaves * 512)
        }
        .with_bricks();
        assert_eq!(f.bricks, leaves);
        // Every block possibly partly active: masks of their own, and eight bricks each.
        let any = GridFootprint {
            partial: leaves,
            ..f
        }
        .with_bricks();
        assert_eq!(any.bricks, 8 * leaves);
        let least_any = spill_within(&[(any, SINGLE_VELOCITY_SLOT_BYTES)], &[], 2, 16 << 20)
            .expect_err("16 MiB is too little");
        let grids = [(f, SINGLE_VELOCITY_SLOT_BYTES)];
        let held = Spill {
            structure: u64::MAX,
            ..Spill::least()
        };
        assert!(bake_bytes(&grids, &[], 2, &held) > 3 << 30);
        let least = spill_within(&grids, &[], 2, 16 << 20).expect_err("16 MiB is too little");
        assert!(
            least < 3 << 28 && least_any > 3 * least,
            "{least} {least_any}"
        );
        let (spill, need) = spill_within(&grids, &[], 2, least).expect("the least does");
        assert!(need <= least);
        assert_eq!(spill.above, 0);
        assert_ne!(spill.structure, u64::MAX);
        // With room for the structure in memory, it stays there (faster, no scratch files).
        let (spill, _) = spill_within(&grids, &[], 2, 8 << 30).expect("8 GiB does");
        assert_eq!(spill.structure, u64::MAX);
        // Without a budget: the defaults where the machine holds them; on a machine of
        // 2 GiB, what that limit as a budget keeps on disk; past the address space left
        // for the scratch files, the defaults (which the limits then refuse).
        let (spill, _) = spill_without_budget(&grids, &[], 2, 24 << 30, None);
        assert_eq!(spill, Spill::default());
        let (spill, need) = spill_without_budget(&grids, &[], 2, 2 << 30, None);
        assert!(need <= 2 << 30 && spill.above == 0 && spill.structure != u64::MAX);
        let (spill, _) = spill_without_budget(&grids, &[], 2, 2 << 30, Some(3 << 30));
        assert_eq!(spill, Spill::default());
    }
}
