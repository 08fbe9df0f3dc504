//! The active tree as a ray walks it ([`ActiveTree::segments`]), and where the walks of a
//! group of camera rays start in it ([`ActiveTree::start_in`]).
//!
//! The walk reads a compact copy of the tree ([`Walk`]): every inner node holds both
//! children's boxes in `f32`, widened outwards, in one 64-byte record, so a ray reads one
//! cache line per level and only descends into children it may meet; a leaf keeps its
//! region's exact `f64` box, and the segment is clipped to that, so the `f32` boxes only
//! ever let through more candidates, never fewer, and the segments stay bit-identical.

use format::kd::{inverse, ray_box, Segment};

use super::nodes::{ActiveNode, LEAF};
use crate::dual_mask::DualMask;
use crate::lattice::Lattice;
use crate::volume::{RegionBox, Volume};

/// The regions whose range of one field holds one value, in the file's tree order.
pub(crate) struct ActiveTree {
    pub(super) field: usize,
    /// The cell lattices of every leaf's region, leaf after leaf: `exact` cuts a segment at
    /// their planes, and listing them once here spares each segment a pass over the
    /// region's bricks.
    pub(super) lattices: Vec<Lattice>,
    /// The dual-cell masks of the leaves' regions of one lattice ([`crate::dual_mask`];
    /// `None` where the region's box is too large for one).
    pub(super) masks: Vec<Option<DualMask>>,
    /// The whole box of every region in the tree (a leaf may be one part of it): a hit
    /// hands it on, so that the shading lookups around the hit know its region without a
    /// descent or a table of every region.
    pub(super) region_boxes: Vec<([f64; 3], [f64; 3])>,
    /// What the ray walk reads (built from the tree of [`ActiveNode`]s).
    pub(super) walk: Walk,
}

/// How `exact` searches one leaf of the walk ([`ActiveTree::segments`]): its region's cell
/// lattices, whether the region has more than are listed, its dual-cell mask, and the
/// region's whole box (`None`: not known), which a hit hands on ([`LeafSearch::hit`]).
#[derive(Clone, Copy)]
pub(crate) struct LeafSearch<'t> {
    pub(crate) lattices: &'t [Lattice],
    pub(crate) inexact: bool,
    pub(crate) mask: Option<&'t DualMask>,
    pub(crate) region_box: Option<&'t ([f64; 3], [f64; 3])>,
}

impl LeafSearch<'_> {
    /// The region of a hit in this leaf's segment of region `region`, with its box.
    pub(crate) fn hit(&self, region: u32) -> RegionBox {
        match self.region_box {
            Some(&(min, max)) => RegionBox { region, min, max },
            None => RegionBox::unknown(region),
        }
    }
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
pub(super) struct WalkLeaf {
    min: [f64; 3],
    max: [f64; 3],
    pub(super) region: u32,
    /// First of its lattices in [`ActiveTree::lattices`], and how many.
    first: u32,
    lattices: u8,
    inexact: bool,
    /// Index in [`ActiveTree::masks`], or `u32::MAX` (none).
    mask: u32,
    /// Index in [`ActiveTree::region_boxes`].
    region_box: u32,
}

/// The active tree as the ray walk reads it.
#[derive(Debug, Default)]
pub(super) struct Walk {
    /// Exact box of everything (the root's), tested in `f64` once per ray.
    min: [f64; 3],
    max: [f64; 3],
    /// Reference of the root (`None`: empty tree).
    pub(super) root: Option<u32>,
    inner: Vec<WalkInner>,
    pub(super) leaves: Vec<WalkLeaf>,
}

impl Walk {
    /// Whether leaf reference `c` holds a region `owned` marks.
    fn leaf_owned(&self, c: u32, owned: &[bool]) -> bool {
        self.leaves
            .get((c & !LEAF_REF) as usize)
            .is_some_and(|l| owned.get(l.region as usize).copied().unwrap_or(false))
    }

    /// The walk over `nodes` (children before parents, root last).
    pub(super) fn of(nodes: &[ActiveNode]) -> Walk {
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
                    region_box: node.region_box,
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

    /// Per inner node of the walk, whether a leaf under it holds a region `owned` marks:
    /// what [`ActiveTree::segments_in`] needs to step over the rest.
    pub(crate) fn owned_nodes(&self, owned: &[bool]) -> Vec<bool> {
        let walk = &self.walk;
        let mut keep = vec![false; walk.inner.len()];
        let Some(root) = walk.root else {
            return keep;
        };
        // Post-order: a node is settled once both children are. Each node is pushed at
        // most twice, so a malformed walk cannot loop.
        let mut stack = vec![(root, false)];
        let mut budget = 2 * walk.inner.len() + 2;
        while let Some((r, children_done)) = stack.pop() {
            if r & LEAF_REF != 0 || budget == 0 {
                continue;
            }
            budget -= 1;
            let Some(node) = walk.inner.get(r as usize) else {
                continue;
            };
            if children_done {
                keep[r as usize] = node.child.iter().any(|&c| {
                    if c & LEAF_REF != 0 {
                        walk.leaf_owned(c, owned)
                    } else {
                        keep.get(c as usize).copied().unwrap_or(false)
                    }
                });
            } else {
                stack.push((r, true));
                stack.extend(node.child.iter().map(|&c| (c, false)));
            }
        }
        keep
    }

    /// Calls `f` for every leaf of the tree the ray `o + t d` (local frame) crosses
    /// within `[t_min, t_max]`, front to back (a whole region, or one part of a region
    /// where its dual cells can hold the value), with the region's range of the field
    /// and how to search it ([`LeafSearch`]); `f` returns `false` to stop. `stack` is
    /// scratch space reused between calls.
    ///
    /// With `owned` (one rank's share: the [`ActiveTree::owned_nodes`] and the regions
    /// they were made from) only the leaves of those regions are listed, and the subtrees
    /// without one are stepped over. A segment's bounds come from its leaf's own box, not
    /// from the path to it, so those of the share are the same as without one.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn segments<F: FnMut(Segment, &LeafSearch) -> bool>(
        &self,
        vol: &Volume,
        start: Start,
        o: [f64; 3],
        d: [f64; 3],
        t_min: f64,
        t_max: f64,
        owned: Option<(&[bool], &[bool])>,
        stack: &mut Vec<(u32, f64, f64)>,
        mut f: F,
    ) {
        let walk = &self.walk;
        let keep = |c: u32| match owned {
            None => true,
            Some((nodes, regions)) => {
                if c & LEAF_REF != 0 {
                    walk.leaf_owned(c, regions)
                } else {
                    nodes.get(c as usize).copied().unwrap_or(false)
                }
            }
        };
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
                let mut hit = meets(node, &o32, &inv32, t_lo, t_hi);
                if owned.is_some() {
                    hit = [hit[0] && keep(node.child[0]), hit[1] && keep(node.child[1])];
                }
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
            if owned.is_some() && !keep(r) {
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
            let search = LeafSearch {
                lattices,
                inexact: leaf.inexact,
                mask: self.masks.get(leaf.mask as usize).and_then(Option::as_ref),
                region_box: self.region_boxes.get(leaf.region_box as usize),
            };
            if !f(seg, &search) {
                return;
            }
        }
    }
}
