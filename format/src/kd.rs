//! The KD-tree over the regions: point location and front-to-back ray traversal.
//!
//! This is the one implementation of the file's structure logic: the baker checks its own
//! tree with [`locate`], the viewer samples along [`segments`], and the tests use both as
//! they are. Everything works on the stored numbers plus a `shift` that is subtracted from
//! every stored coordinate: the viewer works in a local frame centred on the data (so that
//! data placed at 1e6 keeps sub-cell precision) and passes the frame's origin; callers in
//! world coordinates pass `[0.0; 3]`. The edge rules are the same everywhere:
//! - a box is half-open, `[min, max)`: a point on a split plane goes right (`>= split`);
//! - a region's box is its leaf's cell: the file's bounds cut by the splits on the way
//!   down (format 3 stores no region boxes), so a walk's interval in a leaf *is* the
//!   ray's part of the region;
//! - a ray visits the child it meets first as `t` grows; a plane crossed exactly at an
//!   end of the ray's interval in a node sends the whole interval to one child (the other
//!   part would be empty), so the walk works for any `t` range, also negative ones;
//! - a ray parallel to a slab is inside when `min <= o < max`.
//!
//! Nothing here trusts the archive beyond what bytecheck proves: indices are checked, and
//! a descent or walk gives up after as many steps as there are nodes, so a malformed tree
//! (a cycle, a child out of range) yields fewer results, never a panic or an endless loop.
//! [`crate::validate::check`] rejects such files at open anyway.

use crate::schema::{ArchivedBrickFile, ArchivedKdNode, KdNode};

/// Bit of a child reference that makes it a leaf: `LEAF | region` holds a region.
pub const LEAF: u32 = 1 << 31;
/// The child reference of an empty leaf (space no support reaches).
pub const EMPTY: u32 = u32::MAX;
/// Largest region index a leaf reference can hold.
pub const MAX_REGION: u32 = EMPTY - LEAF - 1;

/// The child reference of a leaf holding `region` (`None`: empty space).
#[inline]
pub fn leaf_ref(region: Option<u32>) -> u32 {
    match region {
        Some(r) => LEAF | r,
        None => EMPTY,
    }
}

/// A KD node as the descent sees it, its children as references (which the same tree's
/// [`KdTree::node`] resolves).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Node {
    Inner {
        axis: usize,
        split: f64,
        left: u32,
        right: u32,
    },
    Leaf(Option<u32>),
}

/// A KD-tree: node references resolved to nodes.
pub trait KdTree {
    /// Number of stored nodes (a walk visits at most about twice as many).
    fn node_count(&self) -> usize;
    /// Reference of the root.
    fn root(&self) -> u32;
    fn node(&self, i: u32) -> Option<Node>;
}

/// A borrowed tree walks as the tree (so that a walk may hold the tree or a reference).
impl<T: KdTree + ?Sized> KdTree for &T {
    fn node_count(&self) -> usize {
        (**self).node_count()
    }
    fn root(&self) -> u32 {
        (**self).root()
    }
    #[inline(always)]
    fn node(&self, i: u32) -> Option<Node> {
        (**self).node(i)
    }
}

/// A tree as a file stores it (format 3): a root reference, the inner nodes, their axes.
/// `N` is the native node while baking and the archived one when reading a file.
#[derive(Debug)]
pub struct Stored<'a, N> {
    pub root: u32,
    pub nodes: &'a [N],
    pub axes: &'a [u8],
}

impl<N> Clone for Stored<'_, N> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<N> Copy for Stored<'_, N> {}

/// The archived file's tree.
pub fn file_tree(file: &ArchivedBrickFile) -> Stored<'_, ArchivedKdNode> {
    Stored {
        root: file.kd_root.to_native(),
        nodes: file.kd_nodes.as_slice(),
        axes: file.kd_axes.as_slice(),
    }
}

/// What [`Stored`] reads of a node, native or archived.
pub trait SplitNode {
    fn parts(&self) -> (f64, u32, u32);
}

impl SplitNode for KdNode {
    #[inline]
    fn parts(&self) -> (f64, u32, u32) {
        (self.split, self.left, self.right)
    }
}

impl SplitNode for ArchivedKdNode {
    #[inline]
    fn parts(&self) -> (f64, u32, u32) {
        (
            self.split.to_native(),
            self.left.to_native(),
            self.right.to_native(),
        )
    }
}

/// Resolves a reference of a stored tree: leaves from the reference alone, inner nodes
/// from `nodes` and `axes`.
#[inline]
pub fn resolve<N: SplitNode>(nodes: &[N], axes: &[u8], i: u32) -> Option<Node> {
    if i & LEAF != 0 {
        return Some(Node::Leaf((i != EMPTY).then_some(i & !LEAF)));
    }
    let (split, left, right) = nodes.get(i as usize)?.parts();
    Some(Node::Inner {
        axis: usize::from(*axes.get(i as usize)?),
        split,
        left,
        right,
    })
}

