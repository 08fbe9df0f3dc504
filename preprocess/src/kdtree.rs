//! Serialises a [`RegionTree`] into the file's KD-tree (format 3): inner nodes in
//! depth-first, left-first order (node 0 is the root, parents before children), inner
//! nodes send `coordinate < split` left, and a leaf is a child reference naming a region
//! or empty space ([`format::kd::LEAF`]). Regions are numbered in the same depth-first,
//! left-first order, and each sits in one leaf whose cell is its box.

use format::kd::{self, EMPTY, LEAF, MAX_REGION};
use format::{Aabb, KdNode};

use crate::regions::RegionTree;

/// Regions as the tree numbers them: bounds (the leaf's cell) and sorted brick ids.
pub(crate) type Regions = Vec<(Aabb, Vec<u32>)>;

/// The stored tree (root reference, inner nodes, their axes) and the regions its leaves
/// reference; `None` when there are more regions than a leaf reference can name.
pub(crate) fn flatten(tree: &RegionTree) -> Option<(kd::Packed, Regions)> {
    let mut nodes = Vec::new();
    let mut axes = Vec::new();
    let mut regions = Vec::new();
    let root = emit(tree, &mut nodes, &mut axes, &mut regions)?;
    Some(((root, nodes, axes), regions))
}

/// The child reference of `t`, after storing its subtree.
fn emit(
    t: &RegionTree,
    nodes: &mut Vec<KdNode>,
    axes: &mut Vec<u8>,
    regions: &mut Vec<(Aabb, Vec<u32>)>,
) -> Option<u32> {
    Some(match t {
        RegionTree::Empty => EMPTY,
        RegionTree::Region { bounds, bricks } => {
            let r = u32::try_from(regions.len())
                .ok()
                .filter(|&r| r <= MAX_REGION)?;
            regions.push((*bounds, bricks.clone()));
            LEAF | r
        }
        RegionTree::Split {
            axis,
            split,
            left,
            right,
        } => {
            let id = nodes.len();
            if id as u64 >= u64::from(LEAF) {
                return None;
            }
            nodes.push(KdNode {
                split: *split,
                left: EMPTY,
                right: EMPTY,
            });
            axes.push(*axis);
            let l = emit(left, nodes, axes, regions)?;
            let r = emit(right, nodes, axes, regions)?;
            nodes[id].left = l;
            nodes[id].right = r;
            id as u32
        }
    })
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
