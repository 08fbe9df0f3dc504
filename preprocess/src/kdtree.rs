//! Serialises a [`RegionTree`] into the file's KD-tree (format 3): inner nodes in
//! depth-first, left-first order (node 0 is the root, parents before children), inner
//! nodes send `coordinate < split` left, and a leaf is a child reference naming a region
//! or empty space ([`format::kd::LEAF`]). Regions are numbered in the same depth-first,
//! left-first order, and each sits in one leaf whose cell is its box.

use format::kd::{self, EMPTY, LEAF, MAX_REGION};
use format::{Aabb, KdNode, Region};

use crate::regions::RegionTree;

/// Regions as the tree numbers them, laid out as the file stores them: region `r`'s box
/// is `bounds[r]` (its leaf's cell) and its sorted brick ids are the run `runs[r]` of
/// `bricks`. Flat, so that a bake's millions of regions cost their ids and a few bytes
/// each, not a heap allocation each (a copy of each list beside the tree's own made the
/// regions stage of a billion cells, 16.6 M regions, 1.5 GB larger).
#[derive(Debug, Default)]
pub(crate) struct Regions {
    pub bounds: Vec<Aabb>,
    pub runs: Vec<Region>,
    pub bricks: Vec<u32>,
}

impl Regions {
    pub(crate) fn len(&self) -> usize {
        self.runs.len()
    }

    /// The sorted brick ids of region `r`.
    pub(crate) fn bricks_of(&self, r: usize) -> &[u32] {
        let run = &self.runs[r];
        let start = run.bricks_start as usize;
        &self.bricks[start..start + run.bricks_len as usize]
    }
}

/// Why a tree cannot be stored: more regions than a leaf reference can name (counted
/// whole), or more brick references than a region's `u32` run can reach.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum TooLarge {
    Regions(u64),
    BrickRefs(u64),
}

/// The stored tree (root reference, inner nodes, their axes) and the regions its leaves
/// reference. The tree is consumed as it is stored (each node freed once emitted), so the
/// tree and its flat copy are never both held whole.
pub(crate) fn flatten(tree: RegionTree) -> Result<(kd::Packed, Regions), TooLarge> {
    let mut out = Flat::default();
    let root = out.emit(tree);
    if out.regions_seen > u64::from(MAX_REGION) + 1 || out.nodes_seen > u64::from(LEAF) {
        return Err(TooLarge::Regions(out.regions_seen));
    }
    if out.refs_seen > u64::from(u32::MAX) {
        return Err(TooLarge::BrickRefs(out.refs_seen));
    }
    Ok(((root, out.nodes, out.axes), out.regions))
}

/// What [`flatten`] has stored so far; past a limit it only counts.
#[derive(Default)]
struct Flat {
    nodes: Vec<KdNode>,
    axes: Vec<u8>,
    regions: Regions,
    regions_seen: u64,
    refs_seen: u64,
    nodes_seen: u64,
}

impl Flat {
    fn full(&self) -> bool {
        self.regions_seen > u64::from(MAX_REGION) + 1
            || self.refs_seen > u64::from(u32::MAX)
            || self.nodes_seen > u64::from(LEAF)
    }

    /// The child reference of `t`, after storing its subtree.
    fn emit(&mut self, t: RegionTree) -> u32 {
        match t {
            RegionTree::Empty => EMPTY,
            RegionTree::Region { bounds, bricks } => {
                let r = self.regions_seen;
                self.regions_seen += 1;
                let start = self.refs_seen;
                self.refs_seen += bricks.len() as u64;
                if self.full() {
                    return EMPTY;
                }
                let rs = &mut self.regions;
                rs.bounds.push(bounds);
                rs.runs.push(Region {
                    bricks_start: start as u32,
                    bricks_len: bricks.len() as u32,
                });
                rs.bricks.extend_from_slice(&bricks);
                LEAF | r as u32
            }
            RegionTree::Split {
                axis,
                split,
                left,
                right,
            } => {
                let id = self.nodes.len();
                self.nodes_seen += 1;
                if !self.full() {
                    self.nodes.push(KdNode {
                        split,
                        left: EMPTY,
                        right: EMPTY,
                    });
                    self.axes.push(axis);
                }
                let l = self.emit(*left);
                let r = self.emit(*right);
                if let Some(n) = self.nodes.get_mut(id) {
                    n.left = l;
                    n.right = r;
                }
                id as u32
            }
        }
    }
}

/// Region containing `p` by descending the tree (for tests and the baker's self-check):
/// the file's own descent, [`format::kd::locate`].
#[cfg(test)]
pub(crate) fn locate(tree: &kd::Packed, p: [f64; 3]) -> Option<u32> {
    let (root, nodes, axes) = tree;
    format::kd::locate(
        &kd::Stored {
            root: *root,
            nodes,
            axes,
        },
        p,
        [0.0; 3],
    )
}