impl<N: SplitNode> KdTree for Stored<'_, N> {
    fn node_count(&self) -> usize {
        self.nodes.len()
    }
    fn root(&self) -> u32 {
        self.root
    }
    #[inline]
    fn node(&self, i: u32) -> Option<Node> {
        resolve(self.nodes, self.axes, i)
    }
}

/// A KD node as a writer builds it: leaves are nodes too, node 0 is the root and every
/// node is stored before its children. [`pack`] turns such a list into the stored form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BuildNode {
    Inner {
        axis: u8,
        split: f64,
        left: u32,
        right: u32,
    },
    Leaf {
        region: Option<u32>,
    },
}

/// The stored form of a tree: root reference, inner nodes and their axes.
pub type Packed = (u32, Vec<KdNode>, Vec<u8>);

/// Stores a built tree (node 0 is the root; an empty list is an empty tree): inner nodes
/// in depth-first, left-first order (parent before children), leaves as references.
/// A node reached a second time, or a child out of range, becomes an empty leaf, so any
/// list packs into a tree.
pub fn pack(built: &[BuildNode]) -> Packed {
    let mut nodes: Vec<KdNode> = Vec::new();
    let mut axes: Vec<u8> = Vec::new();
    let mut seen = vec![false; built.len()];
    // (built node, stored parent and side to patch; `None` for the root)
    let mut todo: Vec<(u32, Option<(usize, bool)>)> = vec![(0, None)];
    let mut root = EMPTY;
    while let Some((b, parent)) = todo.pop() {
        let r = match built.get(b as usize) {
            Some(_) if seen[b as usize] => EMPTY,
            None => EMPTY,
            Some(BuildNode::Leaf { region }) => {
                seen[b as usize] = true;
                leaf_ref(*region)
            }
            Some(BuildNode::Inner {
                axis,
                split,
                left,
                right,
            }) => {
                seen[b as usize] = true;
                let i = nodes.len();
                nodes.push(KdNode {
                    split: *split,
                    left: EMPTY,
                    right: EMPTY,
                });
                axes.push(*axis);
                // Left first: popped first, so it is stored right after its parent.
                todo.push((*right, Some((i, false))));
                todo.push((*left, Some((i, true))));
                i as u32
            }
        };
        match parent {
            None => root = r,
            Some((p, true)) => nodes[p].left = r,
            Some((p, false)) => nodes[p].right = r,
        }
    }
    (root, nodes, axes)
}

/// The leaf's region reached from the root by the point `p` (`p[axis] < split - shift[axis]`
/// goes left); `None` for an empty leaf. The leaf's cell is the region's box only inside
/// the file's bounds: the caller checks that `p` lies in them.
#[inline]
pub fn locate<T: KdTree + ?Sized>(tree: &T, p: [f64; 3], shift: [f64; 3]) -> Option<u32> {
    locate_from(tree, tree.root(), p, shift)
}

/// [`locate`] from the node `n` down.
#[inline]
fn locate_from<T: KdTree + ?Sized>(
    tree: &T,
    mut n: u32,
    p: [f64; 3],
    shift: [f64; 3],
) -> Option<u32> {
    for _ in 0..=tree.node_count() {
        match tree.node(n)? {
            Node::Inner {
                axis,
                split,
                left,
                right,
            } => {
                let a = axis.min(2);
                n = if p[a] < split - shift[a] { left } else { right };
            }
            Node::Leaf(r) => return r,
        }
    }
    None
}

/// [`locate`] with the leaf's cell: the region reached by `p` and the box `min..max`
/// cut by the splits on the way down, every number minus `shift`, as [`LeafCells`] gives
/// it for that leaf. In a tree whose leaves name every region once (what the reader's
/// validation ensures), that is the region's box, found without a table of them.
#[inline]
pub fn locate_cell<T: KdTree + ?Sized>(
    tree: &T,
    p: [f64; 3],
    min: [f64; 3],
    max: [f64; 3],
    shift: [f64; 3],
) -> Option<(u32, [f64; 3], [f64; 3])> {
    let mut lo: [f64; 3] = std::array::from_fn(|a| min[a] - shift[a]);
    let mut hi: [f64; 3] = std::array::from_fn(|a| max[a] - shift[a]);
    let mut n = tree.root();
    for _ in 0..=tree.node_count() {
        match tree.node(n)? {
            Node::Inner {
                axis,
                split,
                left,
                right,
            } => {
                // As `cut_cell` cuts, one side on one axis.
                let a = axis.min(2);
                let s = split - shift[a];
                let cut = s.max(lo[a]).min(hi[a]);
                if p[a] < s {
                    (n, hi[a]) = (left, cut);
                } else {
                    (n, lo[a]) = (right, cut);
                }
            }
            Node::Leaf(r) => return r.map(|r| (r, lo, hi)),
        }
    }
    None
}

