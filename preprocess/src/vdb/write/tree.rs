//! The 5-4-3 tree, the writer's side of [`crate::vdb::tree`]: a grid's tiles and leaves are
//! placed in the nodes OpenVDB would hold them in (root entries, 32³ upper and 16³ lower
//! internal nodes, 8³ leaves), then written as topology (every node depth first, internal
//! values included, leaves as their value masks) followed by the leaf buffers in the same
//! order. Placing everything first is what catches overlapping or misaligned input before
//! a byte is written. Only the leaves' shapes (origin and active mask) are placed: their
//! values are asked for one batch at a time while the buffers are written, so a grid
//! larger than memory can be written from a function that samples it.

use std::collections::BTreeMap;

use rayon::prelude::*;

use super::source::{GridSource, LeafShape};
use super::values::write_values;
use super::Unwritable;
use crate::grid::LEAF_VOXELS;
use crate::vdb::codec::{CompressionFlags, VdbValue};

/// Leaves (by their index in the source), lower internal nodes (16³ children of 8³) and
/// upper internal nodes (32³ children of 128³), keyed by their index inside the parent, in
/// the order OpenVDB visits them.
struct Lower<V> {
    leaves: BTreeMap<usize, usize>,
    tiles: BTreeMap<usize, V>,
}

struct Upper<V> {
    children: BTreeMap<usize, Lower<V>>,
    tiles: BTreeMap<usize, V>,
}

enum RootEntry<V> {
    Child(Upper<V>),
    Tile(V),
}

type Root<V> = BTreeMap<[i32; 3], RootEntry<V>>;

/// A grid's tiles and leaves placed in their nodes; root entries sorted by origin, as
/// OpenVDB's root table is.
pub(super) struct Tree<V> {
    root: Root<V>,
    background: V,
}

fn upper_index(p: [i32; 3]) -> usize {
    (((p[0] & 4095) >> 7) as usize) << 10
        | (((p[1] & 4095) >> 7) as usize) << 5
        | ((p[2] & 4095) >> 7) as usize
}

fn lower_index(p: [i32; 3]) -> usize {
    (((p[0] & 127) >> 3) as usize) << 8
        | (((p[1] & 127) >> 3) as usize) << 4
        | ((p[2] & 127) >> 3) as usize
}

fn root_key(p: [i32; 3]) -> [i32; 3] {
    p.map(|v| v & !4095)
}

/// Places every tile and leaf of `grid` in its node, refusing overlaps, misaligned origins
/// and tile sizes a 5-4-3 tree does not have.
pub(super) fn build_tree<V: VdbValue>(grid: &GridSource<'_, V>) -> Result<Tree<V>, Unwritable> {
    let mut root: Root<V> = BTreeMap::new();
    // Root tiles first, so that anything placed inside one is reported.
    for t in grid.tiles.iter().filter(|t| t.size == 4096) {
        check_aligned(t.origin, 4096, "tile")?;
        if root.insert(t.origin, RootEntry::Tile(t.value)).is_some() {
            return Err(Unwritable::TwoTiles { origin: t.origin });
        }
    }
    for t in grid.tiles.iter().filter(|t| t.size != 4096) {
        match t.size {
            128 => {
                check_aligned(t.origin, 128, "tile")?;
                let u = upper_of(&mut root, t.origin)?;
                if u.tiles.insert(upper_index(t.origin), t.value).is_some() {
                    return Err(Unwritable::TwoTiles { origin: t.origin });
                }
            }
            8 => {
                check_aligned(t.origin, 8, "tile")?;
                let u = upper_of(&mut root, t.origin)?;
                let ui = upper_index(t.origin);
                if u.tiles.contains_key(&ui) {
                    return Err(Unwritable::InsideUpperTile {
                        what: "tile",
                        origin: t.origin,
                    });
                }
                let lower = u.children.entry(ui).or_insert_with(|| Lower {
                    leaves: BTreeMap::new(),
                    tiles: BTreeMap::new(),
                });
                if lower.tiles.insert(lower_index(t.origin), t.value).is_some() {
                    return Err(Unwritable::TwoTiles { origin: t.origin });
                }
            }
            other => {
                return Err(Unwritable::TileSize {
                    origin: t.origin,
                    size: other,
                })
            }
        }
    }
    for (index, leaf) in grid.leaves.iter().enumerate() {
        check_aligned(leaf.origin, 8, "leaf")?;
        let u = upper_of(&mut root, leaf.origin)?;
        let ui = upper_index(leaf.origin);
        if u.tiles.contains_key(&ui) {
            return Err(Unwritable::InsideUpperTile {
                what: "leaf",
                origin: leaf.origin,
            });
        }
        let lower = u.children.entry(ui).or_insert_with(|| Lower {
            leaves: BTreeMap::new(),
            tiles: BTreeMap::new(),
        });
        let li = lower_index(leaf.origin);
        if lower.tiles.contains_key(&li) {
            return Err(Unwritable::InsideLowerTile {
                origin: leaf.origin,
            });
        }
        if lower.leaves.insert(li, index).is_some() {
            return Err(Unwritable::TwoLeaves {
                origin: leaf.origin,
            });
        }
    }
    Ok(Tree {
        root,
        background: grid.background,
    })
}

