//! Bricking: dense boxes of leaf cells of one grid, at most `max` cells per axis.
//!
//! Deterministic greedy: leaf cells are visited in (z, y, x) order; each cell not yet in a
//! brick starts one that grows along x, then y (whole rows), then z (whole slabs) while
//! every cell is a free leaf cell and the cap is not reached.

use rayon::prelude::*;

use crate::cells::{CellSet, BLOCK_CELLS};
use crate::grid::leaf_offset;

/// A brick in the integer cell-index space of its grid: a concept of its own, not a
/// second float box. Bricks are cut from cells by index (exact, no rounding); world boxes
/// (a brick's support, the regions) are [`format::Aabb`], made from this with the grid's
/// cell width.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct BrickBox {
    /// Index of the cell set (grid) the brick belongs to.
    pub set: usize,
    pub level: u32,
    /// Lowest cell (index space).
    pub lo: [i32; 3],
    pub dims: [u32; 3],
}

impl BrickBox {
    pub(crate) fn cells(&self) -> u64 {
        self.dims.iter().map(|&d| d as u64).product()
    }

    /// Calls `visit` with the number (brick order, x fastest), coordinate and slot in `set`
    /// (None where `set` has no block) of every cell. Cells are visited z fastest, the
    /// order of a block's slots, so that reading their values (and their neighbours')
    /// walks memory forward; along z the slot steps by one instead of being looked up
    /// again.
    pub(crate) fn for_each_cell(
        &self,
        set: &CellSet,
        mut visit: impl FnMut(usize, [i32; 3], Option<usize>),
    ) {
        let [nx, ny, nz] = self.dims.map(|d| d as usize);
        for x in 0..nx {
            for y in 0..ny {
                let mut slot = None;
                for z in 0..nz {
                    let ijk = [
                        self.lo[0] + x as i32,
                        self.lo[1] + y as i32,
                        self.lo[2] + z as i32,
                    ];
                    // Same block as the previous cell unless z starts a new one.
                    slot = if z > 0 && ijk[2] & 7 != 0 {
                        slot.map(|s| s + 1)
                    } else {
                        set.slot(ijk)
                    };
                    visit(x + nx * (y + ny * z), ijk, slot);
                }
            }
        }
    }
}

/// Bricks of all sets: ordered by level, then set index, then greedy order.
pub(crate) fn make_bricks(sets: &[CellSet], max: u32) -> Vec<BrickBox> {
    let per_set: Vec<Vec<BrickBox>> = sets
        .par_iter()
        .enumerate()
        .map(|(s, set)| bricks_of(s, set, max.max(1)))
        .collect();
    let mut order: Vec<usize> = (0..sets.len()).collect();
    order.sort_by_key(|&s| (sets[s].level, s));
    order
        .into_iter()
        .flat_map(|s| per_set[s].iter().copied())
        .collect()
}

fn bricks_of(s: usize, set: &CellSet, max: u32) -> Vec<BrickBox> {
    let mut free = set.leaf.clone();
    let is_free = |free: &Vec<[u64; 8]>, ijk: [i32; 3]| -> bool {
        set.slot(ijk).is_some_and(|sl| {
            let (b, n) = (sl / BLOCK_CELLS, sl % BLOCK_CELLS);
            (free[b][n >> 6] >> (n & 63)) & 1 == 1
        })
    };
    let max = max as i64;
    let inside = |c: i32, d: i64| (c as i64 + d) <= i32::MAX as i64;
    let mut out = Vec::new();
    for_each_leaf_zyx(set, |c, slot| {
        let (b, n) = (slot / BLOCK_CELLS, slot % BLOCK_CELLS);
        if (free[b][n >> 6] >> (n & 63)) & 1 == 0 {
            return;
        }
        // Grow along x.
        let mut nx = 1i64;
        while nx < max && inside(c[0], nx) && is_free(&free, [c[0] + nx as i32, c[1], c[2]]) {
            nx += 1;
        }
        let row_free = |free: &Vec<[u64; 8]>, y: i32, z: i32| {
            (0..nx).all(|x| is_free(free, [c[0] + x as i32, y, z]))
        };
        // Grow along y by whole rows.
        let mut ny = 1i64;
        while ny < max && inside(c[1], ny) && row_free(&free, c[1] + ny as i32, c[2]) {
            ny += 1;
        }
        // Grow along z by whole slabs.
        let mut nz = 1i64;
        while nz < max
            && inside(c[2], nz)
            && (0..ny).all(|y| row_free(&free, c[1] + y as i32, c[2] + nz as i32))
        {
            nz += 1;
        }
        let b = BrickBox {
            set: s,
            level: set.level,
            lo: c,
            dims: [nx as u32, ny as u32, nz as u32],
        };
        b.for_each_cell(set, |_, _, slot| {
            if let Some(sl) = slot {
                let (bb, n) = (sl / BLOCK_CELLS, sl % BLOCK_CELLS);
                free[bb][n >> 6] &= !(1u64 << (n & 63));
            }
        });
        out.push(b);
    });
    out
}

/// Calls `visit` with the coordinate and slot of every leaf cell of `set` in (z, y, x)
/// order. Blocks are sorted by origin (z, y, x), so walking each slab of blocks (same z
/// origin) plane by plane, and each run of blocks in the slab with the same y origin row
/// by row, yields that order without sorting the cells (millions on a dense level).
fn for_each_leaf_zyx(set: &CellSet, mut visit: impl FnMut([i32; 3], usize)) {
    let blocks = &set.blocks;
    let mut slab = 0;
    while slab < blocks.len() {
        let oz = blocks[slab][2];
        let slab_end = slab + blocks[slab..].partition_point(|o| o[2] == oz);
        for z in 0..8 {
            let mut run = slab;
            while run < slab_end {
                let oy = blocks[run][1];
                let run_end = run + blocks[run..slab_end].partition_point(|o| o[1] == oy);
                for y in 0..8 {
                    for (b, o) in blocks.iter().enumerate().take(run_end).skip(run) {
                        let leaf = &set.leaf[b];
                        for x in 0..8 {
                            let n = leaf_offset(x, y, z);
                            if (leaf[n >> 6] >> (n & 63)) & 1 == 1 {
                                let c = [o[0] + x as i32, oy + y as i32, oz + z as i32];
                                visit(c, b * BLOCK_CELLS + n);
                            }
                        }
                    }
                }
                run = run_end;
            }
        }
        slab = slab_end;
    }
}