/// How many steps of a descent a [`Descent`] keeps.
const DESCENT_STEPS: usize = 64;

/// The way one point went down the tree ([`Descent::of`]). A point near it (a shading
/// normal's neighbour points, a cell away) goes the same way down to the first split
/// that lies between the two, and [`Descent::locate`] starts its descent there instead of
/// at the root: a few comparisons on numbers already read instead of a full descent
/// through memory, with the same result as [`locate`].
#[derive(Debug, Clone)]
pub struct Descent {
    /// Per step: the split minus the shift, the axis, whether the point went left, and
    /// the child it did not take.
    split: [f64; DESCENT_STEPS],
    axis: [u8; DESCENT_STEPS],
    left: [bool; DESCENT_STEPS],
    other: [u32; DESCENT_STEPS],
    len: usize,
    /// Where the point's descent ended ([`locate`] of the point).
    leaf: Option<u32>,
    /// Every step is kept (a deeper descent, or a malformed tree, leaves the others to
    /// [`locate`] from the root).
    whole: bool,
}

impl Descent {
    /// The descent of `p` (as [`locate`] takes it).
    pub fn of<T: KdTree + ?Sized>(tree: &T, p: [f64; 3], shift: [f64; 3]) -> Descent {
        let mut d = Descent {
            split: [0.0; DESCENT_STEPS],
            axis: [0; DESCENT_STEPS],
            left: [false; DESCENT_STEPS],
            other: [0; DESCENT_STEPS],
            len: 0,
            leaf: None,
            whole: false,
        };
        let mut n = tree.root();
        for _ in 0..=tree.node_count() {
            match tree.node(n) {
                Some(Node::Inner {
                    axis,
                    split,
                    left,
                    right,
                }) => {
                    if d.len == DESCENT_STEPS {
                        return d;
                    }
                    let a = axis.min(2);
                    let s = split - shift[a];
                    let go_left = p[a] < s;
                    (d.split[d.len], d.axis[d.len], d.left[d.len]) = (s, a as u8, go_left);
                    (n, d.other[d.len]) = if go_left {
                        (left, right)
                    } else {
                        (right, left)
                    };
                    d.len += 1;
                }
                Some(Node::Leaf(r)) => {
                    d.leaf = r;
                    d.whole = true;
                    return d;
                }
                None => return d,
            }
        }
        d
    }

    /// [`locate`] of `q` in the tree this descent was taken in.
    #[inline]
    pub fn locate<T: KdTree + ?Sized>(
        &self,
        tree: &T,
        q: [f64; 3],
        shift: [f64; 3],
    ) -> Option<u32> {
        if !self.whole {
            return locate(tree, q, shift);
        }
        for i in 0..self.len {
            let go_left = q[usize::from(self.axis[i])] < self.split[i];
            if go_left != self.left[i] {
                return locate_from(tree, self.other[i], q, shift);
            }
        }
        self.leaf
    }
}

/// Calls `f(region, min, max)` for every leaf holding a region, with its cell (the box
/// `min..max` cut by the splits on the way down, each clamped to its node's cell, every
/// number minus `shift`), in
/// depth-first, left-first order. A malformed tree yields fewer leaves (the walk stops
/// after as many steps as a tree of that many nodes takes).
pub fn leaf_cells<T: KdTree + ?Sized, F: FnMut(u32, [f64; 3], [f64; 3])>(
    tree: &T,
    min: [f64; 3],
    max: [f64; 3],
    shift: [f64; 3],
    mut f: F,
) {
    for (r, lo, hi) in LeafCells::new(tree, min, max, shift) {
        f(r, lo, hi);
    }
}

/// [`leaf_cells`] as an iterator of `(region, min, max)`, for a reader that takes the
/// cells a batch at a time instead of holding one per region. It holds `tree` (a tree or
/// a reference to one).
#[derive(Clone)]
pub struct LeafCells<T: KdTree> {
    tree: T,
    shift: [f64; 3],
    budget: usize,
    stack: Vec<(u32, [f64; 3], [f64; 3])>,
}

impl<T: KdTree> LeafCells<T> {
    pub fn new(tree: T, min: [f64; 3], max: [f64; 3], shift: [f64; 3]) -> Self {
        let lo: [f64; 3] = std::array::from_fn(|a| min[a] - shift[a]);
        let hi: [f64; 3] = std::array::from_fn(|a| max[a] - shift[a]);
        LeafCells {
            shift,
            budget: tree.node_count().saturating_mul(2).saturating_add(1),
            stack: vec![(tree.root(), lo, hi)],
            tree,
        }
    }
}

