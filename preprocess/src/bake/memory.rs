//! How much memory a bake needs, estimated from the decoded grids before any cell is made,
//! so that a bake the machine cannot hold is refused with its size through the one shared
//! limit ([`files::limits::check_memory`]) instead of dying in an allocation failure half
//! way through. A file of a few kilobytes can hold a single active tile of 640³ voxels:
//! nothing about the file's size says what the bake will take, only its cells do.
//!
//! The estimate follows what the pipeline allocates:
//! - the decoded grids' leaves ([`GridFootprint::decoded`]): they and the cells made from
//!   them are both held while a grid is converted, the bake's peak since what the bake
//!   drops afterwards is given back to the system ([`return_freed`]);
//! - per slot of every 8³ block a cell set takes ([`GridFootprint::blocks`], 512 slots
//!   each, inactive slots included): the cells' values, 24 bytes for a velocity, 72 for a
//!   staggered one (faces kept beside the centred values), 8 for a scalar; plus the masks;
//! - per active cell: 4 bytes for every baked field and [`CELL_BYTES`] for bricks,
//!   supports, regions, their ranges and what the allocator rounds up.
//!
//! Measured peaks (`/usr/bin/time -v`, maximum resident set, 2 threads) against it: one
//! 384³ tile 38.8 bytes per cell (estimate 40); a 256³ Lamb–Oseen grid of leaves 43.3
//! (none) and 47.3 (zip) bytes per cell (estimate 52.4), 55.7 with five fields
//! (estimate 64.4). The figures are in docs/baking.md.

/// Gives the pages of freed allocations back to the system; called where a bake has just
/// dropped much (the decoded grids, the input values, the cells before the file is
/// written), not between every stage: each call consolidates the allocator's free lists,
/// about 3 % of a small bake's time when it ran before all nine stages. The decoded grids
/// are millions of 6 kB leaves: once converted to cells they are
/// freed, but glibc's allocator keeps freed small blocks in its heaps, so without this the
/// bake's resident memory kept them to the end (a 56.6 M-cell bake peaked at 2.60 GB
/// instead of 2.14 GB, the leaves' 12 bytes a cell held through the later stages). Only the
/// release is asked for: nothing the bake computes depends on it.
#[allow(unsafe_code)]
pub fn return_freed() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `malloc_trim` takes no pointers; it releases only memory the allocator holds
    // free, and is safe to call from any thread at any time.
    unsafe {
        libc::malloc_trim(0);
    }
}

use crate::cells::BLOCK_CELLS;
use crate::error::BakeError;
use crate::grid::{AnyGrid, Grid, Leaf, LEAF_DIM, LEAF_VOXELS};

use super::BakeOptions;

/// Bytes per active cell besides the values and fields (bricks, supports, regions and
/// their value ranges, the KD-tree, allocator rounding): the measured residual (about 7
/// bytes on a 384³ tile) with some headroom.
pub const CELL_BYTES: u64 = 8;
/// Bytes of one baked field per cell (an `f32`).
pub const FIELD_BYTES: u64 = 4;
/// Bytes per block besides its values: active and leaf masks, origin, index entry.
const BLOCK_BYTES: u64 = 2 * 64 + 12 + 16;

/// Bytes per cell-set slot of a cell-centred velocity (`[f64; 3]`).
pub const VELOCITY_SLOT_BYTES: u64 = 24;
/// A staggered velocity keeps its face values beside the centred ones, and makes the
/// centred ones from them while both exist.
pub const STAGGERED_SLOT_BYTES: u64 = 3 * VELOCITY_SLOT_BYTES;
/// Bytes per slot of a scalar grid (`f64`), baked on its own or as an extra field.
pub const SCALAR_SLOT_BYTES: u64 = 8;

/// What one grid brings into a bake.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GridFootprint {
    /// Bytes of its decoded leaves (tiles take next to nothing).
    pub decoded: u64,
    /// 8³ blocks its cell set will take: at most this many (a block a leaf and a tile
    /// share is counted twice).
    pub blocks: u64,
    /// Active voxels, tiles counted as the voxels they cover.
    pub cells: u64,
}

impl GridFootprint {
    pub fn of(grid: &AnyGrid) -> GridFootprint {
        match grid {
            AnyGrid::Float(g) => Self::of_grid(g),
            AnyGrid::Double(g) => Self::of_grid(g),
            AnyGrid::Vec3s(g) => Self::of_grid(g),
            AnyGrid::Vec3d(g) => Self::of_grid(g),
        }
    }

