//! One bit per slot of every 8³ block, with the blocks whose bits are all set or all clear
//! sharing one pattern.
//!
//! A cell set holds two such masks (active cells, leaf cells). Held as 64 bytes a block
//! each, they were a third of what a budgeted bake of a billion cells kept resident (0.25
//! of 0.68 GiB): a dense grid's blocks are all wholly active, and under a finer grid a coarse
//! block is wholly covered or not at all except along the finer grid's edges. So each
//! block holds the number of its pattern (4 bytes), and only a block with some bits set and
//! some clear has a pattern of its own. A pattern a block leaves is reused by the next
//! block that needs one, so the patterns never outnumber the blocks that are partly set
//! at once.

use files::limits;

/// The pattern of a block with no bit set.
const NONE: u32 = 0;
/// The pattern of a block with every bit set.
const ALL: u32 = 1;

/// A mask of one bit per slot over a list of blocks (see the module docs).
#[derive(Debug, Clone)]
pub(crate) struct BlockMasks {
    /// Per block: its pattern's index in `patterns`.
    of: Vec<u32>,
    /// `[NONE, ALL, the patterns of blocks partly set …]`.
    patterns: Vec<[u64; 8]>,
    /// Patterns no block uses any more, reused before `patterns` grows.
    unused: Vec<u32>,
}

impl BlockMasks {
    /// `blocks` blocks with no bit set; the per-block part is allocated as
    /// [`limits::vec_of`] checks it, named `what` in its error.
    pub(crate) fn new(what: &str, blocks: usize) -> Result<BlockMasks, limits::LimitError> {
        Ok(BlockMasks {
            of: limits::vec_of(what, blocks)?,
            patterns: vec![[0; 8], [u64::MAX; 8]],
            unused: Vec::new(),
        })
    }

    /// The masks of `n` blocks, block `b`'s from `mask(b)`.
    #[cfg(test)]
    pub(crate) fn from_fn(
        what: &str,
        n: usize,
        mut mask: impl FnMut(usize) -> [u64; 8],
    ) -> Result<BlockMasks, limits::LimitError> {
        let mut m = BlockMasks::new(what, n)?;
        for b in 0..n {
            m.set(b, mask(b));
        }
        Ok(m)
    }

    /// Number of blocks.
    pub(crate) fn len(&self) -> usize {
        self.of.len()
    }

    /// Block `b`'s bits (bit `n` of word `n / 64` for slot `n`).
    #[inline(always)]
    pub(crate) fn get(&self, b: usize) -> &[u64; 8] {
        &self.patterns[self.of[b] as usize]
    }

    /// Whether slot `n` of block `b` is set. A block wholly set or clear is answered from
    /// its pattern number alone (the neighbour lookups of the gradients ask this six times
    /// a cell, mostly in such blocks).
    #[inline(always)]
    pub(crate) fn bit(&self, b: usize, n: usize) -> bool {
        match self.of[b] {
            ALL => true,
            NONE => false,
            p => (self.patterns[p as usize][n >> 6] >> (n & 63)) & 1 == 1,
        }
    }

    /// Sets block `b`'s bits to `mask`.
    pub(crate) fn set(&mut self, b: usize, mask: [u64; 8]) {
        let shared = match mask {
            m if m == [0; 8] => Some(NONE),
            m if m == [u64::MAX; 8] => Some(ALL),
            _ => None,
        };
        let own = self.of[b];
        match (shared, own > ALL) {
            (Some(p), true) => {
                self.unused.push(own);
                self.of[b] = p;
            }
            (Some(p), false) => self.of[b] = p,
            (None, true) => self.patterns[own as usize] = mask,
            (None, false) => {
                self.of[b] = match self.unused.pop() {
                    Some(p) => {
                        self.patterns[p as usize] = mask;
                        p
                    }
                    None => {
                        self.patterns.push(mask);
                        (self.patterns.len() - 1) as u32
                    }
                };
            }
        }
    }

    /// Sets slot `n` of block `b` (one bit at a time, as tiles and leaves off the block
    /// lattice are written: a block filling up holds a pattern only until it is full).
    #[inline]
    pub(crate) fn insert(&mut self, b: usize, n: usize) {
        let own = self.of[b];
        let bit = 1u64 << (n & 63);
        if own > ALL {
            let p = &mut self.patterns[own as usize];
            p[n >> 6] |= bit;
            if p[n >> 6] == u64::MAX && *p == [u64::MAX; 8] {
                self.unused.push(own);
                self.of[b] = ALL;
            }
        } else if own == NONE {
            let mut m = [0u64; 8];
            m[n >> 6] = bit;
            self.set(b, m);
        }
    }

