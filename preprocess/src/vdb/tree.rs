//! The 5-4-3 tree: root (background, tiles, children), two levels of internal nodes (32³ and
//! 16³ entries, with child and value masks and one value per entry) and 8³ leaves.
//!
//! A tree is stored as *topology* (all nodes depth first, internal-node values included,
//! leaves only as their value masks) followed by *buffers* (leaf values, in the same
//! depth-first order, root children visited in sorted-coordinate order). How each node's
//! values are stored is [`super::values`]' business.

use rayon::prelude::*;

use super::codec::VdbValue;
use super::compress::Inflater;
use super::cursor::Cursor;
use super::error::{ErrorKind, Invalid, RawError, RawResult};
use super::values::{decode_values, locate_values, read_values, Codec};
use crate::bake::memory::leaf_bytes;
use crate::cells::LEAF_BATCH;
use crate::grid::{Leaf, LeafTopology, Tile, LEAF_VOXELS};

const ROOT_CHILD_LOG2: u32 = 12; // 4096 voxels per root child
const INT1_LOG2: u32 = 5; // 32³ entries in an upper internal node
const INT2_LOG2: u32 = 4; // 16³ entries in a lower internal node
const LEAF_LOG2: u32 = 3;

/// Leaf topology kept between the topology and buffer passes.
struct LeafTopo {
    origin: [i32; 3],
    mask: [u64; 8],
}

/// A leaf whose buffer has been found in the file but not decoded: where it is in the grid
/// and in the file. Decoding it later ([`decode_leaves`]) reads only its own bytes, so a
/// bake can decode a grid a batch of leaves at a time into its cells instead of holding
/// every decoded leaf at once.
#[derive(Debug, Clone, PartialEq)]
pub struct LocatedLeaf {
    pub origin: [i32; 3],
    pub active: [u64; 8],
    /// The file bytes of its buffer (the value mask's copy, then the values).
    pub(crate) bytes: std::ops::Range<usize>,
}

impl LeafTopology for LocatedLeaf {
    fn origin(&self) -> [i32; 3] {
        self.origin
    }
    fn active(&self) -> &[u64; 8] {
        &self.active
    }
}

/// A tree with its leaves located, not decoded.
#[derive(Debug)]
pub(crate) struct LocatedTree<V> {
    pub background: V,
    pub tiles: Vec<Tile<V>>,
    /// In file order.
    pub leaves: Vec<LocatedLeaf>,
}

fn child_origin(parent: [i32; 3], n: usize, log2: u32, child_log2: u32) -> [i32; 3] {
    let m = (1usize << log2) - 1;
    let x = (n >> (2 * log2)) as i32;
    let y = ((n >> log2) & m) as i32;
    let z = (n & m) as i32;
    [
        parent[0] + (x << child_log2),
        parent[1] + (y << child_log2),
        parent[2] + (z << child_log2),
    ]
}

struct TopoReader<V> {
    codec: Codec,
    background: V,
    tiles: Vec<Tile<V>>,
    leaves: Vec<LeafTopo>,
    scratch: Vec<V>,
}

impl<V: VdbValue> TopoReader<V> {
    /// One internal node: child mask, value mask, values, then its children.
    fn internal(&mut self, cur: &mut Cursor<'_>, origin: [i32; 3], log2: u32) -> RawResult<()> {
        let entries = 1usize << (3 * log2);
        let child_log2 = if log2 == INT1_LOG2 {
            INT2_LOG2 + LEAF_LOG2
        } else {
            LEAF_LOG2
        };
        let what = "internal node";
        let child_mask = cur.mask(entries, what)?;
        let value_mask = cur.mask(entries, what)?;
        self.scratch.resize(entries, V::default());
        let mut values = std::mem::take(&mut self.scratch);
        read_values(
            cur,
            self.codec,
            self.background,
            &value_mask,
            &mut values,
            what,
        )?;
        for (w, (&c, &a)) in child_mask.iter().zip(&value_mask).enumerate() {
            let mut tiles = a & !c;
            while tiles != 0 {
                let n = w * 64 + tiles.trailing_zeros() as usize;
                tiles &= tiles - 1;
                self.tiles.push(Tile {
                    origin: child_origin(origin, n, log2, child_log2),
                    size: 1 << child_log2,
                    value: values[n],
                });
            }
        }
        self.scratch = values;
        for (w, &c) in child_mask.iter().enumerate() {
            let mut children = c;
            while children != 0 {
                let n = w * 64 + children.trailing_zeros() as usize;
                children &= children - 1;
                let child = child_origin(origin, n, log2, child_log2);
                if log2 == INT1_LOG2 {
                    self.internal(cur, child, INT2_LOG2)?;
                } else {
                    let bytes = cur.take(64, "leaf topology")?;
                    let mut mask = [0u64; 8];
                    for (m, c) in mask.iter_mut().zip(bytes.chunks_exact(8)) {
                        let mut a = [0u8; 8];
                        a.copy_from_slice(c);
                        *m = u64::from_le_bytes(a);
                    }
                    self.leaves.push(LeafTopo {
                        origin: child,
                        mask,
                    });
                }
            }
        }
        Ok(())
    }
}