impl<T: KdTree + Copy> LeafCells<T> {
    /// The walk of [`LeafCells::new`] cut into the walks of the subtrees `depth` levels
    /// below the root (fewer where a leaf comes first), in the whole walk's order: walked
    /// one after the other they give the whole walk's leaves, in its order. So the leaves
    /// can be walked on several threads; each part is bounded as a whole walk is.
    pub fn split(tree: T, min: [f64; 3], max: [f64; 3], shift: [f64; 3], depth: u32) -> Vec<Self> {
        let whole = LeafCells::new(tree, min, max, shift);
        let mut frontier = Vec::new();
        let mut stack: Vec<(u32, [f64; 3], [f64; 3], u32)> = whole
            .stack
            .iter()
            .map(|&(n, lo, hi)| (n, lo, hi, 0))
            .collect();
        // Each expansion adds one node: a malformed tree cannot make this loop long.
        let mut budget = 1usize << depth.min(20);
        while let Some((n, lo, hi, d)) = stack.pop() {
            let inner = match tree.node(n) {
                Some(Node::Inner {
                    axis,
                    split,
                    left,
                    right,
                }) if d < depth && budget > 0 => Some((axis, split, left, right)),
                _ => None,
            };
            let Some((axis, split, left, right)) = inner else {
                frontier.push((n, lo, hi));
                continue;
            };
            budget -= 1;
            let (lhi, rlo) = cut_cell(axis, split, shift, lo, hi);
            stack.push((right, rlo, hi, d + 1));
            stack.push((left, lo, lhi, d + 1));
        }
        frontier
            .into_iter()
            .map(|(n, lo, hi)| LeafCells {
                shift,
                budget: whole.budget,
                stack: vec![(n, lo, hi)],
                tree,
            })
            .collect()
    }
}

impl<T: KdTree> Iterator for LeafCells<T> {
    type Item = (u32, [f64; 3], [f64; 3]);

    fn next(&mut self) -> Option<Self::Item> {
        while let Some((n, lo, hi)) = self.stack.pop() {
            if self.budget == 0 {
                self.stack.clear();
                return None;
            }
            self.budget -= 1;
            match self.tree.node(n) {
                Some(Node::Inner {
                    axis,
                    split,
                    left,
                    right,
                }) => {
                    let (lhi, rlo) = cut_cell(axis, split, self.shift, lo, hi);
                    self.stack.push((right, rlo, hi));
                    self.stack.push((left, lo, lhi));
                }
                Some(Node::Leaf(Some(r))) => return Some((r, lo, hi)),
                _ => {}
            }
        }
        None
    }
}

/// The cell `lo..hi` cut by an inner node's split: the left child's upper corner and the
/// right child's lower corner. Clamped to the cell: a split outside it leaves one child
/// empty, as the descent and the ray walk see it, and no box reaches past its parent's.
#[inline]
pub fn cut_cell(
    axis: usize,
    split: f64,
    shift: [f64; 3],
    lo: [f64; 3],
    hi: [f64; 3],
) -> ([f64; 3], [f64; 3]) {
    let a = axis.min(2);
    let s = (split - shift[a]).max(lo[a]).min(hi[a]);
    let (mut lhi, mut rlo) = (hi, lo);
    lhi[a] = s;
    rlo[a] = s;
    (lhi, rlo)
}

/// `1/d` per axis, infinite for a zero component.
#[inline]
pub fn inverse(d: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|a| {
        if d[a] == 0.0 {
            f64::INFINITY
        } else {
            1.0 / d[a]
        }
    })
}

/// Entry and exit of the ray `o + t d` (`inv = inverse(d)`) through the half-open box
/// `min..max`, clipped to `[t_min, t_max]`; `None` when that part is empty. A ray
/// parallel to a slab is inside it when `min <= o < max`.
#[inline]
pub fn ray_box(
    min: &[f64; 3],
    max: &[f64; 3],
    o: &[f64; 3],
    inv: &[f64; 3],
    t_min: f64,
    t_max: f64,
) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (t_min, t_max);
    for a in 0..3 {
        if inv[a].is_infinite() {
            if o[a] < min[a] || o[a] >= max[a] {
                return None;
            }
            continue;
        }
        let ta = (min[a] - o[a]) * inv[a];
        let tb = (max[a] - o[a]) * inv[a];
        let (lo, hi) = if ta <= tb { (ta, tb) } else { (tb, ta) };
        t0 = t0.max(lo);
        t1 = t1.min(hi);
    }
    (t0 < t1).then_some((t0, t1))
}

/// The part of a ray inside one region, or inside a skipped subtree.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// The region, or [`SKIPPED`] for a whole KD subtree skipped by its value range.
    pub region: u32,
    pub t0: f64,
    pub t1: f64,
    /// Value range of the traversal's field over the region / subtree.
    pub min: f32,
    pub max: f32,
}

