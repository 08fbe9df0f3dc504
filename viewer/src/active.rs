//! The regions one iso value can touch, as a small tree of tight boxes: what `exact`
//! walks instead of the file's KD-tree.
//!
//! `exact` looks for a crossing only in regions whose value range holds the iso value;
//! every other region is stepped over. Walking the file's tree (a quarter of a million
//! nodes on a 5 M-cell wake, depth 33) to find the few per cent of regions that matter
//! is most of a ray's cost when most rays hit nothing. So the first `exact` ray of a
//! frame builds, once per (field, iso value), the file's tree with every subtree that
//! holds no such region removed and every node left with one child replaced by it, and
//! gives each node the box around its regions:
//! - the order of the file's tree is kept (the two children of a node still lie on the
//!   two sides of its split plane), so the walk is front to back;
//! - a node's box is the union of its regions' boxes, so a ray that passes beside them
//!   is rejected at once instead of descending through empty cells;
//! - a region of one cell lattice is cut into its *parts*, the boxes where its dual cells
//!   can hold the value ([`DualMask::sub_boxes`]): a ray that crosses the region beside
//!   them needs no interval there, and a region with none leaves the tree;
//! - a leaf's segment is the ray clipped to the leaf's own box (a whole region's, as in
//!   the file's walk, or a part's), and a part's intervals are its region's.
//!
//! Building costs one pass over the subtrees whose range holds the value and the masks of
//! the regions found (a few milliseconds, on all the render threads); the volume keeps the
//! last few trees, so a still view or a sequence of frames at one iso value builds once.
//!
//! The walk reads a compact copy of the tree ([`Walk`]): every inner node holds both
//! children's boxes in `f32`, widened outwards, in one 64-byte record, so a ray reads one
//! cache line per level and only descends into children it may meet; a leaf keeps its
//! region's exact `f64` box, and the segment is clipped to that, so the `f32` boxes only
//! ever let through more candidates, never fewer, and the segments stay bit-identical.

use std::sync::Arc;

use format::kd::{inverse, ray_box, Node, Segment, WalkNodes};

use rayon::prelude::*;

use crate::dual_mask::{DualMask, SubBox, MAX_TREE_WORK};
use crate::sampling::{Lattice, Lattices};
use crate::volume::Volume;

/// Marker of "no node".
const NONE: u32 = u32::MAX;
/// `ActiveNode::axis` of a leaf.
const LEAF: u8 = 3;

/// A node of the active tree (local frame).
#[derive(Debug, Clone, Copy)]
struct ActiveNode {
    /// Union of the boxes of the regions below (a leaf: its region's box).
    min: [f64; 3],
    max: [f64; 3],
    /// Inner: the child below the split plane; leaf: the region.
    a: u32,
    /// Inner: the child at or above the split plane.
    b: u32,
    /// 0..=2: inner node split on this axis; [`LEAF`]: a region.
    axis: u8,
    /// Leaf: its region has more cell lattices than `exact` cuts.
    inexact: bool,
    /// Leaf: how many of [`ActiveTree::lattices`], from `b` on, are its region's.
    lattices: u8,
    /// Leaf: its region's index in [`ActiveTree::masks`], or [`NONE`].
    mask: u32,
    /// Leaf of a whole region: its index in the list of the regions' sub-boxes while the
    /// tree is built ([`ActiveTree::build`]), or [`NONE`].
    sub: u32,
}

/// Whether the range `[mn, mx]` holds `value`: the one test of which regions `exact`
/// searches, whether it walks the active tree or the file's.
#[inline]
pub(crate) fn range_holds(mn: f32, mx: f32, value: f64) -> bool {
    crate::transfer::range_meets(mn, mx, value, value)
}

/// The regions whose range of one field holds one value, in the file's tree order.
pub(crate) struct ActiveTree {
    field: usize,
    /// `f64::to_bits` of the value (bits, so that a NaN value is a key like any other).
    value_bits: u64,
    /// The cell lattices of every leaf's region, leaf after leaf: `exact` cuts a segment at
    /// their planes, and listing them once here spares each segment a pass over the
    /// region's bricks.
    lattices: Vec<Lattice>,
    /// The dual-cell masks of the leaves' regions of one lattice ([`crate::dual_mask`];
    /// `None` where the region's box is too large for one).
    masks: Vec<Option<DualMask>>,
    /// What the ray walk reads (built from the tree of [`ActiveNode`]s).
    walk: Walk,
}

/// Reference bit of a [`Walk`] child that is a leaf (`LEAF_REF | index into leaves`).
const LEAF_REF: u32 = 1 << 31;

/// An inner node of the walk: both children's boxes (local frame, `f32`, widened so that
/// a ray that meets the exact box always meets these), axis by axis with the two
/// children side by side so that both are tested at once, and the children (the left one,
/// below the split plane on `axis`, first). One 64-byte line.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
struct WalkInner {
    lo: [[f32; 2]; 3],
    hi: [[f32; 2]; 3],
    child: [u32; 2],
    axis: u8,
}

/// A leaf of the walk: its region, exact box and lattices.
#[derive(Debug, Clone, Copy)]
struct WalkLeaf {
    min: [f64; 3],
    max: [f64; 3],
    region: u32,
    /// First of its lattices in [`ActiveTree::lattices`], and how many.
    first: u32,
    lattices: u8,
    inexact: bool,
    /// Index in [`ActiveTree::masks`], or [`NONE`].
    mask: u32,
}

/// The active tree as the ray walk reads it.
#[derive(Debug, Default)]
struct Walk {
    /// Exact box of everything (the root's), tested in `f64` once per ray.
    min: [f64; 3],
    max: [f64; 3],
    /// Reference of the root (`None`: empty tree).
    root: Option<u32>,
    inner: Vec<WalkInner>,
    leaves: Vec<WalkLeaf>,
}

