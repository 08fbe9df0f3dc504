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
use format::kd::{Node, WalkNodes};

use crate::volume::Volume;

/// A KD node with one field's range and fullness (one half cache line).
#[derive(Debug, Clone, Copy)]
pub(crate) struct PackedNode {
    /// Split plane as stored (world), inner nodes.
    split: f64,
    /// Inner: left child; leaf: region or `u32::MAX` for empty space.
    a: u32,
    /// Inner: right child.
    b: u32,
    min: f32,
    max: f32,
    /// 0..=2: inner node splitting this axis; 3: leaf.
    axis: u8,
    full: bool,
}

/// A field's packed tree.
pub(crate) struct Packed(Vec<PackedNode>);

impl Packed {
    /// Field `field`'s packed tree: nodes in depth-first, left-first order, the root
    /// first.
    pub fn build(file: &format::ArchivedBrickFile, field: usize) -> Packed {
        let nf = file.fields.len();
        let entries = format::kd::subtree_ranges(&format::kd::file_tree(file), |r| {
            let v = file
                .region_ranges
                .get((r as usize).checked_mul(nf)? + field)?;
            (field < nf).then(|| (v.min.to_native(), v.max.to_native()))
        });
        Packed(
            entries
                .iter()
                .map(|e| {
                    let (min, max) = e.range;
                    match e.node {
                        Node::Inner { axis, split, .. } => PackedNode {
                            split,
                            a: e.children[0],
                            b: e.children[1],
                            min,
                            max,
                            axis: axis.min(2) as u8,
                            full: e.full,
                        },
                        Node::Leaf(r) => PackedNode {
                            split: 0.0,
                            a: r.unwrap_or(u32::MAX),
                            b: 0,
                            min,
                            max,
                            axis: 3,
                            full: e.full,
                        },
                    }
                })
                .collect(),
        )
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
        let p = self.0.get(n as usize)?;
        Some(if p.axis < 3 {
            Node::Inner {
                axis: usize::from(p.axis),
                split: p.split,
                left: p.a,
                right: p.b,
            }
        } else {
            Node::Leaf((p.a != u32::MAX).then_some(p.a))
        })
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
        let node = if p.axis < 3 {
            Node::Inner {
                axis: usize::from(p.axis),
                split: p.split,
                left: p.a,
                right: p.b,
            }
        } else {
            Node::Leaf((p.a != u32::MAX).then_some(p.a))
        };
        Some((node, Some((p.min, p.max)), p.full))
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