    pub fn of_grid<V: Copy>(g: &Grid<V>) -> GridFootprint {
        let mut blocks = 0u64;
        for t in &g.tiles {
            let per_axis = |a: usize| {
                let lo = i64::from(t.origin[a]);
                let hi = (lo + i64::from(t.size)).min(i64::from(i32::MAX) + 1);
                if hi <= lo {
                    0
                } else {
                    ((hi - 1).div_euclid(8) - lo.div_euclid(8) + 1) as u64
                }
            };
            blocks = blocks.saturating_add(
                per_axis(0)
                    .saturating_mul(per_axis(1))
                    .saturating_mul(per_axis(2)),
            );
        }
        for l in &g.leaves {
            // A leaf off the block lattice straddles up to 8 blocks.
            let aligned = l.origin.iter().all(|c| c % LEAF_DIM == 0);
            blocks = blocks.saturating_add(if aligned { 1 } else { 8 });
        }
        GridFootprint {
            decoded: (g.leaves.len() as u64).saturating_mul(leaf_bytes::<V>()),
            blocks,
            cells: g.active_voxel_count(),
        }
    }

    /// The footprint of `n` full leaves of `V` (no tiles), as `synth` samples a box.
    pub fn leaves<V>(n: u64, cells: u64) -> GridFootprint {
        GridFootprint {
            decoded: n.saturating_mul(leaf_bytes::<V>()),
            blocks: n,
            cells,
        }
    }
}

/// Bytes one decoded leaf of `V` takes: the entry in the grid's leaf list and its boxed
/// values.
pub fn leaf_bytes<V>() -> u64 {
    (std::mem::size_of::<Leaf<V>>() + std::mem::size_of::<[V; LEAF_VOXELS]>()) as u64
}

/// The estimated peak of a bake: `grids` with `slot_bytes` per slot of their cell sets
/// (see the module docs), baked into `fields` fields, with the scalar grids `extras`
/// resampled as extra fields.
pub fn bake_bytes(grids: &[(GridFootprint, u64)], extras: &[GridFootprint], fields: u64) -> u64 {
    let slots = |f: &GridFootprint| f.blocks.saturating_mul(BLOCK_CELLS as u64);
    let mut total = 0u64;
    for (f, slot_bytes) in grids {
        total = total
            .saturating_add(f.decoded)
            .saturating_add(slots(f).saturating_mul(*slot_bytes))
            .saturating_add(f.blocks.saturating_mul(BLOCK_BYTES))
            .saturating_add(
                f.cells.saturating_mul(
                    fields
                        .saturating_mul(FIELD_BYTES)
                        .saturating_add(CELL_BYTES),
                ),
            );
    }
    for f in extras {
        total = total
            .saturating_add(f.decoded)
            .saturating_add(slots(f).saturating_mul(SCALAR_SLOT_BYTES))
            .saturating_add(f.blocks.saturating_mul(BLOCK_BYTES));
    }
    total
}

/// Refuses, before any cell is made, a bake of `grids` (and of the scalar grids `extras`
/// as extra fields) whose estimated peak ([`bake_bytes`]) is over the shared memory limit.
pub(super) fn check_bake_memory(
    grids: &[AnyGrid],
    extras: &[AnyGrid],
    opts: &BakeOptions,
    input_cells: u64,
) -> Result<(), BakeError> {
    let vector = grids.first().is_some_and(AnyGrid::is_vector);
    let fields = if vector {
        opts.fields.as_ref().map_or(2, |kinds| {
            kinds.iter().map(|k| k.names().len() as u64).sum::<u64>()
        })
    } else {
        1
    };
    let per_grid: Vec<(GridFootprint, u64)> = grids
        .iter()
        .map(|g| {
            let slot = if !g.is_vector() {
                SCALAR_SLOT_BYTES
            } else if opts.staggered.iter().any(|s| s == g.name()) {
                STAGGERED_SLOT_BYTES
            } else {
                VELOCITY_SLOT_BYTES
            };
            (GridFootprint::of(g), slot)
        })
        .collect();
    let extras: Vec<GridFootprint> = extras.iter().map(GridFootprint::of).collect();
    let need = bake_bytes(&per_grid, &extras, fields);
    let mut names: Vec<&str> = grids.iter().map(AnyGrid::name).collect();
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
    files::limits::check_memory(
        format!("the bake of {input_cells} input cells ({grid_s} {names})"),
        need,
    )?;
    Ok(())
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
        assert_eq!(f.decoded, 0);
        // 640³ cells, two fields: about 40 bytes per cell, 10 GB.
        let need = bake_bytes(&[(f, VELOCITY_SLOT_BYTES)], &[], 2);
        assert!(need > 40 * f.cells && need < 41 * f.cells, "{need}");

        let leaf = Leaf {
            origin: [8, 0, -8],
            active: [1, 0, 0, 0, 0, 0, 0, 0],
            values: Box::new([[0.0; 3]; LEAF_VOXELS]),
        };
        let f = GridFootprint::of_grid(&grid(vec![], vec![leaf]));
        // One active voxel still takes a whole block of slots.
        assert_eq!((f.blocks, f.cells), (1, 1));
        assert!(bake_bytes(&[(f, VELOCITY_SLOT_BYTES)], &[], 2) > 512 * 24);
    }
}