/// [`Segment::region`] of a skipped subtree.
pub const SKIPPED: u32 = u32::MAX;

/// Which subtrees [`segments`] may skip whole.
#[derive(Debug, Clone, Copy)]
pub struct Skip<K: Fn(f32, f32) -> bool> {
    /// Field whose ranges are tested.
    pub field: usize,
    /// Keep (descend into) a subtree whose range is `[min, max]`.
    pub keep: K,
    /// Skip subtrees that contain empty space too (callers that need to notice gaps in
    /// the data pass `false`).
    pub across_gaps: bool,
}

/// Skip nothing: every region is visited.
pub fn keep_all() -> Skip<fn(f32, f32) -> bool> {
    Skip {
        field: 0,
        keep: |_, _| true,
        across_gaps: false,
    }
}

/// A node with the walk's field's range over its subtree (`None`: no range, skip
/// nothing) and whether it is full.
pub type NodeEntry = (Node, Option<(f32, f32)>, bool);

/// What the ray walk reads per node: the node, and the walk's field's range and fullness
/// over its subtree. The file's own tables ([`FileNodes`]) are one store; a reader may
/// pack them per field for speed (the viewer does: node and subtree range in one cache
/// line) and walk the same way with [`segments`].
pub trait WalkNodes {
    fn node_count(&self) -> usize;
    fn root(&self) -> u32;
    fn node(&self, n: u32) -> Option<Node>;
    /// Range of the walk's field over node `n`'s subtree; `None` when the store has no
    /// range for it (nothing is skipped there).
    fn range(&self, n: u32) -> Option<(f32, f32)>;
    /// Every leaf below `n` holds a region.
    fn full(&self, n: u32) -> bool;
    /// All three at once (a store that keeps them together answers with one read).
    #[inline]
    fn get(&self, n: u32) -> Option<NodeEntry> {
        Some((self.node(n)?, self.range(n), self.full(n)))
    }
}

/// The archived tree with field `field`'s region ranges at its leaves. The file stores no
/// ranges of inner nodes (format 3), so walking it skips no subtree; the viewer derives
/// them once per field ([`subtree_ranges`]).
#[derive(Clone, Copy)]
pub struct FileNodes<'a> {
    file: &'a ArchivedBrickFile,
    tree: Stored<'a, ArchivedKdNode>,
    field: usize,
    fields: usize,
}

impl<'a> FileNodes<'a> {
    pub fn new(file: &'a ArchivedBrickFile, field: usize) -> Self {
        Self {
            file,
            tree: file_tree(file),
            field,
            fields: file.fields.len(),
        }
    }
}

impl WalkNodes for FileNodes<'_> {
    fn node_count(&self) -> usize {
        self.tree.nodes.len()
    }
    fn root(&self) -> u32 {
        self.tree.root
    }
    #[inline]
    fn node(&self, n: u32) -> Option<Node> {
        self.tree.node(n)
    }
    #[inline]
    fn range(&self, n: u32) -> Option<(f32, f32)> {
        if n & LEAF == 0 || n == EMPTY || self.field >= self.fields {
            return None;
        }
        let r = self
            .file
            .region_ranges
            .get((n & !LEAF) as usize * self.fields + self.field)?;
        Some((r.min.to_native(), r.max.to_native()))
    }
    #[inline]
    fn full(&self, n: u32) -> bool {
        n & LEAF != 0 && n != EMPTY
    }
}

/// Per node of `tree` reached from its root, in depth-first, left-first order (parents
/// before children, the root first): the node with its children as positions in this
/// list, the range of one field over its subtree (`range(region)` gives a region's) and
/// whether every leaf below holds a region. Empty leaves get the empty range (`+∞..−∞`).
/// What a reader that skips by subtree ranges builds once per field (the file stores no
/// per-node ranges); the list is itself a [`WalkNodes`] store (the viewer walks it).
pub fn subtree_ranges<T: KdTree + ?Sized>(
    tree: &T,
    range: impl Fn(u32) -> Option<(f32, f32)>,
) -> Vec<RangedNode> {
    let mut out: Vec<RangedNode> = Vec::with_capacity(tree.node_count() * 2 + 1);
    let mut budget = tree.node_count().saturating_mul(2).saturating_add(1);
    // (reference, parent position and side)
    let mut todo: Vec<(u32, Option<(usize, bool)>)> = vec![(tree.root(), None)];
    while let Some((n, parent)) = todo.pop() {
        if budget == 0 {
            break;
        }
        budget -= 1;
        let i = out.len();
        let (entry, children) = ranged_entry(tree.node(n), &range);
        out.push(entry);
        if let Some((left, right)) = children {
            todo.push((right, Some((i, false))));
            todo.push((left, Some((i, true))));
        }
        if let Some((p, left)) = parent {
            if left {
                out[p].a = i as u32;
            } else {
                out[p].b = i as u32;
            }
        }
    }
    fold_ranges(&mut out, 0);
    out
}