/// The upper internal node holding `origin`, created if missing.
fn upper_of<V>(root: &mut Root<V>, origin: [i32; 3]) -> Result<&mut Upper<V>, Unwritable> {
    let entry = root.entry(root_key(origin)).or_insert_with(|| {
        RootEntry::Child(Upper {
            children: BTreeMap::new(),
            tiles: BTreeMap::new(),
        })
    });
    match entry {
        RootEntry::Child(u) => Ok(u),
        RootEntry::Tile(_) => Err(Unwritable::InsideRootTile { origin }),
    }
}

fn check_aligned(origin: [i32; 3], size: i32, what: &'static str) -> Result<(), Unwritable> {
    if origin.iter().any(|v| v.rem_euclid(size) != 0) {
        return Err(Unwritable::Misaligned { what, origin, size });
    }
    Ok(())
}

/// Writes the topology of `tree` to `out` and returns the source's leaf indices in the
/// order their buffers follow it.
pub(super) fn write_topology<V: VdbValue>(
    out: &mut Vec<u8>,
    tree: &Tree<V>,
    shapes: &[LeafShape],
    flags: CompressionFlags,
) -> Vec<usize> {
    let (root, background) = (&tree.root, tree.background);
    // Buffer count, background, root tiles, then each root child's internal nodes depth
    // first down to the leaves' value masks.
    out.extend_from_slice(&1i32.to_le_bytes()); // buffer count
    background.put(out);
    let tiles = root
        .values()
        .filter(|e| matches!(e, RootEntry::Tile(_)))
        .count() as u32;
    let children = root.len() as u32 - tiles;
    out.extend_from_slice(&tiles.to_le_bytes());
    out.extend_from_slice(&children.to_le_bytes());
    for (key, entry) in root {
        if let RootEntry::Tile(v) = entry {
            key.iter()
                .for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
            v.put(out);
            out.push(1); // active
        }
    }
    let mut leaves = Vec::new();
    for (key, entry) in root {
        let RootEntry::Child(upper) = entry else {
            continue;
        };
        key.iter()
            .for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
        let children: Vec<usize> = upper.children.keys().copied().collect();
        write_internal(
            out,
            32 * 32 * 32,
            &children,
            &upper.tiles,
            background,
            flags,
        );
        for lower in upper.children.values() {
            let children: Vec<usize> = lower.leaves.keys().copied().collect();
            write_internal(
                out,
                16 * 16 * 16,
                &children,
                &lower.tiles,
                background,
                flags,
            );
            for &leaf in lower.leaves.values() {
                shapes[leaf]
                    .active
                    .iter()
                    .for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
                leaves.push(leaf);
            }
        }
    }
    leaves
}

