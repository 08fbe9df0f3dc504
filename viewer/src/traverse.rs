//! Front-to-back region traversal along a ray: the file's KD walk
//! ([`format::kd::segments`]) in the volume's local frame, over a per-field packed copy
//! of the tree.
//!
//! The file stores no per-node value ranges (format 3 keeps its structure small): the
//! first walk over a field derives each subtree's range and fullness from the regions'
//! ranges ([`format::kd::subtree_ranges`]) and packs node, range and fullness into one
//! 32-byte record per node (a few milliseconds for a quarter of a million nodes, once per
//! field and open file); every later walk reads one line per node. Opening stays free,
//! and a field that is never traversed is never packed.

pub use format::kd::{inverse, ray_box, Segment, Skip, SKIPPED};
use format::kd::{Node, RangedNode, WalkNodes};

use crate::volume::Volume;

/// A field's packed tree: [`format::kd::subtree_ranges`] of the file's tree, node, range
/// and fullness in one 32-byte record per node, the root first.
pub(crate) struct Packed(Vec<RangedNode>);

impl Packed {
    pub fn build(file: &format::ArchivedBrickFile, field: usize) -> Packed {
        let nf = file.fields.len();
        Packed(format::kd::subtree_ranges(
            &format::kd::file_tree(file),
            |r| {
                let v = file
                    .region_ranges
                    .get((r as usize).checked_mul(nf)? + field)?;
                (field < nf).then(|| (v.min.to_native(), v.max.to_native()))
            },
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

impl Volume<'_> {
    /// Calls `f` for every region the ray `o + t d` (local frame) crosses within
    /// `[t_min, t_max]`, front to back; `f` returns `false` to stop.
    pub fn segments<F: FnMut(Segment) -> bool>(
        &self,
        o: [f64; 3],
        d: [f64; 3],
        t_min: f64,
        t_max: f64,
        stack: &mut Vec<(u32, f64, f64)>,
        f: F,
    ) {
        let skip = format::kd::keep_all();
        self.segments_skipping(o, d, t_min, t_max, stack, &skip, f)
    }

    /// As [`Volume::segments`], but a KD subtree whose value range `skip.keep` rejects is
    /// reported as one [`SKIPPED`] segment over the ray's part of the subtree's cell.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(crate) fn segments_skipping<K: Fn(f32, f32) -> bool, F: FnMut(Segment) -> bool>(
        &self,
        o: [f64; 3],
        d: [f64; 3],
        t_min: f64,
        t_max: f64,
        stack: &mut Vec<(u32, f64, f64)>,
        skip: &Skip<K>,
        f: F,
    ) {
        match self.packed(skip.field) {
            Some(packed) => format::kd::segments(
                self.file, packed, self.frame, o, d, t_min, t_max, stack, skip, f,
            ),
            None => {
                let stored = format::kd::FileNodes::new(self.file, skip.field);
                format::kd::segments(
                    self.file, &stored, self.frame, o, d, t_min, t_max, stack, skip, f,
                )
            }
        }
    }
}
