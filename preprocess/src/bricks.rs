//! Bricking: dense boxes of leaf cells of one grid, at most `max` cells per axis.
//!
//! Deterministic greedy: leaf cells are visited in (z, y, x) order; each cell not yet in a
//! brick starts one that grows along x, then y (whole rows), then z (whole slabs) while
//! every cell is a free leaf cell and the cap is not reached.

use rayon::prelude::*;

use crate::cells::{CellSet, BLOCK_CELLS};

/// A brick in the integer cell-index space of its grid: a concept of its own, not a
/// second float box. Bricks are cut from cells by index (exact, no rounding); world boxes
/// (a brick's support, the regions) are [`format::Aabb`], made from this with the grid's
/// cell width.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BrickBox {
    /// Index of the cell set (grid) the brick belongs to.
    pub set: usize,
    pub level: u32,
    /// Lowest cell (index space).
    pub lo: [i32; 3],
    pub dims: [u32; 3],
}

impl BrickBox {
    pub fn cells(&self) -> u64 {
        self.dims.iter().map(|&d| d as u64).product()
    }

    /// Cell coordinates in brick order (x fastest).
    pub(crate) fn cell_coords(&self) -> impl Iterator<Item = [i32; 3]> + '_ {
        let d = self.dims;
        (0..d[2]).flat_map(move |z| {
            (0..d[1]).flat_map(move |y| {
                (0..d[0]).map(move |x| {
                    [
                        self.lo[0] + x as i32,
                        self.lo[1] + y as i32,
                        self.lo[2] + z as i32,
                    ]
                })
            })
        })
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
    let mut cells: Vec<[i32; 3]> = (0..set.blocks.len())
        .flat_map(|b| {
            (0..BLOCK_CELLS)
                .filter(move |&n| (set.leaf[b][n >> 6] >> (n & 63)) & 1 == 1)
                .map(move |n| set.ijk(b * BLOCK_CELLS + n))
        })
        .collect();
    // Millions of cells on a dense level: sorting them is a visible share of the bake, and
    // the order is total (no equal keys), so the parallel sort gives the same order.
    cells.par_sort_unstable_by_key(|c| (c[2], c[1], c[0]));
    let max = max as i64;
    let inside = |c: i32, d: i64| (c as i64 + d) <= i32::MAX as i64;
    let mut out = Vec::new();
    for c in cells {
        if !is_free(&free, c) {
            continue;
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
        for q in b.cell_coords() {
            if let Some(sl) = set.slot(q) {
                let (bb, n) = (sl / BLOCK_CELLS, sl % BLOCK_CELLS);
                free[bb][n >> 6] &= !(1u64 << (n & 63));
            }
        }
        out.push(b);
    }
    out
}
