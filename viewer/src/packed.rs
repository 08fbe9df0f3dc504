//! The file's KD-tree packed with one field's value ranges, the form every ray walk reads.
//!
//! The file stores no per-node value ranges (format 3 keeps its structure small): packing
//! derives each subtree's range and fullness from the regions' ranges
//! ([`format::kd::subtree_ranges`]) and puts node, range and fullness into one 32-byte
//! record per node (a few milliseconds for a quarter of a million nodes; larger trees on
//! all cores, [`format::kd::subtree_ranges_on`]), so that a walk
//! reads one line per node and skips a whole subtree whose values cannot matter. Which
//! field is packed is a view setting, so a view's acceleration ([`crate::accel`]) owns
//! the tree of its iso field; the volume keeps field 0's for point location, which any
//! packing serves.

use format::kd::{Node, RangedNode, WalkNodes};

/// A field's packed tree: [`format::kd::subtree_ranges`] of the file's tree, node, range
/// and fullness in one 32-byte record per node, the root first.
pub(crate) struct Packed(Vec<RangedNode>);

impl Packed {
    /// The tree of `file` packed with the ranges of field `field` (a field the file does
    /// not have gives no ranges: nothing is skipped).
    pub(crate) fn build(file: &format::ArchivedBrickFile, field: usize) -> Packed {
        let nf = file.fields.len();
        let tree = format::kd::file_tree(file);
        // On all cores from a quarter of a million nodes (a few milliseconds on one):
        // a billion cells make tens of millions, a second of the first frame.
        let threads = if file.kd_nodes.len() >= 1 << 18 {
            std::thread::available_parallelism().map_or(1, |n| n.get())
        } else {
            1
        };
        Packed(format::kd::subtree_ranges_on(
            &tree,
            |r| {
                let v = file
                    .region_ranges
                    .get((r as usize).checked_mul(nf)? + field)?;
                (field < nf).then(|| (v.min.to_native(), v.max.to_native()))
            },
            threads,
        ))
    }
}

impl format::kd::KdTree for Packed {
    fn node_count(&self) -> usize {
        self.0.len()
    }
    fn root(&self) -> u32 {
        0
    }
    #[inline(always)]
    fn node(&self, n: u32) -> Option<Node> {
        WalkNodes::node(self, n)
    }
}

impl WalkNodes for Packed {
    fn node_count(&self) -> usize {
        self.0.len()
    }
    fn root(&self) -> u32 {
        0
    }
    #[inline(always)]
    fn node(&self, n: u32) -> Option<Node> {
        self.0.get(n as usize).map(RangedNode::node)
    }
    #[inline(always)]
    fn range(&self, n: u32) -> Option<(f32, f32)> {
        self.0.get(n as usize).map(|p| (p.min, p.max))
    }
    #[inline(always)]
    fn full(&self, n: u32) -> bool {
        self.0.get(n as usize).is_some_and(|p| p.full)
    }
    #[inline(always)]
    fn get(&self, n: u32) -> Option<format::kd::NodeEntry> {
        let p = self.0.get(n as usize)?;
        Some((p.node(), Some((p.min, p.max)), p.full))
    }
}
