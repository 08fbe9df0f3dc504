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
    let lo: [f64; 3] = std::array::from_fn(|a| min[a] - shift[a]);
    let hi: [f64; 3] = std::array::from_fn(|a| max[a] - shift[a]);
    locate_cell_from(tree, tree.root(), p, lo, hi, shift)
}

/// [`locate_cell`] from the node `n` down, whose cell is `lo..hi` (already shifted).
#[inline]
fn locate_cell_from<T: KdTree + ?Sized>(
    tree: &T,
    mut n: u32,
    p: [f64; 3],
    mut lo: [f64; 3],
    mut hi: [f64; 3],
    shift: [f64; 3],
) -> Option<(u32, [f64; 3], [f64; 3])> {
    for _ in 0..=tree.node_count() {
        match tree.node(n)? {
            Node::Inner {
                axis,
                split,
                left,
                right,
            } => {
                let a = axis.min(2);
                let s = split - shift[a];
                let go_left = p[a] < s;
                keep_side(&mut lo, &mut hi, a, s, go_left);
                n = if go_left { left } else { right };
            }
            Node::Leaf(r) => return r.map(|r| (r, lo, hi)),
        }
    }
    None
}

/// The cell `lo..hi` cut by the (shifted) split `s` on axis `a`, keeping the left side
/// or the right: one side of [`cut_cell`], clamped to the cell as it clamps.
#[inline(always)]
fn keep_side(lo: &mut [f64; 3], hi: &mut [f64; 3], a: usize, s: f64, left: bool) {
    let cut = s.max(lo[a]).min(hi[a]);
    if left {
        hi[a] = cut;
    } else {
        lo[a] = cut;
    }
}

/// How many steps of a descent a [`Descent`] keeps.
const DESCENT_STEPS: usize = 64;

