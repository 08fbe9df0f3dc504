//! Bricking: dense boxes of leaf cells of one grid, at most `max` cells per axis.
//!
//! Deterministic greedy: leaf cells are visited in (z, y, x) order; each cell not yet in a
//! brick starts one that grows along x, then y (whole rows), then z (whole slabs) while
//! every cell is a free leaf cell and the brick stays inside its *tile*: the box of `max`
//! cells a side that holds its first cell, tiles being laid from the grid's lowest active
//! cell on each axis (the corner of a box-shaped grid) in steps of `max`.
//!
//! Tiles keep the bricks of one grid on one grid of faces. Without them a brick that starts
//! right after a hole (an obstacle's inactive cells, a finer box's covered cells) is shifted
//! by the hole, and so is every brick after it along the row: their supports' faces then
//! miss each other by a cell or two, and each near miss is a region boundary. On issue 33's
//! independent file (a solid sphere inside three nested boxes) tiles took the bricks from
//! 15 637 to 9 732 and the regions from 267 665 to 201 536; on `synth wake --n0 128` the
//! regions from 122 166 to 116 219 (bricks 10 458 → 10 498); on the bundled sample (n0 48,
//! whose boxes are not on multiples of 8 cells) the bricks from 884 to 860 and the regions
//! from 12 856 to 11 786.

use rayon::prelude::*;

use crate::cells::{BlockMasks, CellSet, BLOCK_CELLS};
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
    let is_free = |free: &BlockMasks, ijk: [i32; 3]| -> bool {
        set.slot(ijk)
            .is_some_and(|sl| free.bit(sl / BLOCK_CELLS, sl % BLOCK_CELLS))
    };
    let max = max as i64;
    let inside = |c: i32, d: i64| (c as i64 + d) <= i32::MAX as i64;
    let anchor = tile_anchor(set);
    let mut out = Vec::new();
    for_each_leaf_zyx(set, |c, slot| {
        if !free.bit(slot / BLOCK_CELLS, slot % BLOCK_CELLS) {
            return;
        }
        // Cells left in the tile of `c` along each axis.
        let room: [i64; 3] =
            std::array::from_fn(|a| max - (i64::from(c[a]) - anchor[a]).rem_euclid(max));
        // Grow along x.
        let mut nx = 1i64;
        while nx < room[0] && inside(c[0], nx) && is_free(&free, [c[0] + nx as i32, c[1], c[2]]) {
            nx += 1;
        }
        let row_free = |free: &BlockMasks, y: i32, z: i32| {
            (0..nx).all(|x| is_free(free, [c[0] + x as i32, y, z]))
        };
        // Grow along y by whole rows.
        let mut ny = 1i64;
        while ny < room[1] && inside(c[1], ny) && row_free(&free, c[1] + ny as i32, c[2]) {
            ny += 1;
        }
        // Grow along z by whole slabs.
        let mut nz = 1i64;
        while nz < room[2]
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
                free.remove(sl / BLOCK_CELLS, sl % BLOCK_CELLS);
            }
        });
        out.push(b);
    });
    out
}