fn aligned(c: [i32; 3], log2: u32) -> bool {
    c.iter().all(|v| v & ((1 << log2) - 1) == 0)
}

/// Every leaf of `tree` decoded from `data` a batch at a time, in file order, after a check
/// that the shared memory limit holds them all. `release` hears the range of the file each
/// batch was read from once it is decoded: a reader of a mapped file lets those pages go
/// ([`files::input::Whole::release`]), so a large file is never held whole beside the
/// leaves decoded from it.
pub(crate) fn decode_all<V: VdbValue>(
    data: &[u8],
    codec: Codec,
    tree: &LocatedTree<V>,
    release: &dyn Fn(std::ops::Range<usize>),
) -> RawResult<Vec<Leaf<V>>> {
    // Compressed leaves take a few dozen bytes in the file and kilobytes in memory: the
    // file's size bounds the leaf count, not their memory, so it is checked here.
    if let Some(last) = tree.leaves.last() {
        let n = tree.leaves.len();
        let need = (n as u64).saturating_mul(leaf_bytes::<V>());
        files::limits::check_memory(format!("decoding {n} leaves"), need).map_err(|e| {
            RawError::new(
                last.bytes.end,
                "leaf buffers",
                ErrorKind::Memory(Box::new(e)),
            )
        })?;
    }
    let mut leaves = Vec::with_capacity(tree.leaves.len());
    for batch in tree.leaves.chunks(LEAF_BATCH) {
        leaves.extend(decode_leaves(data, codec, tree.background, batch)?);
        release(batch_bytes(batch));
    }
    Ok(leaves)
}

/// The file bytes a batch of leaves (in file order) was read from.
pub(crate) fn batch_bytes(batch: &[LocatedLeaf]) -> std::ops::Range<usize> {
    match (batch.first(), batch.last()) {
        (Some(a), Some(b)) => a.bytes.start..b.bytes.end,
        _ => 0..0,
    }
}

/// Decodes `leaves` (located in `data` by [`locate_tree`]) in parallel: decompression,
/// half floats and inactive values are independent per leaf.
pub(crate) fn decode_leaves<V: VdbValue>(
    data: &[u8],
    codec: Codec,
    background: V,
    leaves: &[LocatedLeaf],
) -> RawResult<Vec<Leaf<V>>> {
    leaves
        .par_iter()
        .map_init(Inflater::default, |inflater, leaf| {
            let mut cur = Cursor::new(&data[..leaf.bytes.end], leaf.bytes.start);
            // The value mask is stored again; OpenVDB ignores the copy when seeking.
            cur.skip(64, "leaf buffer")?;
            let frame = locate_values(
                &mut cur,
                codec,
                background,
                &leaf.active,
                LEAF_VOXELS,
                "leaf buffer",
            )?;
            let mut values = Box::new([V::default(); LEAF_VOXELS]);
            decode_values(&frame, codec, &leaf.active, &mut values[..], inflater)?;
            Ok(Leaf {
                origin: leaf.origin,
                active: leaf.active,
                values,
            })
        })
        .collect()
}

/// Bytes of leaf buffers [`locate_tree`] walks before it lets their pages go: well under
/// the 16 MiB of fixed overhead a `--memory` budget allows, since the walk runs before the
/// budget's windows apply (a madvise call per 4 MiB costs nothing beside the walk).
const LOCATE_RELEASE_BYTES: usize = 4 << 20;