/// The list entry of a node (an inner node's children not yet placed) and the children
/// to list after it.
fn ranged_entry(
    node: Option<Node>,
    range: &(impl Fn(u32) -> Option<(f32, f32)> + ?Sized),
) -> (RangedNode, Option<(u32, u32)>) {
    let empty = (f32::INFINITY, f32::NEG_INFINITY);
    match node.unwrap_or(Node::Leaf(None)) {
        Node::Inner {
            axis,
            split,
            left,
            right,
        } => (RangedNode::inner(axis, split, empty), Some((left, right))),
        Node::Leaf(Some(r)) => (RangedNode::leaf(Some(r), range(r).unwrap_or(empty)), None),
        Node::Leaf(None) => (RangedNode::leaf(None, empty), None),
    }
}

/// Sets every inner node's range and fullness from its children's, back to front
/// (children come after parents); `list` starts at position `base` of the whole list, and
/// a child outside it counts as missing (not full).
fn fold_ranges(list: &mut [RangedNode], base: usize) {
    for i in (0..list.len()).rev() {
        if list[i].axis == RangedNode::LEAF {
            continue;
        }
        let (mut full, mut lo, mut hi) = (true, f32::INFINITY, f32::NEG_INFINITY);
        for c in [list[i].a, list[i].b] {
            match (c as usize).checked_sub(base).and_then(|c| list.get(c)) {
                Some(child) => {
                    full &= child.full;
                    lo = lo.min(child.min);
                    hi = hi.max(child.max);
                }
                None => full = false,
            }
        }
        list[i].full = full;
        list[i].min = lo;
        list[i].max = hi;
    }
}

/// [`subtree_ranges`] on `threads` threads, the same list: the subtrees a few levels
/// below the root are counted, then filled, each into its own stretch of the list, and
/// the nodes above them last. A billion cells make tens of millions of nodes, a second
/// of the first frame on one core. Plain scoped threads (a caller may be a rayon task
/// initialising something other tasks wait for).
pub fn subtree_ranges_on<T: KdTree + Sync + ?Sized>(
    tree: &T,
    range: impl Fn(u32) -> Option<(f32, f32)> + Sync,
    threads: usize,
) -> Vec<RangedNode> {
    let budget = tree.node_count().saturating_mul(2).saturating_add(1);
    if threads <= 1 {
        return subtree_ranges(tree, range);
    }
    // The nodes above the cut in list order, each an inner node (with the entries of its
    // children) or a subtree below the cut.
    enum Top {
        Inner(usize, f64, [usize; 2]),
        Below(u32),
    }
    let depth = (threads * 8).next_power_of_two().trailing_zeros();
    let mut top: Vec<Top> = Vec::new();
    // (reference, depth, parent entry and side)
    let mut todo = vec![(tree.root(), 0u32, None::<(usize, usize)>)];
    while let Some((n, d, parent)) = todo.pop() {
        let k = top.len();
        if let Some((p, side)) = parent {
            if let Some(Top::Inner(_, _, c)) = top.get_mut(p) {
                c[side] = k;
            }
        }
        match tree.node(n) {
            Some(Node::Inner {
                axis,
                split,
                left,
                right,
            }) if d < depth => {
                top.push(Top::Inner(axis, split, [usize::MAX; 2]));
                todo.push((right, d + 1, Some((k, 1))));
                todo.push((left, d + 1, Some((k, 0))));
            }
            _ => top.push(Top::Below(n)),
        }
    }
    let below: Vec<u32> = top
        .iter()
        .filter_map(|t| match t {
            Top::Below(n) => Some(*n),
            Top::Inner(..) => None,
        })
        .collect();
    // How many nodes each subtree below the cut lists (`None`: past the budget).
    let counts = on_threads(
        below.iter().map(|&n| move || count_nodes(tree, n, budget)),
        threads,
    );
    let mut total = top.len() - below.len();
    let mut sizes = Vec::with_capacity(counts.len());
    for c in counts {
        match c {
            Some(c) if total.saturating_add(c) <= budget => {
                total += c;
                sizes.push(c);
            }
            // A malformed tree: the one walk stops where it stops.
            _ => return subtree_ranges(tree, range),
        }
    }
    let empty = (f32::INFINITY, f32::NEG_INFINITY);
    let mut out = vec![RangedNode::leaf(None, empty); total];
    // Where each entry starts in the list; each subtree below the cut gets its stretch.
    let mut at = Vec::with_capacity(top.len());
    {
        let mut work = Vec::with_capacity(below.len());
        let mut rest: &mut [RangedNode] = &mut out;
        let mut sizes = sizes.iter();
        for t in &top {
            let base = at.last().map_or(0, |&(p, len)| p + len);
            let len = match t {
                Top::Inner(..) => 1,
                Top::Below(_) => sizes.next().copied().unwrap_or(0),
            };
            at.push((base, len));
            let (here, after) = std::mem::take(&mut rest).split_at_mut(len);
            rest = after;
            if let Top::Below(n) = t {
                work.push((*n, base, here));
            }
        }
        let range = &range;
        on_threads(
            work.into_iter()
                .map(|(n, base, stretch)| move || fill_nodes(tree, n, range, stretch, base)),
            threads,
        );
    }
    // The nodes above the cut, children first.
    for k in (0..top.len()).rev() {
        let Top::Inner(axis, split, children) = top[k] else {
            continue;
        };
        let mut node = RangedNode::inner(axis, split, empty);
        let (mut full, mut lo, mut hi) = (true, empty.0, empty.1);
        for (side, &c) in children.iter().enumerate() {
            let pos = at.get(c).map_or(u32::MAX, |&(p, _)| p as u32);
            if side == 0 {
                node.a = pos;
            } else {
                node.b = pos;
            }
            match out.get(pos as usize) {
                Some(child) => {
                    full &= child.full;
                    lo = lo.min(child.min);
                    hi = hi.max(child.max);
                }
                None => full = false,
            }
        }
        (node.full, node.min, node.max) = (full, lo, hi);
        out[at[k].0] = node;
    }
    out
}

