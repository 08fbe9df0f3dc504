//! Serialises a [`RegionTree`] into the file's KD-tree: node 0 is the root, inner nodes
//! send `coordinate < split` left, leaves hold a region id or nothing (empty space).
//! Regions are numbered in depth-first, left-first order.

use format::KdNode;

use crate::regions::RegionTree;
use format::Aabb;

/// KD nodes and the regions (bounds, sorted brick ids) they reference.
pub(crate) fn flatten(tree: &RegionTree) -> (Vec<KdNode>, Vec<(Aabb, Vec<u32>)>) {
    let mut nodes = Vec::new();
    let mut regions = Vec::new();
    if !matches!(tree, RegionTree::Empty) {
        emit(tree, &mut nodes, &mut regions);
    }
    (nodes, regions)
}

fn emit(t: &RegionTree, nodes: &mut Vec<KdNode>, regions: &mut Vec<(Aabb, Vec<u32>)>) -> u32 {
    let id = nodes.len() as u32;
    match t {
        RegionTree::Empty => nodes.push(KdNode::Leaf { region: None }),
        RegionTree::Region { bounds, bricks } => {
            nodes.push(KdNode::Leaf {
                region: Some(regions.len() as u32),
            });
            regions.push((*bounds, bricks.clone()));
        }
        RegionTree::Split {
            axis,
            split,
            left,
            right,
        } => {
            nodes.push(KdNode::Leaf { region: None });
            let l = emit(left, nodes, regions);
            let r = emit(right, nodes, regions);
            nodes[id as usize] = KdNode::Inner {
                axis: *axis,
                split: *split,
                left: l,
                right: r,
            };
        }
    }
    id
}

/// Region containing `p` by descending the nodes (for tests and the baker's self-check):
/// the file's own descent, [`format::kd::locate`].
pub(crate) fn locate(nodes: &[KdNode], p: [f64; 3]) -> Option<u32> {
    format::kd::locate(nodes, p, [0.0; 3])
}