impl Walk {
    /// The walk over `nodes` (children before parents, root last).
    fn of(nodes: &[ActiveNode]) -> Walk {
        let Some(root) = nodes.last() else {
            return Walk::default();
        };
        // Largest coordinate magnitude the walk meets: the slab test's rounding error is
        // relative to it (rays start on the root box, see `segments`).
        let scale = (0..3)
            .map(|a| root.min[a].abs().max(root.max[a].abs()))
            .fold(0.0f64, f64::max)
            .max(f64::MIN_POSITIVE);
        // How far the `f32` boxes are widened: about a hundred times the slab test's
        // rounding (a few units of 2^-24 of `scale`) for a ray that starts on the root box.
        let pad = scale * (2.0f64).powi(-16);
        let mut walk = Walk {
            min: root.min,
            max: root.max,
            root: None,
            inner: Vec::new(),
            leaves: Vec::new(),
        };
        let lo32 = |v: f64| {
            let x = (v - pad) as f32;
            if f64::from(x) > v - pad {
                x.next_down()
            } else {
                x
            }
        };
        let hi32 = |v: f64| {
            let x = (v + pad) as f32;
            if f64::from(x) < v + pad {
                x.next_up()
            } else {
                x
            }
        };
        // Top-down from the root; an inner node's slot is filled once its children have
        // references.
        let mut todo: Vec<(u32, Option<(usize, usize)>)> = vec![((nodes.len() - 1) as u32, None)];
        while let Some((n, parent)) = todo.pop() {
            let node = &nodes[n as usize];
            let r = if node.axis == LEAF {
                walk.leaves.push(WalkLeaf {
                    min: node.min,
                    max: node.max,
                    region: node.a,
                    first: node.b,
                    lattices: node.lattices,
                    inexact: node.inexact,
                    mask: node.mask,
                });
                LEAF_REF | (walk.leaves.len() - 1) as u32
            } else {
                let i = walk.inner.len();
                let (a, b) = (&nodes[node.a as usize], &nodes[node.b as usize]);
                walk.inner.push(WalkInner {
                    lo: std::array::from_fn(|k| [lo32(a.min[k]), lo32(b.min[k])]),
                    hi: std::array::from_fn(|k| [hi32(a.max[k]), hi32(b.max[k])]),
                    child: [u32::MAX; 2],
                    axis: node.axis,
                });
                todo.push((node.b, Some((i, 1))));
                todo.push((node.a, Some((i, 0))));
                i as u32
            };
            match parent {
                None => walk.root = Some(r),
                Some((p, side)) => walk.inner[p].child[side] = r,
            }
        }
        walk
    }
}

/// Whether the ray `o + t d` meets each child box of `node` for some `t` in `[t0, t1]`.
/// `inv` is `1/d` with every infinite component (a ray parallel to that axis) replaced
/// by `±f32::MAX`: then no `0 · ∞` arises, so no NaN, and the test needs no branch; a
/// parallel ray outside a slab gets a huge entry or a huge negative exit and is rejected,
/// one inside it gets no constraint. Straight-line code over both children, which the
/// compiler keeps in vector registers.
#[inline(always)]
fn meets(node: &WalkInner, o: &[f32; 3], inv: &[f32; 3], t0: f32, t1: f32) -> [bool; 2] {
    let (mut near, mut far) = ([t0; 2], [t1; 2]);
    for a in 0..3 {
        for c in 0..2 {
            let ta = (node.lo[a][c] - o[a]) * inv[a];
            let tb = (node.hi[a][c] - o[a]) * inv[a];
            let (enter, exit) = if ta < tb { (ta, tb) } else { (tb, ta) };
            near[c] = if enter > near[c] { enter } else { near[c] };
            far[c] = if exit < far[c] { exit } else { far[c] };
        }
    }
    [near[0] <= far[0], near[1] <= far[1]]
}

/// Where the walks of a group of rays start in an [`ActiveTree`] (see
/// [`ActiveTree::start_in`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Start {
    /// At the root: any ray.
    Root,
    /// At this node (a [`Walk`] reference): everything outside it lies outside the
    /// group's frustum.
    At(u32),
    /// Nowhere: no region of the tree lies in the group's frustum.
    Nothing,
}

impl ActiveTree {
    /// Where the rays inside `frustum` can start their walk: the deepest node above
    /// every region whose box may lie in the frustum, found by descending while only one
    /// child's box may (the walk reads the same children in the same order below it, so
    /// every ray of the group gets the same segments as from the root, after fewer
    /// tests), or [`Start::Nothing`] when no box may. A tile of pixels beside the
    /// surface then skips the walk altogether.
    pub(crate) fn start_in(&self, frustum: &crate::camera::Frustum) -> Start {
        let walk = &self.walk;
        let Some(mut r) = walk.root else {
            return Start::Nothing;
        };
        if !frustum.may_meet(&walk.min, &walk.max) {
            return Start::Nothing;
        }
        // A tree's depth bounds the descent; the count only guards a malformed walk.
        for _ in 0..=walk.inner.len() {
            if r & LEAF_REF != 0 {
                let Some(leaf) = walk.leaves.get((r & !LEAF_REF) as usize) else {
                    return Start::Root;
                };
                return if frustum.may_meet(&leaf.min, &leaf.max) {
                    Start::At(r)
                } else {
                    Start::Nothing
                };
            }
            let Some(node) = walk.inner.get(r as usize) else {
                return Start::Root;
            };
            let child_box = |c: usize| -> ([f64; 3], [f64; 3]) {
                (
                    std::array::from_fn(|a| f64::from(node.lo[a][c])),
                    std::array::from_fn(|a| f64::from(node.hi[a][c])),
                )
            };
            let [m0, m1] = [0, 1].map(|c| {
                let (lo, hi) = child_box(c);
                frustum.may_meet(&lo, &hi)
            });
            r = match (m0, m1) {
                (true, true) => return Start::At(r),
                (true, false) => node.child[0],
                (false, true) => node.child[1],
                (false, false) => return Start::Nothing,
            };
        }
        Start::Root
    }