/// Runs each job on one of `threads` scoped threads, taking them in order; their results
/// in the jobs' order. For work split by subtree (here and in the viewer's region
/// table) inside initialisers that rayon tasks may wait on, where a rayon pool could
/// hand the waiting worker the very task it waits for.
pub fn on_threads<R: Send, J: FnOnce() -> R + Send>(
    jobs: impl Iterator<Item = J>,
    threads: usize,
) -> Vec<R> {
    let queue: Vec<(usize, J)> = jobs.enumerate().collect();
    let n = queue.len();
    let queue = std::sync::Mutex::new(queue.into_iter());
    let results = std::sync::Mutex::new(Vec::with_capacity(n));
    std::thread::scope(|scope| {
        for _ in 0..threads.min(n) {
            scope.spawn(|| loop {
                let job = queue.lock().ok().and_then(|mut q| q.next());
                let Some((i, job)) = job else {
                    return;
                };
                let r = job();
                if let Ok(mut g) = results.lock() {
                    g.push((i, r));
                }
            });
        }
    });
    let mut results = results.into_inner().unwrap_or_default();
    results.sort_by_key(|(i, _)| *i);
    results.into_iter().map(|(_, r)| r).collect()
}

/// How many nodes [`subtree_ranges`] lists for the subtree of `root`; `None` past `budget`.
fn count_nodes<T: KdTree + ?Sized>(tree: &T, root: u32, budget: usize) -> Option<usize> {
    let mut todo = vec![root];
    let mut count = 0usize;
    while let Some(n) = todo.pop() {
        if count >= budget {
            return None;
        }
        count += 1;
        if let Some(Node::Inner { left, right, .. }) = tree.node(n) {
            todo.push(right);
            todo.push(left);
        }
    }
    Some(count)
}

/// [`subtree_ranges`] of the subtree of `root` into `out` (exactly as long as its list:
/// [`count_nodes`]), which starts at position `base` of the whole list.
fn fill_nodes<T: KdTree + ?Sized>(
    tree: &T,
    root: u32,
    range: &(impl Fn(u32) -> Option<(f32, f32)> + ?Sized),
    out: &mut [RangedNode],
    base: usize,
) {
    let mut todo: Vec<(u32, Option<(usize, bool)>)> = vec![(root, None)];
    let mut i = 0;
    while let Some((n, parent)) = todo.pop() {
        if i >= out.len() {
            break;
        }
        let (entry, children) = ranged_entry(tree.node(n), range);
        out[i] = entry;
        if let Some((left, right)) = children {
            todo.push((right, Some((i, false))));
            todo.push((left, Some((i, true))));
        }
        if let Some((p, left)) = parent {
            if left {
                out[p].a = (base + i) as u32;
            } else {
                out[p].b = (base + i) as u32;
            }
        }
        i += 1;
    }
    fold_ranges(out, base);
}

/// A node of [`subtree_ranges`] with its subtree's range of one field (32 bytes: half a
/// cache line, so a walk reads node and range with one load).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangedNode {
    /// Split plane as stored (inner nodes).
    pub split: f64,
    /// Inner: position of the left child; leaf: the region, or `u32::MAX` for empty space.
    pub a: u32,
    /// Inner: position of the right child.
    pub b: u32,
    /// Range of the field over the subtree.
    pub min: f32,
    pub max: f32,
    /// 0..=2: inner node splitting this axis; [`RangedNode::LEAF`]: a leaf.
    pub axis: u8,
    /// Every leaf below holds a region.
    pub full: bool,
}