/// Where the tiles of `set` start: the lowest index of its active cells on each axis (the
/// corner of a box-shaped grid), so that a grid whose box is not on multiples of the tile
/// size is tiled from its own corner, as greedy bricking from that corner would cut it.
fn tile_anchor(set: &CellSet) -> [i64; 3] {
    let mut lo = [i64::MAX; 3];
    for (o, m) in set.blocks.iter().zip(set.active.iter()) {
        if *m == [0; 8] {
            continue;
        }
        for n in 0..BLOCK_CELLS {
            if (m[n >> 6] >> (n & 63)) & 1 == 1 {
                let c = [
                    o[0] + (n >> 6) as i32,
                    o[1] + ((n >> 3) & 7) as i32,
                    o[2] + (n & 7) as i32,
                ];
                for a in 0..3 {
                    lo[a] = lo[a].min(i64::from(c[a]));
                }
            }
        }
    }
    lo.map(|v| if v == i64::MAX { 0 } else { v })
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
                        let leaf = set.leaf.get(b);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Grid, Leaf, Transform, LEAF_VOXELS};

    /// A grid of the cells `[0, n)³` (plus `shift` on every axis) for which `keep` holds.
    fn set_of(n: i32, shift: i32, keep: impl Fn([i32; 3]) -> bool) -> CellSet {
        let mut leaves = Vec::new();
        let first = shift.div_euclid(8) * 8;
        for ox in (first..shift + n).step_by(8) {
            for oy in (first..shift + n).step_by(8) {
                for oz in (first..shift + n).step_by(8) {
                    let mut active = [0u64; 8];
                    for i in 0..LEAF_VOXELS {
                        let c = [
                            ox + (i >> 6) as i32,
                            oy + ((i >> 3) & 7) as i32,
                            oz + (i & 7) as i32,
                        ];
                        let inside = c.iter().all(|&v| v >= shift && v < shift + n);
                        if inside && keep(c) {
                            active[i >> 6] |= 1 << (i & 63);
                        }
                    }
                    leaves.push(Leaf {
                        origin: [ox, oy, oz],
                        active,
                        values: Box::new([0.0f32; LEAF_VOXELS]),
                    });
                }
            }
        }
        let grid = Grid {
            name: "g".into(),
            transform: Transform {
                voxel_size: [1.0; 3],
                translation: [0.5; 3],
            },
            background: 0.0,
            leaves,
            tiles: vec![],
        };
        CellSet::from_grid(grid, 0, f64::from).expect("small").0
    }

    /// Every leaf cell in exactly one brick, every brick dense with leaf cells and inside
    /// one tile of `max` cells.
    fn check(set: &CellSet, bricks: &[BrickBox], max: u32) {
        let mut seen = std::collections::HashSet::new();
        let anchor = tile_anchor(set);
        let max = i64::from(max);
        for b in bricks {
            for (a, anchor) in anchor.iter().enumerate() {
                let first = i64::from(b.lo[a]) - anchor;
                let last = first + i64::from(b.dims[a]) - 1;
                assert_eq!(
                    first.div_euclid(max),
                    last.div_euclid(max),
                    "{b:?} crosses a tile"
                );
            }
            b.for_each_cell(set, |_, ijk, slot| {
                assert!(slot.is_some_and(|s| set.is_leaf(s)), "{ijk:?} of {b:?}");
                assert!(seen.insert(ijk), "{ijk:?} in two bricks");
            });
        }
        assert_eq!(seen.len() as u64, set.leaf_count());
    }

    /// A hole at the start of some rows does not shift the bricks after it: they stay on
    /// the tiles (without tiles, a row starting at x = 3 made bricks 3..11, 11..19, …).
    #[test]
    fn bricks_stay_in_their_tiles() {
        let set = set_of(24, 0, |c| !(c[0] < 3 && c[1] < 5));
        let bricks = make_bricks(std::slice::from_ref(&set), 8);
        check(&set, &bricks, 8);
        assert!(bricks.iter().all(|b| b.lo[0] % 8 == 0 || b.lo[0] == 3));
        // Full tiles stay whole: 27 tiles, the three holed ones in two bricks each.
        assert_eq!(bricks.len(), 27 + 3);
        // Tiles start at the grid's corner: a box from -5 is cut as greedy cuts it.
        let set = set_of(24, -5, |_| true);
        assert_eq!(tile_anchor(&set), [-5; 3]);
        let bricks = make_bricks(std::slice::from_ref(&set), 8);
        check(&set, &bricks, 8);
        assert_eq!(bricks.len(), 27);
        // A ball-shaped hole, off the tile grid, and other caps.
        let ball = |c: [i32; 3]| c.iter().map(|&v| (v as f64 - 9.3).powi(2)).sum::<f64>() > 30.0;
        for (shift, max) in [(0, 8), (-5, 8), (3, 5), (-13, 3), (0, 1), (2, 16)] {
            let set = set_of(21, shift, ball);
            let bricks = make_bricks(std::slice::from_ref(&set), max);
            check(&set, &bricks, max);
        }
    }
}