    /// Whether this tree answers for `value` in field `field`.
    pub(crate) fn is_for(&self, field: usize, value: f64) -> bool {
        self.field == field && self.value_bits == value.to_bits()
    }

    /// The tree of the regions of `vol` whose range of `field` holds `value`, built from
    /// the field's packed KD-tree (its per-node ranges prune whole subtrees), each region
    /// of one cell lattice cut into the parts where its dual cells can hold the value
    /// ([`DualMask::sub_boxes`]). `None` when the file's tree cannot be walked as a tree
    /// (the caller then walks the file's tree itself). `parallel` builds the regions'
    /// masks on the current rayon pool: only for a caller that holds no lock another job
    /// of that pool may wait for.
    pub fn build(vol: &Volume, field: usize, value: f64, parallel: bool) -> Option<ActiveTree> {
        Self::build_with(vol, field, value, parallel, true, MAX_TREE_WORK)
    }

    /// [`ActiveTree::build`] with every region whole (what the cut tree is compared with).
    #[cfg(test)]
    pub(crate) fn uncut(vol: &Volume, field: usize, value: f64) -> Option<ActiveTree> {
        Self::build_with(vol, field, value, false, false, MAX_TREE_WORK)
    }

    /// [`ActiveTree::build`] with the masks' work bounded by `mask_work` instead of
    /// [`MAX_TREE_WORK`], and how many regions got a mask.
    #[cfg(test)]
    pub(crate) fn with_mask_work(
        vol: &Volume,
        field: usize,
        value: f64,
        mask_work: usize,
    ) -> Option<(ActiveTree, usize)> {
        let tree = Self::build_with(vol, field, value, false, true, mask_work)?;
        let masks = tree.masks.iter().filter(|m| m.is_some()).count();
        Some((tree, masks))
    }

    /// How many leaves the tree has, and how many regions they belong to.
    #[cfg(test)]
    pub(crate) fn leaf_count(&self) -> (usize, usize) {
        let mut regions: Vec<u32> = self.walk.leaves.iter().map(|l| l.region).collect();
        regions.sort_unstable();
        regions.dedup();
        (self.walk.leaves.len(), regions.len())
    }

