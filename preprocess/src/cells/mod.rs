//! Cells of the input grids on their index lattices, and leaf-cell classification.
//!
//! A [`CellSet`] holds one grid's active cells as 8³ blocks (the VDB leaf layout) with an
//! active mask and a leaf mask ([`masks`]: a whole block shares one pattern), so that
//! neighbour lookups are one block-index probe ([`index`]) and a bit test.
//! Values live beside it in a plain `Vec` indexed by the same slot (`block * 512 + offset`).
//!
//! A cell is a *leaf cell* when its box is not fully covered by active cells of finer grids
//! (smaller voxel size); [`classify_leaves`] finds them.

use bytemuck::Pod;

use crate::error::BakeError;
use crate::grid::{leaf_offset, Grid, Leaf, LeafTopology, Transform, LEAF_VOXELS};

mod classify;
mod index;
mod masks;
mod values;

pub(crate) use classify::classify_leaves;
use index::BlockIndex;
pub(crate) use masks::BlockMasks;
pub(crate) use values::{window_values, Keep, SlotValues, SlotView, Slots, Widen};

/// Cells per block (one VDB leaf).
pub(crate) const BLOCK_CELLS: usize = LEAF_VOXELS;

/// Index coordinate of the block holding `ijk`.
#[inline]
fn block_origin(ijk: [i32; 3]) -> [i32; 3] {
    [ijk[0] & !7, ijk[1] & !7, ijk[2] & !7]
}

/// Whether `o` is a block origin (all coordinates multiples of 8).
fn is_block_origin(o: [i32; 3]) -> bool {
    o.iter().all(|c| c & 7 == 0)
}

#[inline]
fn offset_in_block(ijk: [i32; 3]) -> usize {
    leaf_offset(
        (ijk[0] & 7) as usize,
        (ijk[1] & 7) as usize,
        (ijk[2] & 7) as usize,
    )
}

#[inline]
fn bit(mask: &[u64; 8], n: usize) -> bool {
    (mask[n >> 6] >> (n & 63)) & 1 == 1
}

/// Decoded leaf values [`CellSet::from_leaves`] frees before it hands them back to the
/// system (a few hundred `malloc_trim` calls for a billion cells), and lets the pages of
/// values kept on disk go.
const RELEASE_BYTES: usize = 256 << 20;

/// Leaves decoded at once: 24 MiB of single-precision velocity.
pub(crate) const LEAF_BATCH: usize = 4096;

/// Index coordinates of the active voxels of a leaf at `origin` with mask `active`.
fn active_cells(origin: [i32; 3], active: &[u64; 8]) -> impl Iterator<Item = [i32; 3]> + '_ {
    (0..LEAF_VOXELS)
        .filter(move |&n| bit(active, n))
        .map(move |n| {
            [
                origin[0] + (n >> 6) as i32,
                origin[1] + ((n >> 3) & 7) as i32,
                origin[2] + (n & 7) as i32,
            ]
        })
}

/// One input grid's cells on its lattice.
#[derive(Debug, Clone)]
pub(crate) struct CellSet {
    /// Grid name (for messages).
    pub name: String,
    pub transform: Transform,
    /// Cell edge length (the grid's voxel size; cells are cubes).
    pub width: f64,
    /// Level of this grid (0 = finest).
    pub level: u32,
    /// Block origins (multiples of 8 in index space), sorted.
    pub blocks: Vec<[i32; 3]>,
    index: BlockIndex,
    /// Active mask per block (bit `n` = offset `n`, see [`leaf_offset`]).
    pub active: BlockMasks,
    /// Leaf mask per block (active and not covered by finer cells); equals `active` until
    /// [`classify_leaves`] runs.
    pub leaf: BlockMasks,
}

