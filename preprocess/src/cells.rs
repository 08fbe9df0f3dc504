//! Cells of the input grids on their index lattices, and leaf-cell classification.
//!
//! A [`CellSet`] holds one grid's active cells as 8³ blocks (the VDB leaf layout) with an
//! active mask and a leaf mask, so that neighbour lookups are one hash probe and a bit test.
//! Values live beside it in a plain `Vec` indexed by the same slot (`block * 512 + offset`).
//!
//! A cell is a *leaf cell* when its box is not fully covered by active cells of finer grids
//! (smaller voxel size). Coverage is tested exactly for any lattice offsets: the cell box is
//! cut at every finer-cell boundary inside it and each piece is looked up in the finer grids.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use rayon::prelude::*;

use crate::grid::{leaf_offset, Grid, Transform, LEAF_VOXELS};

/// Cells per block (one VDB leaf).
pub(crate) const BLOCK_CELLS: usize = LEAF_VOXELS;

/// Small multiplicative hasher for integer keys (block origins): the default SipHash costs
/// more than the rest of a neighbour lookup.
#[derive(Default, Clone, Copy)]
pub(crate) struct MixHasher(u64);

impl Hasher for MixHasher {
    fn write(&mut self, bytes: &[u8]) {
        // `[i32; 3]` keys arrive as one 12-byte slice: mix whole words, not bytes.
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            let mut w = [0u8; 8];
            w.copy_from_slice(c);
            self.write_u64(u64::from_le_bytes(w));
        }
        let rest = chunks.remainder();
        if !rest.is_empty() {
            let mut w = [0u8; 8];
            w[..rest.len()].copy_from_slice(rest);
            self.write_u64(u64::from_le_bytes(w) ^ ((rest.len() as u64) << 59));
        }
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    fn write_i32(&mut self, v: i32) {
        self.write_u64(v as u32 as u64);
    }
    fn write_usize(&mut self, v: usize) {
        self.write_u64(v as u64);
    }
    fn finish(&self) -> u64 {
        self.0
    }
}

type BlockMap = HashMap<[i32; 3], u32, BuildHasherDefault<MixHasher>>;

/// Index coordinate of the block holding `ijk`.
fn block_origin(ijk: [i32; 3]) -> [i32; 3] {
    [ijk[0] & !7, ijk[1] & !7, ijk[2] & !7]
}

fn offset_in_block(ijk: [i32; 3]) -> usize {
    leaf_offset(
        (ijk[0] & 7) as usize,
        (ijk[1] & 7) as usize,
        (ijk[2] & 7) as usize,
    )
}

fn bit(mask: &[u64; 8], n: usize) -> bool {
    (mask[n >> 6] >> (n & 63)) & 1 == 1
}

/// One input grid's cells on its lattice.
#[derive(Debug, Clone)]
pub struct CellSet {
    /// Grid name (for messages).
    pub name: String,
    pub transform: Transform,
    /// Cell edge length (the grid's voxel size; cells are cubes).
    pub width: f64,
    /// Level of this grid (0 = finest).
    pub level: u32,
    /// Block origins (multiples of 8 in index space), sorted.
    pub blocks: Vec<[i32; 3]>,
    index: BlockMap,
    /// Active mask per block (bit `n` = offset `n`, see [`leaf_offset`]).
    pub active: Vec<[u64; 8]>,
    /// Leaf mask per block (active and not covered by finer cells); equals `active` until
    /// [`classify_leaves`] runs.
    pub leaf: Vec<[u64; 8]>,
}