    /// [`ActiveTree::build`]; `cut: false` keeps every region whole (its leaf box is the
    /// region's box), which the tests compare the cut tree with; the masks are built in
    /// the tree's order while their work stays within `mask_work`.
    fn build_with(
        vol: &Volume,
        field: usize,
        value: f64,
        parallel: bool,
        cut: bool,
        mask_work: usize,
    ) -> Option<ActiveTree> {
        let tree = vol.packed(field)?;
        let holds = |mn: f32, mx: f32| range_holds(mn, mx, value);
        let mut nodes: Vec<ActiveNode> = Vec::new();
        let mut lattices: Vec<Lattice> = Vec::new();
        // Post-order without recursion (a valid tree may still be deep): `(node, expanded)`.
        let mut todo: Vec<(u32, bool)> = Vec::with_capacity(64);
        // The active-tree node each finished subtree became, or `NONE`.
        let mut done: Vec<u32> = Vec::with_capacity(64);
        if tree.node_count() > 0 {
            todo.push((tree.root(), false));
        }
        // Every node is visited at most twice in a tree; more means it is not one.
        let mut budget = tree.node_count().saturating_mul(2).saturating_add(2);
        while let Some((n, expanded)) = todo.pop() {
            budget = budget.checked_sub(1)?;
            let (node, range, _) = tree.get(n)?;
            if expanded {
                let (Node::Inner { axis, .. }, Some(hi), Some(lo)) = (node, done.pop(), done.pop())
                else {
                    return None;
                };
                done.push(join(&mut nodes, lo, hi, axis.min(2) as u8));
                continue;
            }
            if range.is_some_and(|(mn, mx)| !holds(mn, mx)) {
                done.push(NONE);
                continue;
            }
            match node {
                Node::Inner { left, right, .. } => {
                    todo.push((n, true));
                    todo.push((right, false));
                    todo.push((left, false));
                }
                Node::Leaf(Some(r)) if (r as usize) < vol.region_count() => {
                    let [mn, mx] = vol.range(r as usize, field);
                    if holds(mn, mx) {
                        let reg = vol.region(r as usize);
                        let l = Lattices::of(vol, r as usize);
                        let first = u32::try_from(lattices.len()).ok()?;
                        lattices.extend_from_slice(l.as_slice());
                        nodes.push(ActiveNode {
                            min: reg.min,
                            max: reg.max,
                            a: r,
                            b: first,
                            axis: LEAF,
                            inexact: l.inexact,
                            lattices: l.as_slice().len() as u8,
                            mask: NONE,
                            sub: NONE,
                        });
                        done.push((nodes.len() - 1) as u32);
                    } else {
                        done.push(NONE);
                    }
                }
                Node::Leaf(_) => done.push(NONE),
            }
        }
        match done.as_slice() {
            [] | [NONE] => nodes.clear(),
            [root] if *root as usize + 1 == nodes.len() => {}
            _ => return None,
        }
        // The masks of the regions of one lattice, and where in them the value can lie,
        // within a bound on the work of them all.
        let mut mask_budget = mask_work;
        let masked: Vec<usize> = (0..nodes.len())
            .filter(|&i| {
                let n = &nodes[i];
                if n.axis != LEAF || n.lattices != 1 || n.inexact {
                    return false;
                }
                let bricks = vol.region_brick_ids(n.a as usize).len();
                let work = DualMask::work(&lattices[n.b as usize], &n.min, &n.max, bricks);
                let fits = work <= mask_budget;
                if fits {
                    mask_budget -= work;
                }
                fits
            })
            .collect();
        let prepare = |&i: &usize| {
            let leaf = &nodes[i];
            let mut bricks = Vec::new();
            vol.dual_bricks(leaf.a as usize, &mut bricks);
            let mask = DualMask::build(
                vol,
                &bricks,
                &lattices[leaf.b as usize],
                &leaf.min,
                &leaf.max,
                field,
                value,
            );
            let subs = match (&mask, cut) {
                (Some(m), true) => Some(m.sub_boxes(&leaf.min, &leaf.max)),
                _ => None,
            };
            (mask, subs)
        };
        let prepared: Vec<(Option<DualMask>, Option<Vec<SubBox>>)> = if parallel {
            masked.par_iter().map(prepare).collect()
        } else {
            masked.iter().map(prepare).collect()
        };
        let mut masks = Vec::with_capacity(prepared.len());
        let mut subs: Vec<Vec<SubBox>> = Vec::new();
        for (&i, (mask, sub)) in masked.iter().zip(prepared) {
            let leaf = &mut nodes[i];
            leaf.mask = u32::try_from(masks.len()).ok()?;
            masks.push(mask);
            if let Some(sub) = sub {
                // The leaf stands for its parts: their box, or nothing.
                let (mut mn, mut mx) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
                for b in &sub {
                    for a in 0..3 {
                        mn[a] = mn[a].min(b.min[a]);
                        mx[a] = mx[a].max(b.max[a]);
                    }
                }
                (leaf.min, leaf.max) = (mn, mx);
                leaf.sub = u32::try_from(subs.len()).ok()?;
                subs.push(sub);
            }
        }
        // Regions no part of which can hold the value leave the tree.
        nodes = rewrite(&nodes, |leaf, out| {
            let empty = leaf.sub != NONE && subs[leaf.sub as usize].is_empty();
            if !empty {
                out.push(*leaf);
            }
            !empty
        });
        if let Some(better) = surface_area_tree(&nodes) {
            nodes = better;
        }
        // Each cut region becomes the tree of its parts.
        nodes = rewrite(&nodes, |leaf, out| {
            match subs.get(leaf.sub as usize) {
                Some(parts) if leaf.sub != NONE && !parts.is_empty() => {
                    let mut parts = parts.clone();
                    part_tree(&mut parts, leaf, out);
                }
                _ => out.push(*leaf),
            }
            true
        });
        let walk = Walk::of(&nodes);
        Some(ActiveTree {
            field,
            value_bits: value.to_bits(),
            lattices,
            masks,
            walk,
        })
    }

    /// Calls `f` for every leaf of the tree the ray `o + t d` (local frame) crosses
    /// within `[t_min, t_max]`, front to back (a whole region, or one part of a region
    /// where its dual cells can hold the value), with the region's range of the field,
    /// its cell lattices, whether it has more than are listed, and its dual-cell mask;
    /// `f` returns `false` to stop. `stack` is scratch space reused between calls.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn segments<F: FnMut(Segment, &[Lattice], bool, Option<&DualMask>) -> bool>(
        &self,
        vol: &Volume,
        start: Start,
        o: [f64; 3],
        d: [f64; 3],
        t_min: f64,
        t_max: f64,
        stack: &mut Vec<(u32, f64, f64)>,
        mut f: F,
    ) {
        let walk = &self.walk;
        let root = match (walk.root, start) {
            (None, _) | (_, Start::Nothing) => return,
            (Some(root), Start::Root) => root,
            (Some(_), Start::At(node)) => node,
        };
        if t_min >= t_max || t_min.is_nan() || t_max.is_nan() {
            return;
        }
        let inv = inverse(&d);
        let Some((r0, r1)) = ray_box(&walk.min, &walk.max, &o, &inv, t_min, t_max) else {
            return;
        };
        // The `f32` tests run on the ray moved to start where it enters the root box, so
        // that their rounding is relative to the data's size, not to the camera's
        // distance; the widened boxes cover it. A ray parallel to every axis (no finite
        // entry) keeps its origin: only the parallel checks apply to it.
        let (o32, t_hi): ([f32; 3], f32) = if r0.is_finite() && r1.is_finite() {
            let start: [f64; 3] = std::array::from_fn(|a| o[a] + r0 * d[a]);
            (start.map(|v| v as f32), ((r1 - r0) * (1.0 + 1e-4)) as f32)
        } else {
            (o.map(|v| v as f32), f32::INFINITY)
        };
        let t_lo = -t_hi.min(1.0) * 1e-4 - f32::MIN_POSITIVE;
        let inv32 = inv.map(|v| {
            let x = v as f32;
            if x.is_finite() {
                x
            } else {
                f32::MAX.copysign(x)
            }
        });
        stack.clear();
        let mut next = Some(root);
        loop {
            let Some(mut r) = next.take().or_else(|| stack.pop().map(|e| e.0)) else {
                return;
            };
            while r & LEAF_REF == 0 {
                let node = &walk.inner[r as usize];
                let hit = meets(node, &o32, &inv32, t_lo, t_hi);
                // The two children lie on the two sides of the split plane: the one on
                // the side the ray starts from comes first.
                let (near, far) = if d[usize::from(node.axis)] > 0.0 {
                    (0, 1)
                } else {
                    (1, 0)
                };
                match (hit[near], hit[far]) {
                    (true, true) => {
                        stack.push((node.child[far], 0.0, 0.0));
                        r = node.child[near];
                    }
                    (true, false) => r = node.child[near],
                    (false, true) => r = node.child[far],
                    (false, false) => break,
                }
            }
            if r & LEAF_REF == 0 {
                continue;
            }
            let leaf = &walk.leaves[(r & !LEAF_REF) as usize];
            let Some((s0, s1)) = ray_box(&leaf.min, &leaf.max, &o, &inv, t_min, t_max) else {
                continue;
            };
            let [mn, mx] = vol.range(leaf.region as usize, self.field);
            let first = leaf.first as usize;
            let lattices = self
                .lattices
                .get(first..first + usize::from(leaf.lattices))
                .unwrap_or(&[]);
            let seg = Segment {
                region: leaf.region,
                t0: s0,
                t1: s1,
                min: mn,
                max: mx,
            };
            let mask = self.masks.get(leaf.mask as usize).and_then(Option::as_ref);
            if !f(seg, lattices, leaf.inexact, mask) {
                return;
            }
        }
    }
}

