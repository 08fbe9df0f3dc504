//! The regions one iso value can touch, as a small tree of tight boxes: what iso-surface
//! rays walk instead of the file's KD-tree.
//!
//! An iso-surface search looks for a crossing only in regions whose value range holds the
//! iso value; every other region is stepped over. Walking the file's tree (a quarter of a
//! million nodes on a 5 M-cell wake, depth 33) to find the few per cent of regions that
//! matter is most of a ray's cost when most rays hit nothing. So a view builds, for its
//! field and iso value, the file's tree with every subtree that holds no such region
//! removed and every node left with one child replaced by it, and gives each node the box
//! around its regions:
//! - the order of the file's tree is kept (the two children of a node still lie on the
//!   two sides of its split plane), so the walk is front to back;
//! - a node's box is the union of its regions' boxes, so a ray that passes beside them
//!   is rejected at once instead of descending through empty cells;
//! - a region of one cell lattice is cut into its *parts*, the boxes where its dual cells
//!   can hold the value ([`crate::dual_mask::DualMask::sub_boxes`]): a ray that crosses
//!   the region beside them needs no interval there, and a region with none leaves the
//!   tree;
//! - a leaf's segment is the ray clipped to the leaf's own box (a whole region's, as in
//!   the file's walk, or a part's), and a part's intervals are its region's.
//!
//! Building costs one pass over the subtrees whose range holds the value and the masks of
//! the regions found (a few milliseconds, on all the render threads, before a frame's
//! first tile). The tree belongs to the view it was built for ([`crate::accel::Accel`]);
//! a renderer that keeps views' accelerations builds it once for a still view or a
//! sequence of camera moves at one iso value.
//!
//! Three files, one step each: `build` finds the regions and their parts, `nodes` shapes
//! the tree they form (joins, the parts of a region, the surface-area regrouping), and
//! `tree` is the tree as a ray walks it.

mod build;
mod nodes;
#[cfg(test)]
mod tests;
mod tree;

pub(crate) use tree::{ActiveTree, LeafSearch, Start};

/// Whether the range `[mn, mx]` holds `value`: the one test of which regions an
/// iso-surface search searches, whether it walks the active tree or the file's.
#[inline]
pub(crate) fn range_holds(mn: f32, mx: f32, value: f64) -> bool {
    crate::transfer::range_meets(mn, mx, value, value)
}