impl CellSet {
    /// Builds the cell set of `grid` and its values converted by `conv`, one per slot,
    /// kept as `keep` says (in memory, or in a scratch file when large). The leaves'
    /// values come from `decode`, a batch of leaves at a time (at most [`LEAF_BATCH`], and
    /// no more than `keep.window` bytes of them decoded): decoded
    /// grids hand theirs over as they are, grids located in a file decode them then. Tiles
    /// are expanded to cells; the caller bounds the total beforehand (see
    /// [`crate::bake::memory`]), and the allocations that grow with it (the blocks' values
    /// and masks) are fallible, so an estimate that falls short is an error, not an abort.
    ///
    /// The decoded leaves are freed batch by batch once copied (and handed back to the
    /// system every [`RELEASE_BYTES`]), while the values' pages become resident only as they
    /// are written; values kept on disk let their pages go every `keep.window` bytes. So
    /// the grid and its cells are never both held whole: the conversion's peak is the
    /// larger of the two, not their sum, and with a located grid on disk, a batch of each.
    pub(crate) fn from_leaves<V: Copy, L: LeafTopology, T: Pod>(
        grid: Grid<V, L>,
        level: u32,
        conv: impl Fn(V) -> T,
        keep: Keep<'_>,
        mut decode: impl FnMut(Vec<L>) -> Result<Vec<Leaf<V>>, BakeError>,
    ) -> Result<(CellSet, Slots<T>), BakeError> {
        let tile_ranges: Vec<([i64; 3], [i64; 3])> = grid
            .tiles
            .iter()
            .map(|t| {
                let lo = t.origin.map(|c| c as i64);
                let hi = lo.map(|c| (c + t.size as i64).min(i32::MAX as i64 + 1));
                (lo, hi)
            })
            .collect();
        // The blocks first (every block a tile or an active leaf voxel falls in), sorted by
        // origin so that nothing depends on the order of leaves in the file; then the values
        // go straight to their place.
        let mut blocks: Vec<[i32; 3]> = Vec::with_capacity(grid.leaves.len());
        for (lo, hi) in &tile_ranges {
            if (0..3).any(|a| lo[a] >= hi[a]) {
                continue;
            }
            let first = lo.map(|c| c & !7);
            for z in (first[2]..hi[2]).step_by(8) {
                for y in (first[1]..hi[1]).step_by(8) {
                    for x in (first[0]..hi[0]).step_by(8) {
                        blocks.push([x as i32, y as i32, z as i32]);
                    }
                }
            }
        }
        for leaf in &grid.leaves {
            let origin = leaf.origin();
            if is_block_origin(origin) {
                if *leaf.active() != [0; 8] {
                    blocks.push(origin);
                }
            } else {
                blocks.extend(active_cells(origin, leaf.active()).map(block_origin));
            }
        }
        blocks.sort_unstable_by_key(|o| (o[2], o[1], o[0]));
        blocks.dedup();
        let index = BlockIndex::new(&blocks);
        let what = format!("the cells of grid \"{}\"", grid.name);
        let mut active = BlockMasks::new(&what, blocks.len())?;
        let mut slots: Slots<T> = Slots::zeroed(&what, blocks.len() * BLOCK_CELLS, keep)?;
        // The leaves come in the file's order and go to their blocks' places, all over the
        // values: within a budget, no readahead while they are written (passes after read
        // in order).
        slots.read_ahead(!keep.bounded);
        let put = |active: &mut BlockMasks, values: &mut [T], ijk: [i32; 3], v: T| {
            if let Some(b) = index.get(block_origin(ijk)) {
                let n = offset_in_block(ijk);
                active.insert(b as usize, n);
                values[b as usize * BLOCK_CELLS + n] = v;
            }
        };
        // Tiles first, so that leaf voxels win where a (malformed) file has both. A tile can
        // be gigabytes of values: those kept on disk let their pages go as they go.
        let window = keep.window_values(std::mem::size_of::<T>());
        let mut written = 0usize;
        for (t, (lo, hi)) in grid.tiles.iter().zip(&tile_ranges) {
            let v = conv(t.value);
            for z in lo[2]..hi[2] {
                let values = slots.as_mut_slice();
                for y in lo[1]..hi[1] {
                    for x in lo[0]..hi[0] {
                        put(&mut active, values, [x as i32, y as i32, z as i32], v);
                    }
                }
                written += ((hi[1] - lo[1]) * (hi[0] - lo[0])) as usize;
                if written >= window {
                    slots.release(0..usize::MAX);
                    written = 0;
                }
            }
        }
        let leaf_bytes = std::mem::size_of::<[V; LEAF_VOXELS]>();
        // A batch of decoded leaves is held beside the values: within the window too.
        let batch_leaves = keep.window_values(leaf_bytes).min(LEAF_BATCH);
        let mut freed = 0usize;
        let mut leaves = grid.leaves.into_iter();
        loop {
            let batch: Vec<L> = leaves.by_ref().take(batch_leaves).collect();
            if batch.is_empty() {
                break;
            }
            let decoded = decode(batch)?;
            freed += decoded.len() * leaf_bytes;
            written += decoded.len() * LEAF_VOXELS;
            let values = slots.as_mut_slice();
            for leaf in decoded {
                if !is_block_origin(leaf.origin) {
                    for (ijk, v) in leaf.active_voxels() {
                        put(&mut active, values, ijk, conv(v));
                    }
                    continue;
                }
                // A leaf on the block lattice is one block with the same voxel layout.
                let Some(b) = index.get(leaf.origin) else {
                    continue;
                };
                let b = b as usize;
                let out = &mut values[b * BLOCK_CELLS..(b + 1) * BLOCK_CELLS];
                let mut mask = *active.get(b);
                for (w, &word) in leaf.active.iter().enumerate() {
                    let mut bits = word;
                    while bits != 0 {
                        let n = w * 64 + bits.trailing_zeros() as usize;
                        bits &= bits - 1;
                        out[n] = conv(leaf.values[n]);
                    }
                    mask[w] |= word;
                }
                active.set(b, mask);
            }
            if freed >= RELEASE_BYTES {
                crate::heap::return_freed();
                freed = 0;
            }
            if written >= window {
                slots.release(0..usize::MAX);
                written = 0;
            }
        }
        let set = CellSet {
            name: grid.name.clone(),
            transform: grid.transform,
            width: grid.transform.voxel_size[0],
            level,
            blocks,
            index,
            leaf: active.clone(),
            active,
        };
        slots.release(0..usize::MAX);
        slots.read_ahead(true);
        Ok((set, slots))
    }