/// The node that joins the subtrees `lo` (below a split plane on `axis`) and `hi` (at or
/// above it) of `nodes`, either of which may be [`NONE`]: a new inner node around both, the
/// one that is there, or [`NONE`].
fn join(nodes: &mut Vec<ActiveNode>, lo: u32, hi: u32, axis: u8) -> u32 {
    match (lo, hi) {
        (NONE, NONE) => NONE,
        (x, NONE) | (NONE, x) => x,
        (lo, hi) => {
            let (l, h) = (nodes[lo as usize], nodes[hi as usize]);
            nodes.push(ActiveNode {
                min: std::array::from_fn(|a| l.min[a].min(h.min[a])),
                max: std::array::from_fn(|a| l.max[a].max(h.max[a])),
                a: lo,
                b: hi,
                axis,
                inexact: false,
                lattices: 0,
                mask: NONE,
                sub: NONE,
            });
            (nodes.len() - 1) as u32
        }
    }
}

/// `tree` (children before parents, root last) with every leaf replaced by what `leaf`
/// appends for it and returns `true` (a subtree, children before parents and its root
/// last), or by nothing when it returns `false` (the leaf leaves the tree). An inner node left with one child becomes that child, and
/// inner boxes are those of what remains below them.
fn rewrite(
    tree: &[ActiveNode],
    mut leaf: impl FnMut(&ActiveNode, &mut Vec<ActiveNode>) -> bool,
) -> Vec<ActiveNode> {
    let mut out = Vec::with_capacity(tree.len());
    let mut map = Vec::with_capacity(tree.len());
    for node in tree {
        let r = if node.axis == LEAF {
            if leaf(node, &mut out) {
                (out.len() - 1) as u32
            } else {
                NONE
            }
        } else {
            let (lo, hi) = (map[node.a as usize], map[node.b as usize]);
            join(&mut out, lo, hi, node.axis)
        };
        map.push(r);
    }
    out
}

/// Appends the tree of one region's parts (`leaf` stands for the region): split
/// recursively between blocks, on the axis along which the parts' blocks spread most,
/// so that every inner node has a plane between its two sides, as the walk needs.
/// Children before parents, the root last.
fn part_tree(parts: &mut [SubBox], leaf: &ActiveNode, out: &mut Vec<ActiveNode>) {
    if let [p] = parts {
        out.push(ActiveNode {
            min: p.min,
            max: p.max,
            sub: NONE,
            ..*leaf
        });
        return;
    }
    let spread = |a: usize| {
        let (lo, hi) = parts.iter().fold((u32::MAX, 0), |(lo, hi), p| {
            (lo.min(p.block[a]), hi.max(p.block[a]))
        });
        hi - lo
    };
    let axis = (0..3).max_by_key(|&a| spread(a)).unwrap_or(0);
    parts.sort_unstable_by_key(|p| p.block[axis]);
    // Below the median block on the axis, and the rest (at least one part each: parts lie
    // in distinct blocks, so they spread along some axis).
    let mid = parts[parts.len() / 2].block[axis];
    let mut k = parts.partition_point(|p| p.block[axis] < mid);
    if k == 0 {
        k = parts.partition_point(|p| p.block[axis] <= mid);
    }
    let (lo, hi) = parts.split_at_mut(k);
    part_tree(lo, leaf, out);
    let a = (out.len() - 1) as u32;
    part_tree(hi, leaf, out);
    let b = (out.len() - 1) as u32;
    join(out, a, b, axis as u8);
}

/// Above this many regions the active tree keeps the file's splits: the surface-area
/// build sorts at every node, which would make an iso value that touches much of a large
/// file slow to switch to.
const SAH_MAX_LEAVES: usize = 1 << 15;

/// Surface area of a box (what the chance of a ray meeting it grows with).
fn area(min: &[f64; 3], max: &[f64; 3]) -> f64 {
    let e: [f64; 3] = std::array::from_fn(|a| (max[a] - min[a]).max(0.0));
    e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
}

