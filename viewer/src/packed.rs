//! The file's KD-tree packed with one field's value ranges, the form every ray walk reads.
//!
//! The file stores no per-node value ranges (format 3 keeps its structure small): packing
//! derives each subtree's range and fullness from the regions' ranges
//! ([`format::kd::subtree_ranges`]) and puts inner node, range and fullness into one
//! 32-byte record, and each region's range into a table of 8 bytes a region (a few
//! milliseconds for a quarter of a million nodes; larger trees on all cores,
//! [`format::kd::subtree_ranges_on`]), so that a walk reads one line per node and skips a
//! whole subtree whose values cannot matter. Which field is packed is a view setting, so a
//! view's acceleration ([`crate::accel`]) owns the tree of its iso field; the volume keeps
//! the first one packed for point location, which any packing serves.

use format::kd::{Node, RangedTree, WalkNodes};

/// A field's packed tree: [`format::kd::subtree_ranges`] of the file's tree.
pub(crate) struct Packed(RangedTree);

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
            file.regions.len(),
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

impl Packed {
    /// A tree without regions: what a view of a tree that failed its check walks.
    pub(crate) fn empty() -> Packed {
        Packed(RangedTree {
            root: format::kd::EMPTY,
            inner: Vec::new(),
            leaves: Vec::new(),
        })
    }
}

impl format::kd::KdTree for Packed {
    fn node_count(&self) -> usize {
        format::kd::KdTree::node_count(&self.0)
    }
    fn root(&self) -> u32 {
        format::kd::KdTree::root(&self.0)
    }
    #[inline(always)]
    fn node(&self, n: u32) -> Option<Node> {
        WalkNodes::node(&self.0, n)
    }
}

impl WalkNodes for Packed {
    fn node_count(&self) -> usize {
        WalkNodes::node_count(&self.0)
    }
    fn root(&self) -> u32 {
        WalkNodes::root(&self.0)
    }
    #[inline(always)]
    fn node(&self, n: u32) -> Option<Node> {
        WalkNodes::node(&self.0, n)
    }
    #[inline(always)]
    fn range(&self, n: u32) -> Option<(f32, f32)> {
        self.0.range(n)
    }
    #[inline(always)]
    fn full(&self, n: u32) -> bool {
        self.0.full(n)
    }
    #[inline(always)]
    fn get(&self, n: u32) -> Option<format::kd::NodeEntry> {
        self.0.get(n)
    }
}