/// The way one point went down the tree ([`Descent::of`]). A point near it (a shading
/// normal's neighbour points, a cell away) goes the same way down to the first split
/// that lies between the two, and [`Descent::locate_cell`] starts its descent there
/// instead of at the root: a few comparisons on numbers already read instead of a full
/// descent through memory, with the same result as [`locate_cell`].
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

    /// [`locate_cell`] of `q` in the tree this descent was taken in (`min..max` the
    /// file's bounds, as [`locate_cell`] takes them): the region and its box, for a caller
    /// that keeps the boxes of the regions it found to test the next points against.
    pub fn locate_cell<T: KdTree + ?Sized>(
        &self,
        tree: &T,
        q: [f64; 3],
        min: [f64; 3],
        max: [f64; 3],
        shift: [f64; 3],
    ) -> Option<(u32, [f64; 3], [f64; 3])> {
        if !self.whole {
            return locate_cell(tree, q, min, max, shift);
        }
        let mut lo: [f64; 3] = std::array::from_fn(|a| min[a] - shift[a]);
        let mut hi: [f64; 3] = std::array::from_fn(|a| max[a] - shift[a]);
        for i in 0..self.len {
            let a = usize::from(self.axis[i]);
            let s = self.split[i];
            let go_left = q[a] < s;
            keep_side(&mut lo, &mut hi, a, s, go_left);
            if go_left != self.left[i] {
                return locate_cell_from(tree, self.other[i], q, lo, hi, shift);
            }
        }
        self.leaf.map(|r| (r, lo, hi))
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

/// A tree's inner nodes, parent first (depth-first, left first), each with one field's
/// range over its subtree and whether every leaf below holds a region; a child is a
/// position in `inner` or a leaf reference as the file stores it ([`LEAF`] | region, or
/// [`EMPTY`]), and a leaf's range is its region's, one entry a region in `leaves`. What a
/// reader that skips by subtree ranges builds once per field (the file stores no per-node
/// ranges): 32 bytes an inner node and 8 a region, about 40 bytes a region in all, where
/// listing the leaves as nodes too took 64. The tree walks as a [`KdTree`] and a
/// [`WalkNodes`] store with the same nodes, ranges and fullness as the tree it was made
/// from.
#[derive(Debug, Clone, Default)]
pub struct RangedTree {
    /// Reference of the root: 0 when it is an inner node, else a leaf reference.
    pub root: u32,
    pub inner: Vec<RangedNode>,
    /// Per region, the field's range over it (`+∞..−∞` where the caller had none).
    pub leaves: Vec<(f32, f32)>,
}

/// The empty range: what a subtree without a region, or a region without a range, has.
const NO_RANGE: (f32, f32) = (f32::INFINITY, f32::NEG_INFINITY);

/// The reference a leaf `node` becomes in a [`RangedTree`] ([`leaf_ref`]; empty space
/// for a region number past [`MAX_REGION`]); `None` for an inner node.
#[inline]
fn ranged_leaf(node: Option<Node>) -> Option<u32> {
    match node.unwrap_or(Node::Leaf(None)) {
        Node::Inner { .. } => None,
        Node::Leaf(r) => Some(leaf_ref(r.filter(|&r| r <= MAX_REGION))),
    }
}

impl RangedTree {
    /// The range and fullness of the child reference `c`, the list starting at position
    /// `base` of the whole list (a child outside it counts as missing: not full).
    #[inline]
    fn child(&self, list: &[RangedNode], base: usize, c: u32) -> (bool, (f32, f32)) {
        if c & LEAF != 0 {
            if c == EMPTY {
                return (false, NO_RANGE);
            }
            return (true, self.leaf_range(c & !LEAF));
        }
        match (c as usize).checked_sub(base).and_then(|c| list.get(c)) {
            Some(n) => (n.full, (n.min, n.max)),
            None => (false, NO_RANGE),
        }
    }

    #[inline]
    fn leaf_range(&self, r: u32) -> (f32, f32) {
        self.leaves.get(r as usize).copied().unwrap_or(NO_RANGE)
    }
}

impl KdTree for RangedTree {
    fn node_count(&self) -> usize {
        self.inner.len()
    }
    fn root(&self) -> u32 {
        self.root
    }
    #[inline(always)]
    fn node(&self, n: u32) -> Option<Node> {
        WalkNodes::node(self, n)
    }
}

impl WalkNodes for RangedTree {
    fn node_count(&self) -> usize {
        self.inner.len()
    }
    fn root(&self) -> u32 {
        self.root
    }
    #[inline(always)]
    fn node(&self, n: u32) -> Option<Node> {
        if n & LEAF != 0 {
            return Some(Node::Leaf((n != EMPTY).then_some(n & !LEAF)));
        }
        self.inner.get(n as usize).map(RangedNode::node)
    }
    #[inline(always)]
    fn range(&self, n: u32) -> Option<(f32, f32)> {
        if n & LEAF != 0 {
            return Some(if n == EMPTY {
                NO_RANGE
            } else {
                self.leaf_range(n & !LEAF)
            });
        }
        self.inner.get(n as usize).map(|p| (p.min, p.max))
    }
    #[inline(always)]
    fn full(&self, n: u32) -> bool {
        if n & LEAF != 0 {
            return n != EMPTY;
        }
        self.inner.get(n as usize).is_some_and(|p| p.full)
    }
    #[inline(always)]
    fn get(&self, n: u32) -> Option<NodeEntry> {
        if n & LEAF == 0 {
            let p = self.inner.get(n as usize)?;
            return Some((p.node(), Some((p.min, p.max)), p.full));
        }
        if n == EMPTY {
            return Some((Node::Leaf(None), Some(NO_RANGE), false));
        }
        let r = n & !LEAF;
        Some((Node::Leaf(Some(r)), Some(self.leaf_range(r)), true))
    }
}

/// The [`RangedTree`] of `tree` (its nodes reached from the root) with the ranges of its
/// `regions` regions (`range(region)`; `None`: no range, taken as empty). Empty leaves
/// get the empty range (`+∞..−∞`) and make their ancestors not full.
pub fn subtree_ranges<T: KdTree + ?Sized>(
    tree: &T,
    regions: usize,
    range: impl Fn(u32) -> Option<(f32, f32)>,
) -> RangedTree {
    let leaves = (0..regions)
        .map(|r| range(r as u32).unwrap_or(NO_RANGE))
        .collect();
    let mut out = RangedTree {
        root: EMPTY,
        inner: Vec::new(),
        leaves,
    };
    let budget = tree.node_count().saturating_mul(2).saturating_add(1);
    let mut inner = Vec::with_capacity(tree.node_count().min(budget));
    out.root = list_inner(tree, tree.root(), &mut inner, 0, budget);
    fold_ranges(&out, &mut inner, 0);
    out.inner = inner;
    out
}

/// Lists the inner nodes of the subtree of `root` into `out` (children as positions of
/// the whole list, of which `out` starts at `base`, or leaf references), within `budget`
/// nodes reached; the reference the subtree's root becomes.
fn list_inner<T: KdTree + ?Sized>(
    tree: &T,
    root: u32,
    out: &mut Vec<RangedNode>,
    base: usize,
    budget: usize,
) -> u32 {
    let mut budget = budget;
    let mut root_ref = EMPTY;
    // (reference, parent position in `out` and side)
    let mut todo: Vec<(u32, Option<(usize, bool)>)> = vec![(root, None)];
    while let Some((n, parent)) = todo.pop() {
        if budget == 0 {
            break;
        }
        budget -= 1;
        let node = tree.node(n);
        let r = match ranged_leaf(node) {
            Some(leaf) => leaf,
            None => {
                let i = out.len();
                if let Some(Node::Inner {
                    axis,
                    split,
                    left,
                    right,
                }) = node
                {
                    out.push(RangedNode::inner(axis, split, NO_RANGE));
                    todo.push((right, Some((i, false))));
                    todo.push((left, Some((i, true))));
                }
                (base + i) as u32
            }
        };
        match parent {
            None => root_ref = r,
            Some((p, true)) => out[p].a = r,
            Some((p, false)) => out[p].b = r,
        }
    }
    root_ref
}

/// Sets every inner node's range and fullness from its children's, back to front
/// (children come after parents); `list` starts at position `base` of the whole list.
fn fold_ranges(tree: &RangedTree, list: &mut [RangedNode], base: usize) {
    for i in (0..list.len()).rev() {
        let (mut full, (mut lo, mut hi)) = (true, NO_RANGE);
        for c in [list[i].a, list[i].b] {
            let (f, (a, b)) = tree.child(list, base, c);
            full &= f;
            lo = lo.min(a);
            hi = hi.max(b);
        }
        list[i].full = full;
        list[i].min = lo;
        list[i].max = hi;
    }
}

/// [`subtree_ranges`] on `threads` threads, the same tree: the regions' ranges are copied
/// a stretch a thread, the subtrees a few levels below the root are counted, then listed,
/// each into its own stretch of the list, and the nodes above them last. A billion cells
/// make tens of millions of nodes, a second of the first frame on one core. Plain scoped
/// threads (a caller may be a rayon task initialising something other tasks wait for).
pub fn subtree_ranges_on<T: KdTree + Sync + ?Sized>(
    tree: &T,
    regions: usize,
    range: impl Fn(u32) -> Option<(f32, f32)> + Sync,
    threads: usize,
) -> RangedTree {
    let budget = tree.node_count().saturating_mul(2).saturating_add(1);
    if threads <= 1 {
        return subtree_ranges(tree, regions, range);
    }
    let mut out = RangedTree {
        root: EMPTY,
        inner: Vec::new(),
        leaves: vec![NO_RANGE; regions],
    };
    {
        let range = &range;
        let chunk = regions.div_ceil(threads * 4).max(1 << 12);
        on_threads(
            out.leaves.chunks_mut(chunk).enumerate().map(|(k, part)| {
                move || {
                    for (i, slot) in part.iter_mut().enumerate() {
                        *slot = range((k * chunk + i) as u32).unwrap_or(NO_RANGE);
                    }
                }
            }),
            threads,
        );
    }
    // The inner nodes above the cut in list order (with the entries of their children),
    // and the subtrees below it.
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
    // How many inner nodes each subtree below the cut lists (`None`: past the budget).
    let counts = on_threads(
        below.iter().map(|&n| move || count_inner(tree, n, budget)),
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
            _ => return subtree_ranges(tree, regions, range),
        }
    }
    let mut inner = vec![RangedNode::inner(0, 0.0, NO_RANGE); total];
    // Per entry of `top`: where its stretch starts and how long it is, and the reference
    // it becomes.
    let mut at: Vec<(usize, usize)> = Vec::with_capacity(top.len());
    let mut refs: Vec<u32> = vec![EMPTY; top.len()];
    {
        let mut work = Vec::with_capacity(below.len());
        let mut rest: &mut [RangedNode] = &mut inner;
        let mut sizes = sizes.iter();
        for (k, t) in top.iter().enumerate() {
            let base = at.last().map_or(0, |&(p, len)| p + len);
            let len = match t {
                Top::Inner(..) => 1,
                Top::Below(_) => sizes.next().copied().unwrap_or(0),
            };
            at.push((base, len));
            let (here, after) = std::mem::take(&mut rest).split_at_mut(len);
            rest = after;
            match t {
                Top::Inner(..) => refs[k] = base as u32,
                Top::Below(n) => match ranged_leaf(tree.node(*n)) {
                    Some(leaf) => refs[k] = leaf,
                    None => {
                        refs[k] = base as u32;
                        work.push((*n, base, here));
                    }
                },
            }
        }
        let shared = &out;
        on_threads(
            work.into_iter().map(|(n, base, stretch)| {
                move || {
                    let mut list = Vec::with_capacity(stretch.len());
                    list_inner(tree, n, &mut list, base, budget);
                    fold_ranges(shared, &mut list, base);
                    for (slot, node) in stretch.iter_mut().zip(list) {
                        *slot = node;
                    }
                }
            }),
            threads,
        );
    }
    // The nodes above the cut, children first.
    for k in (0..top.len()).rev() {
        let Top::Inner(axis, split, children) = top[k] else {
            continue;
        };
        let mut node = RangedNode::inner(axis, split, NO_RANGE);
        node.a = children
            .first()
            .and_then(|&c| refs.get(c))
            .copied()
            .unwrap_or(EMPTY);
        node.b = children
            .get(1)
            .and_then(|&c| refs.get(c))
            .copied()
            .unwrap_or(EMPTY);
        let (mut full, (mut lo, mut hi)) = (true, NO_RANGE);
        for c in [node.a, node.b] {
            let (f, (a, b)) = out.child(&inner, 0, c);
            full &= f;
            lo = lo.min(a);
            hi = hi.max(b);
        }
        (node.full, node.min, node.max) = (full, lo, hi);
        inner[at[k].0] = node;
    }
    out.root = refs.first().copied().unwrap_or(EMPTY);
    out.inner = inner;
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

/// How many inner nodes [`subtree_ranges`] lists for the subtree of `root`; `None` past
/// `budget` nodes reached.
fn count_inner<T: KdTree + ?Sized>(tree: &T, root: u32, budget: usize) -> Option<usize> {
    let mut todo = vec![root];
    let (mut reached, mut count) = (0usize, 0usize);
    while let Some(n) = todo.pop() {
        if reached >= budget {
            return None;
        }
        reached += 1;
        if let Some(Node::Inner { left, right, .. }) = tree.node(n) {
            count += 1;
            todo.push(right);
            todo.push(left);
        }
    }
    Some(count)
}

/// An inner node of a [`RangedTree`] with its subtree's range of one field (32 bytes:
/// half a cache line, so a walk reads node and range with one load).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangedNode {
    /// Split plane as stored.
    pub split: f64,
    /// The left child: a position in the list, or a leaf reference.
    pub a: u32,
    /// The right child: a position in the list, or a leaf reference.
    pub b: u32,
    /// Range of the field over the subtree.
    pub min: f32,
    pub max: f32,
    /// The axis the split plane cuts (0..=2).
    pub axis: u8,
    /// Every leaf below holds a region.
    pub full: bool,
}

impl RangedNode {
    fn inner(axis: usize, split: f64, (min, max): (f32, f32)) -> Self {
        RangedNode {
            split,
            a: EMPTY,
            b: EMPTY,
            min,
            max,
            axis: axis.min(2) as u8,
            full: true,
        }
    }

    /// The node, its children as positions in its list or leaf references.
    #[inline(always)]
    pub fn node(&self) -> Node {
        Node::Inner {
            axis: usize::from(self.axis),
            split: self.split,
            left: self.a,
            right: self.b,
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