/// The leaves of `tree` (children before parents, root last) regrouped by the surface
/// area heuristic: at every node, of all planes that separate the node's regions into two
/// non-empty groups without cutting one (a region lies wholly on one side), the one that
/// minimises `area(left) · count(left) + area(right) · count(right)`. The file's splits
/// were chosen for all regions; for the few that hold one iso value, tighter groups let a
/// ray that passes beside them stop sooner. Every node keeps a separating plane, so the
/// walk stays front to back. Root last, like the input. `None` (keep `tree`) when there is
/// nothing to regroup, too much, or no separating plane somewhere.
fn surface_area_tree(tree: &[ActiveNode]) -> Option<Vec<ActiveNode>> {
    let mut leaves: Vec<ActiveNode> = tree.iter().filter(|n| n.axis == LEAF).copied().collect();
    if leaves.len() < 3 || leaves.len() > SAH_MAX_LEAVES {
        return None;
    }
    // Built top-down into slots (index 0 is the root), then reversed so that the root is
    // last and children come before parents, as the walk expects.
    let mut out: Vec<ActiveNode> = vec![leaves[0]];
    let mut work: Vec<(usize, usize, usize)> = vec![(0, leaves.len(), 0)];
    let mut prefix: Vec<([f64; 3], [f64; 3], f64)> = Vec::with_capacity(leaves.len());
    while let Some((lo, hi, slot)) = work.pop() {
        let items = &mut leaves[lo..hi];
        if items.len() == 1 {
            out[slot] = items[0];
            continue;
        }
        // Best separating plane: (cost, axis, number of items on the left).
        let mut best: Option<(f64, usize, usize)> = None;
        for axis in 0..3 {
            items.sort_unstable_by(|p, q| p.min[axis].total_cmp(&q.min[axis]));
            // Left groups: bounds and the largest upper face so far.
            prefix.clear();
            let (mut mn, mut mx) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            for it in items.iter() {
                for a in 0..3 {
                    mn[a] = mn[a].min(it.min[a]);
                    mx[a] = mx[a].max(it.max[a]);
                }
                prefix.push((mn, mx, mx[axis]));
            }
            let (mut rmn, mut rmx) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            for k in (1..items.len()).rev() {
                for a in 0..3 {
                    rmn[a] = rmn[a].min(items[k].min[a]);
                    rmx[a] = rmx[a].max(items[k].max[a]);
                }
                let (lmn, lmx, reach) = prefix[k - 1];
                // Items are sorted by lower face: a plane at items[k].min separates the
                // first k from the rest when none of the first k reaches past it (the
                // rest all start at or after it).
                if reach > items[k].min[axis] {
                    continue;
                }
                let cost =
                    area(&lmn, &lmx) * k as f64 + area(&rmn, &rmx) * (items.len() - k) as f64;
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, k));
                }
            }
        }
        let (_, axis, k) = best?;
        items.sort_unstable_by(|p, q| p.min[axis].total_cmp(&q.min[axis]));
        let (mut mn, mut mx) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for it in items.iter() {
            for a in 0..3 {
                mn[a] = mn[a].min(it.min[a]);
                mx[a] = mx[a].max(it.max[a]);
            }
        }
        let (left, right) = (out.len(), out.len() + 1);
        out.push(items[0]);
        out.push(items[0]);
        out[slot] = ActiveNode {
            min: mn,
            max: mx,
            a: left as u32,
            b: right as u32,
            axis: axis as u8,
            inexact: false,
            lattices: 0,
            mask: NONE,
            sub: NONE,
        };
        work.push((lo, lo + k, left));
        work.push((lo + k, hi, right));
    }
    // Reverse: slot i becomes n - 1 - i.
    let n = out.len();
    out.reverse();
    for node in &mut out {
        if node.axis != LEAF {
            node.a = (n - 1 - node.a as usize) as u32;
            node.b = (n - 1 - node.b as usize) as u32;
        }
    }
    Some(out)
}

/// The last few active trees of a volume, newest last.
#[derive(Default)]
pub(crate) struct ActiveCache(std::sync::Mutex<Vec<Arc<ActiveTree>>>);

/// How many (field, value) trees a volume keeps: a view, its shadow rays and a window
/// that flips between a few iso values reuse them.
const KEEP: usize = 4;

