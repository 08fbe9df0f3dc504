//! Block origin → block number, the lookup behind every neighbour and coverage test of the
//! bake (millions per grid).
//!
//! Simulation grids are mostly dense boxes of blocks, so when the blocks fill a fair share
//! of their bounding box the index is a plain array over that box (one bounds check and
//! one load per lookup); sparse or far-flung grids keep a hash map, whose memory grows with
//! the number of blocks rather than with the box.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

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

/// Hash map from block origin to block number.
pub(crate) type BlockMap = HashMap<[i32; 3], u32, BuildHasherDefault<MixHasher>>;

/// A dense table is used when it has at most this many entries per block (plus
/// [`DENSE_SLACK`]): 4 bytes per entry, so at worst 16 bytes per 8³ block of cells.
const DENSE_PER_BLOCK: u64 = 4;
/// Entries a dense table may always have, however few blocks there are.
const DENSE_SLACK: u64 = 4096;
/// Marks a position of the dense table without a block.
const NONE: u32 = u32::MAX;

/// Block origin → block number (see the module docs).
#[derive(Debug, Clone)]
pub(crate) enum BlockIndex {
    /// Block numbers over the bounding box of the blocks, x fastest, in units of blocks.
    Dense {
        /// Lowest block coordinate (origin / 8) of the box.
        lo: [i64; 3],
        dims: [u64; 3],
        ids: Vec<u32>,
    },
    Sparse(BlockMap),
}

impl BlockIndex {
    /// Index of `origins` (block `n` has origin `origins[n]`, multiples of 8, no repeats).
    pub(crate) fn new(origins: &[[i32; 3]]) -> BlockIndex {
        let Some(first) = origins.first() else {
            return BlockIndex::Sparse(BlockMap::default());
        };
        let (mut lo, mut hi) = (first.map(|c| c >> 3), first.map(|c| c >> 3));
        for o in origins {
            for a in 0..3 {
                lo[a] = lo[a].min(o[a] >> 3);
                hi[a] = hi[a].max(o[a] >> 3);
            }
        }
        let dims = [0, 1, 2].map(|a| (i64::from(hi[a]) - i64::from(lo[a]) + 1) as u64);
        let entries = dims[0].saturating_mul(dims[1]).saturating_mul(dims[2]);
        let budget = (origins.len() as u64)
            .saturating_mul(DENSE_PER_BLOCK)
            .saturating_add(DENSE_SLACK);
        if entries > budget || u32::try_from(origins.len()).is_err() {
            return BlockIndex::Sparse(
                origins
                    .iter()
                    .enumerate()
                    .map(|(n, &o)| (o, n as u32))
                    .collect(),
            );
        }
        let lo = lo.map(i64::from);
        let mut ids = vec![NONE; entries as usize];
        for (n, o) in origins.iter().enumerate() {
            let at = dense_at(lo, dims, *o).unwrap_or(0);
            ids[at] = n as u32;
        }
        BlockIndex::Dense { lo, dims, ids }
    }

    /// Block number of the block with origin `origin` (a multiple of 8).
    #[inline]
    pub(crate) fn get(&self, origin: [i32; 3]) -> Option<u32> {
        match self {
            BlockIndex::Dense { lo, dims, ids } => {
                let id = ids[dense_at(*lo, *dims, origin)?];
                (id != NONE).then_some(id)
            }
            BlockIndex::Sparse(map) => map.get(&origin).copied(),
        }
    }
}

/// Position of block `origin` in a dense table over `lo`, `dims` (block units), if inside.
#[inline]
fn dense_at(lo: [i64; 3], dims: [u64; 3], origin: [i32; 3]) -> Option<usize> {
    let mut at = 0u64;
    for a in [2, 1, 0] {
        let d = (i64::from(origin[a] >> 3) - lo[a]) as u64;
        if d >= dims[a] {
            return None;
        }
        at = at * dims[a] + d;
    }
    Some(at as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(origins: &[[i32; 3]], dense: bool) {
        let idx = BlockIndex::new(origins);
        assert_eq!(matches!(idx, BlockIndex::Dense { .. }), dense);
        for (n, &o) in origins.iter().enumerate() {
            assert_eq!(idx.get(o), Some(n as u32));
            for a in 0..3 {
                for d in [-8, 8] {
                    let mut q = o;
                    q[a] = q[a].wrapping_add(d);
                    let expect = origins.iter().position(|&p| p == q).map(|p| p as u32);
                    assert_eq!(idx.get(q), expect, "{q:?}");
                }
            }
        }
    }

    #[test]
    fn dense_and_sparse_agree_with_a_search() {
        let mut box_of_blocks = Vec::new();
        for z in -2..3 {
            for y in -1..2 {
                for x in 0..4 {
                    if (x + y + z) % 3 != 0 {
                        box_of_blocks.push([x * 8, y * 8, z * 8]);
                    }
                }
            }
        }
        check(&box_of_blocks, true);
        // Far apart: the box would be huge, so a hash map; extreme coordinates included.
        let far = [
            [i32::MIN, i32::MIN, i32::MIN],
            [i32::MAX & !7, 0, 0],
            [0, 0, i32::MAX & !7],
            [8, -8, 16],
        ];
        check(&far, false);
        check(&[], false);
    }
}