impl CellSet {
    /// Builds the cell set of `grid` and its values converted by `conv`, one per slot.
    /// Tiles are expanded to cells; the caller bounds the total beforehand.
    pub(crate) fn from_grid<V: Copy, T: Copy + Default>(
        grid: &Grid<V>,
        level: u32,
        conv: impl Fn(V) -> T,
    ) -> (CellSet, Vec<T>) {
        let mut map: BlockMap = BlockMap::default();
        let mut masks: Vec<[u64; 8]> = Vec::new();
        let mut vals: Vec<T> = Vec::new();
        let mut origins: Vec<[i32; 3]> = Vec::new();
        let mut put = |ijk: [i32; 3], v: T| {
            let bo = block_origin(ijk);
            let b = *map.entry(bo).or_insert_with(|| {
                origins.push(bo);
                masks.push([0; 8]);
                vals.extend(std::iter::repeat_n(T::default(), BLOCK_CELLS));
                (origins.len() - 1) as u32
            }) as usize;
            let n = offset_in_block(ijk);
            masks[b][n >> 6] |= 1 << (n & 63);
            vals[b * BLOCK_CELLS + n] = v;
        };
        // Tiles first, so that leaf voxels win where a (malformed) file has both.
        for t in &grid.tiles {
            let lo = t.origin.map(|c| c as i64);
            let hi = lo.map(|c| (c + t.size as i64).min(i32::MAX as i64 + 1));
            let v = conv(t.value);
            for z in lo[2]..hi[2] {
                for y in lo[1]..hi[1] {
                    for x in lo[0]..hi[0] {
                        put([x as i32, y as i32, z as i32], v);
                    }
                }
            }
        }
        for leaf in &grid.leaves {
            for (ijk, v) in leaf.active_voxels() {
                put(ijk, conv(v));
            }
        }
        // Sort blocks by origin so that nothing depends on the order of leaves in the file.
        let mut order: Vec<usize> = (0..origins.len()).collect();
        order.sort_by_key(|&b| (origins[b][2], origins[b][1], origins[b][0]));
        let mut blocks = Vec::with_capacity(order.len());
        let mut active = Vec::with_capacity(order.len());
        let mut values = Vec::with_capacity(vals.len());
        let mut index = BlockMap::default();
        for (nb, &b) in order.iter().enumerate() {
            blocks.push(origins[b]);
            active.push(masks[b]);
            values.extend_from_slice(&vals[b * BLOCK_CELLS..(b + 1) * BLOCK_CELLS]);
            index.insert(origins[b], nb as u32);
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
        (set, values)
    }

    /// Slot of `ijk` when its block exists (the cell may be inactive).
    pub(crate) fn slot(&self, ijk: [i32; 3]) -> Option<usize> {
        let b = *self.index.get(&block_origin(ijk))? as usize;
        Some(b * BLOCK_CELLS + offset_in_block(ijk))
    }

    /// Active slot of the neighbour `d` cells (|d| <= 8) along `axis` of cell `ijk`
    /// (held in `slot`): in-block arithmetic when the neighbour shares the block.
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
    pub(crate) fn active_slot(&self, ijk: [i32; 3]) -> Option<usize> {
        self.slot(ijk).filter(|&s| self.is_active(s))
    }

    /// Slot of `ijk` when that cell is a leaf cell.
    pub(crate) fn leaf_slot(&self, ijk: [i32; 3]) -> Option<usize> {
        self.slot(ijk).filter(|&s| self.is_leaf(s))
    }

    pub fn is_active(&self, slot: usize) -> bool {
        bit(&self.active[slot / BLOCK_CELLS], slot % BLOCK_CELLS)
    }

    pub(crate) fn is_leaf(&self, slot: usize) -> bool {
        bit(&self.leaf[slot / BLOCK_CELLS], slot % BLOCK_CELLS)
    }

    /// Index coordinate of a slot.
    pub fn ijk(&self, slot: usize) -> [i32; 3] {
        let o = self.blocks[slot / BLOCK_CELLS];
        let n = slot % BLOCK_CELLS;
        [
            o[0] + (n >> 6) as i32,
            o[1] + ((n >> 3) & 7) as i32,
            o[2] + (n & 7) as i32,
        ]
    }

    /// World-space centre of cell `ijk`.
    pub fn centre(&self, ijk: [i32; 3]) -> [f64; 3] {
        self.transform.index_to_world(ijk.map(|c| c as f64))
    }

    /// Index coordinate of the cell containing world point `p` (None outside `i32`).
    pub(crate) fn cell_at(&self, p: [f64; 3]) -> Option<[i32; 3]> {
        let mut out = [0; 3];
        for a in 0..3 {
            let f = round_half_away((p[a] - self.transform.translation[a]) / self.width);
            if !(f >= i32::MIN as f64 && f <= i32::MAX as f64) {
                return None;
            }
            out[a] = f as i32;
        }
        Some(out)
    }

    #[cfg(test)]
    pub(crate) fn active_count(&self) -> u64 {
        self.active
            .iter()
            .flatten()
            .map(|w| w.count_ones() as u64)
            .sum()
    }

    pub(crate) fn leaf_count(&self) -> u64 {
        self.leaf
            .iter()
            .flatten()
            .map(|w| w.count_ones() as u64)
            .sum()
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

/// Marks as non-leaf every active cell whose box is fully covered by active cells of
/// grids with a smaller cell width. Runs in parallel over blocks; the result does not
/// depend on the thread count.
/// `x.round()` (halves away from zero) without the library call that `f64::round` is on
/// the baseline x86-64 target: classification calls it for every cell and every finer
/// grid. Exact for `|x| < 2^52` (beyond that every `f64` is an integer already).
#[inline]
fn round_half_away(x: f64) -> f64 {
    const BIG: f64 = 4_503_599_627_370_496.0; // 2^52
    let a = x.abs();
    if a.is_nan() || a >= BIG {
        return x;
    }
    let t = a as i64 as f64; // trunc(|x|), exact here
    let r = if a - t >= 0.5 { t + 1.0 } else { t };
    r.copysign(x)
}

pub(crate) fn classify_leaves(sets: &mut [CellSet]) {
    let leaves: Vec<Vec<[u64; 8]>> = (0..sets.len())
        .map(|s| {
            let me = &sets[s];
            let finer: Vec<&CellSet> = sets
                .iter()
                .filter(|o| o.width < me.width * (1.0 - 1e-9))
                .collect();
            if finer.is_empty() {
                return me.active.clone();
            }
            (0..me.blocks.len())
                .into_par_iter()
                .map(|b| {
                    let mut mask = me.active[b];
                    let mut cuts: [Vec<f64>; 3] = Default::default();
                    for n in 0..BLOCK_CELLS {
                        if !bit(&mask, n) {
                            continue;
                        }
                        let ijk = me.ijk(b * BLOCK_CELLS + n);
                        let c = me.centre(ijk);
                        // Quick exit: a cell whose centre no finer active cell holds is not
                        // covered (most cells away from finer grids).
                        let centre_in_finer = finer
                            .iter()
                            .any(|g| g.cell_at(c).and_then(|q| g.active_slot(q)).is_some());
                        if !centre_in_finer {
                            continue;
                        }
                        let h = 0.5 * me.width;
                        let lo = c.map(|x| x - h);
                        let hi = c.map(|x| x + h);
                        if box_covered(lo, hi, &finer, &mut cuts) {
                            mask[n >> 6] &= !(1u64 << (n & 63));
                        }
                    }
                    mask
                })
                .collect()
        })
        .collect();
    for (set, leaf) in sets.iter_mut().zip(leaves) {
        set.leaf = leaf;
    }
}

/// Whether the box `[lo, hi]` is covered by the union of the active cells of `finer`.
/// The box is cut at every finer-cell boundary strictly inside it; inside each piece the
/// membership in every finer grid is constant, so testing the piece's midpoint is exact.
fn box_covered(lo: [f64; 3], hi: [f64; 3], finer: &[&CellSet], cuts: &mut [Vec<f64>; 3]) -> bool {
    for a in 0..3 {
        let tol = 1e-7 * (hi[a] - lo[a]);
        let c = &mut cuts[a];
        c.clear();
        c.push(lo[a]);
        for g in finer {
            let w = g.width;
            let t = g.transform.translation[a];
            // Boundaries of g's cells: t + (k - 0.5) w.
            let k0 = ((lo[a] - t) / w + 0.5).floor() as i64;
            let k1 = ((hi[a] - t) / w + 0.5).ceil() as i64;
            if k1 - k0 > 1 << 12 {
                // Absurdly fine grid relative to this cell: treat as not covered (keeps
                // the cell, which is always correct, only less compact).
                return false;
            }
            for k in k0..=k1 {
                let x = t + (k as f64 - 0.5) * w;
                if x > lo[a] + tol && x < hi[a] - tol {
                    c.push(x);
                }
            }
        }
        c.push(hi[a]);
        c.sort_by(f64::total_cmp);
        c.dedup_by(|x, y| (*x - *y).abs() <= tol);
    }
    for iz in 0..cuts[2].len() - 1 {
        let z = 0.5 * (cuts[2][iz] + cuts[2][iz + 1]);
        for iy in 0..cuts[1].len() - 1 {
            let y = 0.5 * (cuts[1][iy] + cuts[1][iy + 1]);
            for ix in 0..cuts[0].len() - 1 {
                let x = 0.5 * (cuts[0][ix] + cuts[0][ix + 1]);
                let p = [x, y, z];
                let inside = finer
                    .iter()
                    .any(|g| g.cell_at(p).and_then(|ijk| g.active_slot(ijk)).is_some());
                if !inside {
                    return false;
                }
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Leaf, Tile};

    fn grid(name: &str, w: f64, t: f64, cells: &[[i32; 3]]) -> Grid<f32> {
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
    fn round_half_away_matches_round() {
        let cases = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.49999999999999994,
            1e15 + 0.5,
            -1e15 - 0.5,
            4.5e15,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            3.2,
            -3.7,
        ];
        for x in cases {
            assert_eq!(round_half_away(x).to_bits(), x.round().to_bits(), "{x}");
        }
        assert!(round_half_away(f64::NAN).is_nan());
        let mut v = 0.123_f64;
        for _ in 0..10_000 {
            v = (v * 7.3 + 0.37).rem_euclid(200.0) - 100.0;
            assert_eq!(round_half_away(v), v.round(), "{v}");
            let h = v.trunc() + 0.5 * v.signum();
            assert_eq!(round_half_away(h), h.round(), "{h}");
        }
    }

    #[test]
    fn coverage_aligned_and_offset() {
        // Coarse cell 0 (width 2, centre 0) spans [-1, 1]; fine cells width 1 centred at
        // -0.5 and 0.5 (translation 0.5 - 1 = -0.5) cover it exactly.
        let mut fine_cells = vec![];
        for z in -1..1 {
            for y in -1..1 {
                for x in -1..1 {
                    fine_cells.push([x, y, z]);
                }
            }
        }
        let fine = grid("fine", 1.0, 0.5, &fine_cells);
        let coarse = grid("coarse", 2.0, 0.0, &[[0, 0, 0], [1, 0, 0]]);
        let (f, _) = CellSet::from_grid(&fine, 0, |v| v);
        let (c, _) = CellSet::from_grid(&coarse, 1, |v| v);
        let mut sets = vec![f, c];
        classify_leaves(&mut sets);
        assert_eq!(sets[1].leaf_count(), 1, "cell 0 covered, cell 1 kept");
        assert!(sets[1].leaf_slot([1, 0, 0]).is_some());
        assert_eq!(sets[0].leaf_count(), 8);

        // Fine lattice shifted by half a fine cell: coarse cell only partially covered.
        let fine2 = grid("fine", 1.0, 0.0, &fine_cells);
        let (f2, _) = CellSet::from_grid(&fine2, 0, |v| v);
        let (c2, _) = CellSet::from_grid(&coarse, 1, |v| v);
        let mut sets = vec![f2, c2];
        classify_leaves(&mut sets);
        assert_eq!(sets[1].leaf_count(), 2);
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
        let (s, v) = CellSet::from_grid(&g, 0, |x| x);
        assert_eq!(s.active_count(), 512);
        let slot = s.active_slot([-1, 7, 15]).expect("inside tile");
        assert_eq!(v[slot], 2.0);
        assert!(s.active_slot([0, 0, 8]).is_none());
    }
}