impl ActiveCache {
    /// The tree for `value` in `field`, built on first use (on the current rayon pool
    /// when `parallel`, see [`ActiveTree::build`]).
    pub(crate) fn get(
        &self,
        vol: &Volume,
        field: usize,
        value: f64,
        parallel: bool,
    ) -> Option<Arc<ActiveTree>> {
        // A poisoned lock only means another thread panicked while holding it; the list
        // itself is always whole.
        let lock = || self.0.lock().unwrap_or_else(|e| e.into_inner());
        // The kept tree for (field, value), moved to the newest place.
        let kept = |trees: &mut Vec<Arc<ActiveTree>>| {
            let i = trees.iter().position(|t| t.is_for(field, value))?;
            let t = trees.remove(i);
            trees.push(t.clone());
            Some(t)
        };
        if let Some(t) = kept(&mut lock()) {
            return Some(t);
        }
        // Built without the lock: a parallel build may run other jobs of its pool while
        // it waits, and one of them may ask for a tree too.
        let t = Arc::new(ActiveTree::build(vol, field, value, parallel)?);
        let mut trees = lock();
        // Another thread may have built it meanwhile: everyone shares the first.
        if let Some(t) = kept(&mut trees) {
            return Some(t);
        }
        if trees.len() == KEEP {
            trees.remove(0);
        }
        trees.push(t.clone());
        Some(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testvol;
    use format::kd::{Skip, SKIPPED};

    /// `(region, t0 bits, t1 bits)` of every region the file's walk gives `exact` (the
    /// regions whose range holds `iso`), and the same from the active tree.
    type Seg = (u32, u64, u64);

    fn both(vol: &Volume, iso: f64, o: [f64; 3], d: [f64; 3], t: (f64, f64)) -> [Vec<Seg>; 2] {
        let mut stack = Vec::new();
        let mut file = Vec::new();
        let skip = Skip {
            field: 0,
            keep: |a: f32, b: f32| range_holds(a, b, iso),
            across_gaps: true,
        };
        vol.segments_skipping(o, d, t.0, t.1, &mut stack, &skip, |s| {
            if s.region != SKIPPED && range_holds(s.min, s.max, iso) {
                file.push((s.region, s.t0.to_bits(), s.t1.to_bits()));
            }
            true
        });
        let tree = ActiveTree::uncut(vol, 0, iso).expect("a valid tree");
        let mut active = Vec::new();
        tree.segments(
            vol,
            Start::Root,
            o,
            d,
            t.0,
            t.1,
            &mut stack,
            |s, l, inexact, _| {
                let want = Lattices::of(vol, s.region as usize);
                assert_eq!(l, want.as_slice(), "lattices of region {}", s.region);
                assert_eq!(inexact, want.inexact);
                active.push((s.region, s.t0.to_bits(), s.t1.to_bits()));
                true
            },
        );
        [file, active]
    }

    /// Deterministic numbers in `[0, 1)`.
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Rays from anywhere in every direction, rays along cell faces and level boundaries
    /// (axis-parallel, on whole coordinates), rays starting inside or far away, negative
    /// `t` ranges, and data placed at 1e6: the active walk lists exactly the regions the file's walk
    /// lets `exact` search, in the same order, with bit-identical `t`.
    #[test]
    fn the_active_walk_gives_the_file_walks_segments_bit_for_bit() {
        for offset in [[0.0; 3], [1e6, -1e6, 1e6]] {
            let shell = move |p: [f64; 3]| {
                let r2: f64 = (0..3).map(|a| (p[a] - offset[a] - 8.3).powi(2)).sum();
                r2.sqrt()
            };
            let file = testvol::nested(8, offset, &[("r", &shell)], 3);
            let view = testvol::open(&file).expect("opens");
            let vol = Volume::new(&view).expect("volume");
            let c = vol.to_local(offset.map(|x| x + 8.0));
            let mut seed = 7;
            let mut checked = 0;
            for iso in [2.5, 4.0, 6.0] {
                let mut rays = Vec::new();
                for _ in 0..400 {
                    let o: [f64; 3] = std::array::from_fn(|a| c[a] + 24.0 * (lcg(&mut seed) - 0.5));
                    let d: [f64; 3] = std::array::from_fn(|_| lcg(&mut seed) - 0.5);
                    rays.push((o, d, (-30.0, 30.0)));
                    rays.push((o, d, (0.0, f64::INFINITY)));
                }
                for a in 0..3 {
                    for k in 0..=16 {
                        let mut o = [c[0] - 8.0, c[1] - 8.0, c[2] - 8.0];
                        o[(a + 1) % 3] += k as f64;
                        o[(a + 2) % 3] += (k % 5) as f64 * 2.0;
                        let mut d = [0.0; 3];
                        d[a] = if k % 2 == 0 { 1.0 } else { -1.0 };
                        o[a] -= 20.0 * d[a];
                        rays.push((o, d, (0.0, f64::INFINITY)));
                        let mut d2 = d;
                        d2[(a + 1) % 3] = 0.5;
                        rays.push((o, d2, (0.0, 100.0)));
                    }
                }
                // Rays from far away (the walk's `f32` boxes are tested on the ray
                // moved to the data's box) aimed at whole and half coordinates, where
                // region faces and level boundaries lie.
                for k in 0..200 {
                    let target: [f64; 3] = std::array::from_fn(|a| {
                        c[a] + ((24.0 * (lcg(&mut seed) - 0.5)) * 2.0).round() / 2.0
                    });
                    let d: [f64; 3] = std::array::from_fn(|_| lcg(&mut seed) - 0.5);
                    let far = [1e2, 1e4, 1e6][k % 3];
                    let o: [f64; 3] = std::array::from_fn(|a| target[a] - far * d[a]);
                    rays.push((o, d, (0.0, f64::INFINITY)));
                }
                for (o, d, t) in rays {
                    let [file, active] = both(&vol, iso, o, d, t);
                    assert_eq!(file, active, "iso {iso}, ray {o:?} + t {d:?}, t in {t:?}");
                    checked += usize::from(!file.is_empty());
                }
            }
            assert!(
                checked > 500,
                "only {checked} rays met a region of the shell"
            );
        }
    }

    /// An iso value no region holds gives an empty tree (no walk at all), and the volume
    /// keeps one tree per (field, value): asking again returns the same tree.
    #[test]
    fn no_region_holds_the_value_so_the_tree_is_empty_and_trees_are_kept() {
        let f = |p: [f64; 3]| p[0] + 0.5 * p[1];
        let file = testvol::nested(4, [0.0; 3], &[("f", &f)], 2);
        let view = testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let mut stack = Vec::new();
        for iso in [-1e3, 1e3, f64::NAN] {
            let tree = ActiveTree::build(&vol, 0, iso, false).expect("a valid tree");
            assert!(tree.walk.root.is_none(), "iso {iso}");
            let mut n = 0;
            tree.segments(
                &vol,
                Start::Root,
                [-50.0; 3],
                [1.0, 1.0, 1.0],
                0.0,
                1e3,
                &mut stack,
                |_, _, _, _| {
                    n += 1;
                    true
                },
            );
            assert_eq!(n, 0);
        }
        let a = vol.active_tree(0, 3.0).expect("field 0");
        assert!(a.walk.root.is_some());
        assert!(std::sync::Arc::ptr_eq(
            &a,
            &vol.active_tree(0, 3.0).expect("field 0")
        ));
        for v in [1.0, 2.0, 4.0, 5.0] {
            vol.active_tree(0, v);
        }
        // Four newer values pushed the first one out: it is built anew.
        assert!(!std::sync::Arc::ptr_eq(
            &a,
            &vol.active_tree(0, 3.0).expect("field 0")
        ));
        assert!(vol.active_tree(1, 3.0).is_none(), "no field 1");
    }

    /// The segments of one ray walked from `start`.
    fn from(vol: &Volume, tree: &ActiveTree, start: Start, o: [f64; 3], d: [f64; 3]) -> Vec<Seg> {
        let mut stack = Vec::new();
        let mut out = Vec::new();
        tree.segments(
            vol,
            start,
            o,
            d,
            0.0,
            f64::INFINITY,
            &mut stack,
            |s, _, _, _| {
                out.push((s.region, s.t0.to_bits(), s.t1.to_bits()));
                true
            },
        );
        out
    }

    /// Every camera ray through a group of pixels (at the group's corners and edges, at
    /// pixel centres and at random sub-pixel offsets) gets from the group's start exactly
    /// the segments it gets from the root: perspective cameras outside, inside and far
    /// from the data, looking along an axis (rays on cell faces and level boundaries) and
    /// obliquely, orthographic ones, images whose last groups are cut, data at 1e6. Groups
    /// that see nothing and groups that start below the root both occur.
    #[test]
    fn a_group_of_camera_rays_gets_the_same_segments_from_its_start_as_from_the_root() {
        use crate::camera::{Camera, Projection};
        use glam::DVec3;
        let mut seed = 11;
        let (mut nothing, mut below_root, mut rays_met) = (0, 0, 0);
        for offset in [[0.0; 3], [1e6, -1e6, 1e6]] {
            let shell = move |p: [f64; 3]| {
                let r2: f64 = (0..3).map(|a| (p[a] - offset[a] - 8.3).powi(2)).sum();
                r2.sqrt()
            };
            let file = testvol::nested(8, offset, &[("r", &shell)], 3);
            let view = testvol::open(&file).expect("opens");
            let vol = Volume::new(&view).expect("volume");
            let frame = DVec3::from_array(vol.frame);
            let at = |p: [f64; 3]| std::array::from_fn(|a| p[a] + offset[a]);
            let persp = |fov_deg| Projection::Perspective { fov_deg };
            let cameras = [
                // Outside, oblique.
                (at([30.0, -20.0, 14.0]), at([8.0, 8.0, 8.0]), persp(30.0)),
                // Inside the data, near the shell.
                (at([8.2, 8.1, 8.4]), at([14.0, 9.0, 7.0]), persp(70.0)),
                // Along the z axis through whole coordinates: rays on cell faces.
                (at([8.0, 8.0, 40.0]), at([8.0, 8.0, 0.0]), persp(20.0)),
                // Far away.
                (at([8e4, 3e4, -5e4]), at([8.0, 8.0, 8.0]), persp(0.02)),
                // Orthographic, along x, one pixel per cell.
                (
                    at([-20.0, 8.0, 8.0]),
                    at([8.0, 8.0, 8.0]),
                    Projection::Orthographic { width: 22.0 },
                ),
                // Orthographic, oblique.
                (
                    at([20.0, 25.0, 30.0]),
                    at([8.0, 8.0, 8.0]),
                    Projection::Orthographic { width: 13.0 },
                ),
            ];
            for iso in [2.5, 4.5] {
                let tree = ActiveTree::build(&vol, 0, iso, false).expect("a valid tree");
                for (eye, look_at, projection) in cameras {
                    let cam = Camera {
                        eye,
                        look_at,
                        up: [0.0, 0.0, 1.0],
                        projection,
                    };
                    let (w, h) = (22u32, 19u32);
                    let rays = cam.ray_generator(w, h);
                    for gy in (0..h).step_by(4) {
                        for gx in (0..w).step_by(4) {
                            let (x1, y1) = ((gx + 4).min(w), (gy + 4).min(h));
                            let (x0, y0) = (f64::from(gx), f64::from(gy));
                            let (x1, y1) = (f64::from(x1), f64::from(y1));
                            let start = tree.start_in(&rays.frustum(x0, y0, x1, y1, frame));
                            match start {
                                Start::Nothing => nothing += 1,
                                Start::At(r) if Some(r) != tree.walk.root => below_root += 1,
                                _ => {}
                            }
                            let mut points = vec![
                                (x0, y0),
                                (x1, y0),
                                (x0, y1),
                                (x1, y1),
                                (0.5 * (x0 + x1), y0),
                                (x0, 0.5 * (y0 + y1)),
                            ];
                            for _ in 0..12 {
                                points.push((
                                    x0 + (x1 - x0) * lcg(&mut seed),
                                    y0 + (y1 - y0) * lcg(&mut seed),
                                ));
                            }
                            for (x, y) in points {
                                let ray = rays.ray(x, y);
                                let o = vol.to_local(ray.origin.to_array());
                                let d = ray.dir.to_array();
                                let want = from(&vol, &tree, Start::Root, o, d);
                                let got = from(&vol, &tree, start, o, d);
                                assert_eq!(
                                    got, want,
                                    "camera {cam:?}, iso {iso}, pixel ({x}, {y}), start {start:?}"
                                );
                                rays_met += usize::from(!want.is_empty());
                            }
                        }
                    }
                }
            }
        }
        assert!(nothing > 50, "only {nothing} groups saw nothing");
        assert!(
            below_root > 50,
            "only {below_root} groups started below the root"
        );
        assert!(rays_met > 1000, "only {rays_met} rays met a region");
    }
}