    /// As [`CellSet::from_leaves`] for a decoded grid, its values in memory.
    #[cfg(test)]
    pub(crate) fn from_grid<V: Copy, T: Pod>(
        grid: Grid<V>,
        level: u32,
        conv: impl Fn(V) -> T,
    ) -> Result<(CellSet, Vec<T>), BakeError> {
        match Self::from_leaves(grid, level, conv, Keep::MEMORY, Ok)? {
            (set, Slots::Memory(values)) => Ok((set, values)),
            (_, Slots::Mapped(_)) => unreachable!("kept in memory"),
        }
    }

    /// Slot of `ijk` when its block exists (the cell may be inactive).
    #[inline]
    pub(crate) fn slot(&self, ijk: [i32; 3]) -> Option<usize> {
        let b = self.index.get(block_origin(ijk))? as usize;
        Some(b * BLOCK_CELLS + offset_in_block(ijk))
    }

    /// Active slot of the neighbour `d` cells (|d| <= 8) along `axis` of cell `ijk`
    /// (held in `slot`): in-block arithmetic when the neighbour shares the block.
    // Always inlined: the gradient calls it six times per cell, and as a call it cost
    // about as much as the rest of an interior cell's central differences.
    #[inline(always)]
    pub(crate) fn active_neighbour(
        &self,
        slot: usize,
        ijk: [i32; 3],
        axis: usize,
        d: i32,
    ) -> Option<usize> {
        let local = (ijk[axis] & 7) + d;
        if (0..8).contains(&local) {
            let stride = [64i64, 8, 1][axis];
            let s = (slot as i64 + stride * d as i64) as usize;
            return self.is_active(s).then_some(s);
        }
        let mut q = ijk;
        q[axis] = q[axis].checked_add(d)?;
        self.active_slot(q)
    }

    /// Slot of `ijk` when that cell is active.
    #[inline]
    pub(crate) fn active_slot(&self, ijk: [i32; 3]) -> Option<usize> {
        self.slot(ijk).filter(|&s| self.is_active(s))
    }