    /// Clears slot `n` of block `b`.
    #[inline]
    pub(crate) fn remove(&mut self, b: usize, n: usize) {
        let own = self.of[b];
        let bit = 1u64 << (n & 63);
        if own > ALL {
            let p = &mut self.patterns[own as usize];
            p[n >> 6] &= !bit;
            if p[n >> 6] == 0 && *p == [0; 8] {
                self.unused.push(own);
                self.of[b] = NONE;
            }
        } else if own == ALL {
            let mut m = [u64::MAX; 8];
            m[n >> 6] &= !bit;
            self.set(b, m);
        }
    }

    /// Every block's bits, in block order.
    pub(crate) fn iter(&self) -> impl ExactSizeIterator<Item = &[u64; 8]> + '_ {
        self.of.iter().map(|&p| &self.patterns[p as usize])
    }

    /// Set bits over all blocks.
    pub(crate) fn count(&self) -> u64 {
        self.iter()
            .map(|m| m.iter().map(|w| u64::from(w.count_ones())).sum::<u64>())
            .sum()
    }

    /// Patterns held for blocks partly set (what the masks hold beyond 4 bytes a block).
    #[cfg(test)]
    pub(crate) fn own_patterns(&self) -> usize {
        self.patterns.len() - 2 - self.unused.len()
    }

    /// Every block's bits as a list (tests compare masks with references built this way).
    #[cfg(test)]
    pub(crate) fn to_vec(&self) -> Vec<[u64; 8]> {
        self.iter().copied().collect()
    }
}

impl PartialEq for BlockMasks {
    /// The same bits in every block, however they are held.
    fn eq(&self, other: &BlockMasks) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A random mask: none, all, or a few bits (the three ways a block is held).
    fn mask() -> impl Strategy<Value = [u64; 8]> {
        prop_oneof![
            Just([0u64; 8]),
            Just([u64::MAX; 8]),
            (0usize..512).prop_map(|n| {
                let mut m = [0u64; 8];
                m[n >> 6] |= 1 << (n & 63);
                m
            }),
            any::<[u64; 8]>(),
        ]
    }

    proptest! {
        /// Whatever is set, inserted or removed in whatever order, every block reads back as
        /// a plain list of masks updated the same way does, and the patterns held never
        /// outnumber the blocks partly set.
        #[test]
        fn masks_read_back_as_a_plain_list(
            blocks in 1usize..12,
            ops in proptest::collection::vec((0usize..12, 0u8..3, mask(), 0usize..512), 0..200),
        ) {
            let mut m = BlockMasks::new("test", blocks).unwrap();
            let mut plain = vec![[0u64; 8]; blocks];
            for (b, op, mask, n) in ops {
                let b = b % blocks;
                match op {
                    0 => {
                        m.set(b, mask);
                        plain[b] = mask;
                    }
                    1 => {
                        m.insert(b, n);
                        plain[b][n >> 6] |= 1 << (n & 63);
                    }
                    _ => {
                        m.remove(b, n);
                        plain[b][n >> 6] &= !(1 << (n & 63));
                    }
                }
                prop_assert_eq!(m.to_vec(), plain.clone());
                let partly = plain.iter().filter(|p| **p != [0; 8] && **p != [u64::MAX; 8]).count();
                prop_assert_eq!(m.own_patterns(), partly);
                prop_assert!(m.patterns.len() <= 2 + blocks);
            }
            for (b, p) in plain.iter().enumerate() {
                for n in [0, 63, 64, 300, 511] {
                    prop_assert_eq!(m.bit(b, n), (p[n >> 6] >> (n & 63)) & 1 == 1);
                }
            }
            let count: u64 = plain.iter().flatten().map(|w| u64::from(w.count_ones())).sum();
            prop_assert_eq!(m.count(), count);
        }
    }

    #[test]
    fn whole_blocks_hold_no_pattern_of_their_own() {
        let m = BlockMasks::from_fn("test", 1000, |b| {
            if b % 2 == 0 {
                [u64::MAX; 8]
            } else {
                [0; 8]
            }
        })
        .unwrap();
        assert_eq!(m.own_patterns(), 0);
        assert_eq!(m.patterns.len(), 2);
        assert_eq!(m.count(), 500 * 512);
    }
}