/// The buffers (value mask again, then values) of the source's leaves `batch`, encoded in
/// parallel, in order.
pub(super) fn leaf_buffers<V: VdbValue>(
    grid: &GridSource<'_, V>,
    batch: &[usize],
    flags: CompressionFlags,
) -> Vec<Vec<u8>> {
    batch
        .par_iter()
        .map(|&index| {
            let shape = &grid.leaves[index];
            let values = (grid.values)(index);
            let mut out = Vec::with_capacity(64 + 1 + LEAF_VOXELS * V::SIZE);
            shape
                .active
                .iter()
                .for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
            write_values(
                &mut out,
                &values[..],
                &shape.active[..],
                None,
                grid.background,
                flags,
            );
            out
        })
        .collect()
}

/// Child mask, value mask and compressed values of an internal node with `size` slots.
fn write_internal<V: VdbValue>(
    out: &mut Vec<u8>,
    size: usize,
    children: &[usize],
    tiles: &BTreeMap<usize, V>,
    background: V,
    flags: CompressionFlags,
) {
    let words = size / 64;
    let mut child_mask = vec![0u64; words];
    let mut value_mask = vec![0u64; words];
    for &c in children {
        child_mask[c >> 6] |= 1 << (c & 63);
    }
    // Slots that are neither children nor tiles hold the background; child slots hold zero.
    let mut values = vec![background; size];
    for &c in children {
        values[c] = V::default();
    }
    for (&i, &v) in tiles {
        value_mask[i >> 6] |= 1 << (i & 63);
        values[i] = v;
    }
    child_mask
        .iter()
        .for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
    value_mask
        .iter()
        .for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
    write_values(
        out,
        &values,
        &value_mask,
        Some(&child_mask),
        background,
        flags,
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Grid, Leaf, Tile, Transform};

    #[test]
    fn node_indices_follow_openvdb_bit_layout() {
        assert_eq!(upper_index([0, 0, 0]), 0);
        assert_eq!(upper_index([128, 0, 0]), 1 << 10);
        assert_eq!(upper_index([0, 128, 0]), 1 << 5);
        assert_eq!(upper_index([0, 0, 128]), 1);
        assert_eq!(upper_index([-128, -128, -128]), 31 << 10 | 31 << 5 | 31);
        assert_eq!(lower_index([8, 16, 24]), 1 << 8 | 2 << 4 | 3);
        assert_eq!(lower_index([-8, 0, 0]), 15 << 8);
        assert_eq!(root_key([-1, 4095, 4096]), [-4096, 0, 4096]);
    }

    #[test]
    fn overlapping_or_misaligned_nodes_are_refused() {
        let leaf = |origin| Leaf {
            origin,
            active: [u64::MAX; 8],
            values: Box::new([0.0f32; LEAF_VOXELS]),
        };
        let mut g = Grid {
            name: "g".into(),
            transform: Transform {
                voxel_size: [1.0; 3],
                translation: [0.0; 3],
            },
            background: 0.0f32,
            leaves: vec![leaf([0, 0, 0]), leaf([0, 0, 0])],
            tiles: Vec::new(),
        };
        assert!(matches!(
            build_tree(&GridSource::of(&g)),
            Err(Unwritable::TwoLeaves { origin: [0, 0, 0] })
        ));
        g.leaves = vec![leaf([4, 0, 0])];
        assert!(matches!(
            build_tree(&GridSource::of(&g)),
            Err(Unwritable::Misaligned { size: 8, .. })
        ));
        g.leaves = vec![leaf([8, 0, 0])];
        g.tiles = vec![Tile {
            origin: [0, 0, 0],
            size: 128,
            value: 1.0,
        }];
        assert!(matches!(
            build_tree(&GridSource::of(&g)),
            Err(Unwritable::InsideUpperTile { what: "leaf", .. })
        ));
        g.tiles[0].origin = [128, 0, 0];
        assert!(build_tree(&GridSource::of(&g)).is_ok());
    }
}