    /// Slot of `ijk` when that cell is a leaf cell.
    #[inline]
    pub(crate) fn leaf_slot(&self, ijk: [i32; 3]) -> Option<usize> {
        self.slot(ijk).filter(|&s| self.is_leaf(s))
    }

    #[inline]
    pub(crate) fn is_active(&self, slot: usize) -> bool {
        self.active.bit(slot / BLOCK_CELLS, slot % BLOCK_CELLS)
    }

    #[inline]
    pub(crate) fn is_leaf(&self, slot: usize) -> bool {
        self.leaf.bit(slot / BLOCK_CELLS, slot % BLOCK_CELLS)
    }

    /// Index coordinate of a slot.
    pub(crate) fn ijk(&self, slot: usize) -> [i32; 3] {
        let o = self.blocks[slot / BLOCK_CELLS];
        let n = slot % BLOCK_CELLS;
        [
            o[0] + (n >> 6) as i32,
            o[1] + ((n >> 3) & 7) as i32,
            o[2] + (n & 7) as i32,
        ]
    }

    /// World-space centre of cell `ijk`.
    pub(crate) fn centre(&self, ijk: [i32; 3]) -> [f64; 3] {
        self.transform.index_to_world(ijk.map(|c| c as f64))
    }

    /// Whether every cell of the index box `lo..=hi` is active; None when the box spans
    /// more than `max_blocks` blocks.
    pub(crate) fn all_active_in(
        &self,
        lo: [i32; 3],
        hi: [i32; 3],
        max_blocks: i64,
    ) -> Option<bool> {
        self.visit_box(lo, hi, max_blocks, |mask, part| {
            mask.is_some_and(|m| m.iter().zip(part).all(|(m, p)| m & p == *p))
        })
    }

    /// Whether some cell of the index box `lo..=hi` is active; None when the box spans
    /// more than `max_blocks` blocks.
    pub(crate) fn any_active_in(
        &self,
        lo: [i32; 3],
        hi: [i32; 3],
        max_blocks: i64,
    ) -> Option<bool> {
        let none = self.visit_box(lo, hi, max_blocks, |mask, part| {
            mask.is_none_or(|m| m.iter().zip(part).all(|(m, p)| m & p == 0))
        });
        none.map(|none| !none)
    }

    /// Calls `visit` for every block position overlapping the index box `lo..=hi` with the
    /// block's active mask (None where there is no block) and the mask of the box's cells
    /// in it, until `visit` returns false. Returns whether it never did, or None (without
    /// calling it) when the box spans more than `max_blocks` blocks.
    fn visit_box(
        &self,
        lo: [i32; 3],
        hi: [i32; 3],
        max_blocks: i64,
        mut visit: impl FnMut(Option<&[u64; 8]>, &[u64; 8]) -> bool,
    ) -> Option<bool> {
        let blo = lo.map(|c| i64::from(c >> 3));
        let bhi = hi.map(|c| i64::from(c >> 3));
        let mut count = 1i64;
        for a in 0..3 {
            count = count.saturating_mul((bhi[a] - blo[a] + 1).max(0));
        }
        if count > max_blocks {
            return None;
        }
        for bz in blo[2]..=bhi[2] {
            for by in blo[1]..=bhi[1] {
                for bx in blo[0]..=bhi[0] {
                    // Block coordinates come from i32 >> 3, so `* 8` fits in i32.
                    let origin = [bx, by, bz].map(|c| (c * 8) as i32);
                    let part = box_part(origin, lo, hi);
                    let mask = self.index.get(origin).map(|b| self.active.get(b as usize));
                    if !visit(mask, &part) {
                        return Some(false);
                    }
                }
            }
        }
        Some(true)
    }

    #[cfg(test)]
    pub(crate) fn active_count(&self) -> u64 {
        self.active.count()
    }

    pub(crate) fn leaf_count(&self) -> u64 {
        self.leaf.count()
    }

    /// Active slots in slot order.
    pub(crate) fn active_slots(&self) -> impl Iterator<Item = usize> + '_ {
        self.active.iter().enumerate().flat_map(|(b, m)| {
            (0..BLOCK_CELLS)
                .filter(move |&n| bit(m, n))
                .map(move |n| b * BLOCK_CELLS + n)
        })
    }
}