impl RangedNode {
    /// [`RangedNode::axis`] of a leaf.
    pub const LEAF: u8 = 3;

    fn inner(axis: usize, split: f64, (min, max): (f32, f32)) -> Self {
        RangedNode {
            split,
            a: u32::MAX,
            b: u32::MAX,
            min,
            max,
            axis: axis.min(2) as u8,
            full: true,
        }
    }

    fn leaf(region: Option<u32>, (min, max): (f32, f32)) -> Self {
        RangedNode {
            split: 0.0,
            a: region.unwrap_or(u32::MAX),
            b: 0,
            min,
            max,
            axis: Self::LEAF,
            full: region.is_some(),
        }
    }

    /// The node, its children as positions in its list.
    #[inline(always)]
    pub fn node(&self) -> Node {
        if self.axis < Self::LEAF {
            Node::Inner {
                axis: usize::from(self.axis),
                split: self.split,
                left: self.a,
                right: self.b,
            }
        } else {
            Node::Leaf((self.a != u32::MAX).then_some(self.a))
        }
    }
}

/// Calls `f` for every region the ray `o + t d` crosses within `[t_min, t_max]`, front to
/// back, with the ray's part of the region (its leaf's cell); a subtree whose range (from `nodes`,
/// the field of `skip.field`) `skip.keep` rejects (and which is full, unless
/// `skip.across_gaps`) is reported as one [`SKIPPED`] segment over the ray's part of its
/// cell. `o`, `d` and the result are in the frame shifted by `shift`. `f` returns `false`
/// to stop. `stack` is reused between calls so that the walk does not allocate.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn segments<N: WalkNodes, K: Fn(f32, f32) -> bool, F: FnMut(Segment) -> bool>(
    file: &ArchivedBrickFile,
    nodes: &N,
    shift: [f64; 3],
    o: [f64; 3],
    d: [f64; 3],
    t_min: f64,
    t_max: f64,
    stack: &mut Vec<(u32, f64, f64)>,
    skip: &Skip<K>,
    mut f: F,
) {
    if t_min >= t_max || t_min.is_nan() || t_max.is_nan() {
        return;
    }
    let all = (f32::NEG_INFINITY, f32::INFINITY);
    let inv = inverse(&d);
    let b = &file.bounds;
    let bmin: [f64; 3] = std::array::from_fn(|a| b.min[a].to_native() - shift[a]);
    let bmax: [f64; 3] = std::array::from_fn(|a| b.max[a].to_native() - shift[a]);
    let Some((t0, t1)) = ray_box(&bmin, &bmax, &o, &inv, t_min, t_max) else {
        return;
    };
    // Each node is entered at most once per ray in a tree: the budget stops the walk on
    // a malformed one.
    let mut budget = nodes.node_count().saturating_mul(2).saturating_add(1);
    stack.clear();
    stack.push((nodes.root(), t0, t1));
    while let Some((mut node, ta, mut tb)) = stack.pop() {
        loop {
            if budget == 0 {
                return;
            }
            budget -= 1;
            let Some((n, range, full)) = nodes.get(node) else {
                break;
            };
            match n {
                Node::Inner {
                    axis,
                    split,
                    left,
                    right,
                } => {
                    if skip.across_gaps || full {
                        if let Some((mn, mx)) = range {
                            if !(skip.keep)(mn, mx) {
                                if ta < tb
                                    && !f(Segment {
                                        region: SKIPPED,
                                        t0: ta,
                                        t1: tb,
                                        min: mn,
                                        max: mx,
                                    })
                                {
                                    return;
                                }
                                break;
                            }
                        }
                    }
                    let a = axis.min(2);
                    let split = split - shift[a];
                    if inv[a].is_infinite() {
                        // Parallel to the plane: on one side for the whole interval.
                        node = if o[a] < split { left } else { right };
                        continue;
                    }
                    // The child the ray meets first as t grows, and the other one.
                    let (first, second) = if d[a] > 0.0 {
                        (left, right)
                    } else {
                        (right, left)
                    };
                    let ts = (split - o[a]) * inv[a];
                    if ts >= tb {
                        node = first;
                    } else if ts <= ta {
                        node = second;
                    } else {
                        stack.push((second, ts, tb));
                        node = first;
                        tb = ts;
                    }
                }
                Node::Leaf(Some(r)) => {
                    // The interval is the ray's part of the leaf's cell, which is the
                    // region's box: the same numbers a slab test against that box gives.
                    if ta < tb {
                        let (mn, mx) = range.unwrap_or(all);
                        if !f(Segment {
                            region: r,
                            t0: ta,
                            t1: tb,
                            min: mn,
                            max: mx,
                        }) {
                            return;
                        }
                    }
                    break;
                }
                Node::Leaf(None) => break,
            }
        }
    }
}