/// Reads a tree's topology and finds its leaf buffers (each one checked to be whole and
/// well-formed as far as that can be told without decoding it), starting at the buffer
/// count; the cursor ends after the tree. Every buffer's header is read, so the walk reads
/// nearly every page of the tree: `release` hears the ranges walked, every
/// [`LOCATE_RELEASE_BYTES`] and at the end, so that a mapped file's pages are let go behind
/// it (they are read again when the leaves are decoded).
pub(crate) fn locate_tree<V: VdbValue>(
    cur: &mut Cursor<'_>,
    codec: Codec,
    release: &dyn Fn(std::ops::Range<usize>),
) -> RawResult<LocatedTree<V>> {
    // Topology: buffer count, root background, root tiles and children.
    let start = cur.pos();
    let buffers = cur.i32("tree buffer count")?;
    if buffers != 1 {
        return Err(RawError::invalid(
            start,
            "tree buffer count",
            Invalid::BufferCount { count: buffers },
        ));
    }
    let background = V::from_bytes(cur.take(V::SIZE, "background value")?);
    let counts_at = cur.pos();
    let num_tiles = cur.u32("root tile count")? as usize;
    let num_children = cur.u32("root child count")? as usize;
    let tile_bytes = 12 + V::SIZE + 1;
    // A child takes at least its coordinate and two 4 KiB masks.
    let child_bytes = 12 + 2 * 4096;
    if num_tiles.saturating_mul(tile_bytes) > cur.left()
        || num_children.saturating_mul(child_bytes) > cur.left()
    {
        return Err(RawError::new(
            counts_at,
            "root node",
            ErrorKind::Truncated {
                expected: format!("{num_tiles} tiles and {num_children} child nodes"),
                left: cur.left() as u64,
            },
        ));
    }
    let mut reader = TopoReader {
        codec,
        background,
        tiles: Vec::new(),
        leaves: Vec::new(),
        scratch: Vec::new(),
    };
    let mut keys = Vec::with_capacity(num_tiles + num_children);
    for _ in 0..num_tiles {
        let at = cur.pos();
        let origin = cur.vec3i("root tile")?;
        let value = V::from_bytes(cur.take(V::SIZE, "root tile")?);
        let active = cur.u8("root tile")? != 0;
        if !aligned(origin, ROOT_CHILD_LOG2) {
            return Err(RawError::invalid(
                at,
                "root tile",
                Invalid::RootOrigin { origin },
            ));
        }
        keys.push((origin, at));
        if active {
            reader.tiles.push(Tile {
                origin,
                size: 1 << ROOT_CHILD_LOG2,
                value,
            });
        }
    }
    // Per root child: origin and the range of its leaves in `reader.leaves`.
    let mut children = Vec::with_capacity(num_children);
    for _ in 0..num_children {
        let at = cur.pos();
        let origin = cur.vec3i("root child")?;
        if !aligned(origin, ROOT_CHILD_LOG2) {
            return Err(RawError::invalid(
                at,
                "root child",
                Invalid::RootOrigin { origin },
            ));
        }
        keys.push((origin, at));
        let first = reader.leaves.len();
        reader.internal(cur, origin, INT1_LOG2)?;
        children.push((origin, first..reader.leaves.len()));
    }
    keys.sort_unstable();
    if let Some(w) = keys.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(RawError::invalid(
            w[1].1,
            "root node",
            Invalid::DuplicateRootEntry { origin: w[1].0 },
        ));
    }

    // Buffers: leaf values, root children in sorted order (OpenVDB's root table is a
    // sorted map).
    children.sort_unstable_by_key(|c| c.0);
    let TopoReader {
        tiles,
        leaves: topo,
        ..
    } = reader;
    let mut leaves = Vec::with_capacity(topo.len());
    let mut behind = cur.pos();
    for (_, range) in children {
        for t in &topo[range] {
            let at = cur.pos();
            if at - behind >= LOCATE_RELEASE_BYTES {
                release(behind..at);
                behind = at;
            }
            // The value mask is stored again; OpenVDB ignores the copy when seeking.
            cur.skip(64, "leaf buffer")?;
            locate_values(cur, codec, background, &t.mask, LEAF_VOXELS, "leaf buffer")?;
            leaves.push(LocatedLeaf {
                origin: t.origin,
                active: t.mask,
                bytes: at..cur.pos(),
            });
        }
    }
    release(behind..cur.pos());
    Ok(LocatedTree {
        background,
        tiles,
        leaves,
    })
}