/// Mask of the cells of the index box `lo..=hi` inside the block at `origin` (see
/// [`leaf_offset`]: x selects the word, y and z the bits).
fn box_part(origin: [i32; 3], lo: [i32; 3], hi: [i32; 3]) -> [u64; 8] {
    let r = |a: usize| {
        let l = (i64::from(lo[a]) - i64::from(origin[a])).clamp(0, 7);
        let h = (i64::from(hi[a]) - i64::from(origin[a])).clamp(0, 7);
        (l as usize, h as usize)
    };
    let ((x0, x1), (y0, y1), (z0, z1)) = (r(0), r(1), r(2));
    let row = ((1u64 << (z1 - z0 + 1)) - 1) << z0;
    let word = (y0..=y1).fold(0u64, |w, y| w | row << (8 * y));
    std::array::from_fn(|x| if (x0..=x1).contains(&x) { word } else { 0 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Leaf, Tile};

    pub(super) fn grid(name: &str, w: f64, t: f64, cells: &[[i32; 3]]) -> Grid<f32> {
        let mut leaves: Vec<Leaf<f32>> = Vec::new();
        for &c in cells {
            let o = block_origin(c);
            let idx = match leaves.iter().position(|l| l.origin == o) {
                Some(i) => i,
                None => {
                    leaves.push(Leaf {
                        origin: o,
                        active: [0; 8],
                        values: Box::new([0.0; LEAF_VOXELS]),
                    });
                    leaves.len() - 1
                }
            };
            let n = offset_in_block(c);
            leaves[idx].active[n >> 6] |= 1 << (n & 63);
            leaves[idx].values[n] = 1.0;
        }
        Grid {
            name: name.into(),
            transform: Transform {
                voxel_size: [w; 3],
                translation: [t; 3],
            },
            background: 0.0,
            leaves,
            tiles: vec![],
        }
    }

    #[test]
    fn leaf_off_the_block_lattice_overrides_a_tile() {
        // A (malformed) leaf at x = 4 straddles two blocks; its active voxels win over the
        // tile's values where both are given, and the other tile cells keep theirs.
        let mut leaf = Leaf {
            origin: [4, 0, 0],
            active: [0; 8],
            values: Box::new([0.0f32; LEAF_VOXELS]),
        };
        for (x, v) in [(0, 5.0), (7, 6.0)] {
            let n = leaf_offset(x, 0, 0);
            leaf.active[n >> 6] |= 1 << (n & 63);
            leaf.values[n] = v;
        }
        let g = Grid {
            name: "t".into(),
            transform: Transform {
                voxel_size: [1.0; 3],
                translation: [0.0; 3],
            },
            background: 0.0f32,
            leaves: vec![leaf],
            tiles: vec![Tile {
                origin: [0, 0, 0],
                size: 8,
                value: 2.0,
            }],
        };
        let (s, v) = CellSet::from_grid(g, 0, |x| x).expect("small");
        assert_eq!(s.blocks, vec![[0, 0, 0], [8, 0, 0]]);
        assert_eq!(s.active_count(), 513);
        let at = |ijk| s.active_slot(ijk).map(|slot| v[slot]);
        assert_eq!(at([4, 0, 0]), Some(5.0));
        assert_eq!(at([11, 0, 0]), Some(6.0));
        assert_eq!(at([5, 0, 0]), Some(2.0));
        assert_eq!(at([12, 0, 0]), None);
    }

    #[test]
    fn tiles_expand() {
        let g = Grid {
            name: "t".into(),
            transform: Transform {
                voxel_size: [1.0; 3],
                translation: [0.0; 3],
            },
            background: 0.0f32,
            leaves: vec![],
            tiles: vec![Tile {
                origin: [-8, 0, 8],
                size: 8,
                value: 2.0,
            }],
        };
        let (s, v) = CellSet::from_grid(g, 0, |x| x).expect("small");
        assert_eq!(s.active_count(), 512);
        let slot = s.active_slot([-1, 7, 15]).expect("inside tile");
        assert_eq!(v[slot], 2.0);
        assert!(s.active_slot([0, 0, 8]).is_none());
    }
}
