//! The KD-tree over the regions: point location and front-to-back ray traversal.
//!
//! This is the one implementation of the file's structure logic: the baker checks its own
//! tree with [`locate`], the viewer samples along [`segments`], and the tests use both as
//! they are. Everything works on the stored numbers plus a `shift` that is subtracted from
//! every stored coordinate: the viewer works in a local frame centred on the data (so that
//! data placed at 1e6 keeps sub-cell precision) and passes the frame's origin; callers in
//! world coordinates pass `[0.0; 3]`. The edge rules are the same everywhere:
//! - a box is half-open, `[min, max)`: a point on a split plane goes right (`>= split`);
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

/// A KD node as the descent sees it.
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

/// A KD-tree as stored: native while baking, archived when reading a file.
pub trait KdTree {
    fn node_count(&self) -> usize;
    fn node(&self, i: u32) -> Option<Node>;
}

impl KdTree for [KdNode] {
    fn node_count(&self) -> usize {
        self.len()
    }
    #[inline]
    fn node(&self, i: u32) -> Option<Node> {
        Some(match self.get(i as usize)? {
            KdNode::Inner {
                axis,
                split,
                left,
                right,
            } => Node::Inner {
                axis: usize::from(*axis),
                split: *split,
                left: *left,
                right: *right,
            },
            KdNode::Leaf { region } => Node::Leaf(*region),
        })
    }
}

impl KdTree for [ArchivedKdNode] {
    fn node_count(&self) -> usize {
        self.len()
    }
    #[inline]
    fn node(&self, i: u32) -> Option<Node> {
        Some(match self.get(i as usize)? {
            ArchivedKdNode::Inner {
                axis,
                split,
                left,
                right,
            } => Node::Inner {
                axis: usize::from(*axis),
                split: split.to_native(),
                left: left.to_native(),
                right: right.to_native(),
            },
            ArchivedKdNode::Leaf { region } => Node::Leaf(region.as_ref().map(|r| r.to_native())),
        })
    }
}

/// The leaf's region reached from the root by the point `p` (`p[axis] < split - shift[axis]`
/// goes left); `None` for an empty leaf. The caller checks that `p` lies in the region's
/// box when leaves may be larger than their regions.
#[inline]
pub fn locate<T: KdTree + ?Sized>(tree: &T, p: [f64; 3], shift: [f64; 3]) -> Option<u32> {
    let mut n = 0u32;
    for _ in 0..tree.node_count() {
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

/// A node with the walk's field's range over its subtree (`None`: no ranges, skip
/// nothing) and whether it is full.
pub type NodeEntry = (Node, Option<(f32, f32)>, bool);

/// What the ray walk reads per node: the node, and the walk's field's range and fullness
/// over its subtree. The file's own tables ([`FileNodes`]) are one store; a reader may
/// pack them per field for speed (the viewer does: node and range in one cache line) and
/// walk the same way with [`segments`].
pub trait WalkNodes {
    fn node_count(&self) -> usize;
    fn node(&self, n: u32) -> Option<Node>;
    /// Range of the walk's field over node `n`'s subtree; `None` when the store has no
    /// ranges (nothing is skipped).
    fn range(&self, n: u32) -> Option<(f32, f32)>;
    /// Every leaf below `n` holds a region.
    fn full(&self, n: u32) -> bool;
    /// All three at once (a store that keeps them together answers with one read).
    #[inline]
    fn get(&self, n: u32) -> Option<NodeEntry> {
        Some((self.node(n)?, self.range(n), self.full(n)))
    }
}

/// The archived tree with field `field`'s ranges, as stored in the file.
#[derive(Clone, Copy)]
pub struct FileNodes<'a> {
    file: &'a ArchivedBrickFile,
    field: usize,
    fields: usize,
    ranges: bool,
}

impl<'a> FileNodes<'a> {
    pub fn new(file: &'a ArchivedBrickFile, field: usize) -> Self {
        let (n, nf) = (file.kd_nodes.len(), file.fields.len());
        Self {
            file,
            field,
            fields: nf,
            ranges: field < nf && file.kd_ranges.len() == n * nf && file.kd_full.len() == n,
        }
    }
}

impl WalkNodes for FileNodes<'_> {
    fn node_count(&self) -> usize {
        self.file.kd_nodes.len()
    }
    #[inline]
    fn node(&self, n: u32) -> Option<Node> {
        self.file.kd_nodes.as_slice().node(n)
    }
    #[inline]
    fn range(&self, n: u32) -> Option<(f32, f32)> {
        if !self.ranges {
            return None;
        }
        let r = self
            .file
            .kd_ranges
            .get(n as usize * self.fields + self.field)?;
        Some((r.min.to_native(), r.max.to_native()))
    }
    #[inline]
    fn full(&self, n: u32) -> bool {
        self.file.kd_full.get(n as usize).is_some_and(|f| *f)
    }
}

/// Calls `f` for every region the ray `o + t d` crosses within `[t_min, t_max]`, front to
/// back, with the region's box clipped to the ray; a subtree whose range (from `nodes`,
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
    if nodes.node_count() == 0 || t_min >= t_max || t_min.is_nan() || t_max.is_nan() {
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
    let mut budget = nodes.node_count().saturating_mul(2);
    stack.clear();
    stack.push((0, t0, t1));
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
                    let Some(reg) = file.regions.get(r as usize) else {
                        break;
                    };
                    let rmin: [f64; 3] =
                        std::array::from_fn(|a| reg.bounds.min[a].to_native() - shift[a]);
                    let rmax: [f64; 3] =
                        std::array::from_fn(|a| reg.bounds.max[a].to_native() - shift[a]);
                    if let Some((s0, s1)) = ray_box(&rmin, &rmax, &o, &inv, ta, tb) {
                        let (mn, mx) = range.unwrap_or(all);
                        if !f(Segment {
                            region: r,
                            t0: s0,
                            t1: s1,
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

/// The per-node tables a file stores with its tree ([`crate::BrickFile::kd_ranges`],
/// [`crate::BrickFile::kd_full`]): for every node the range of every field over its
/// subtree and whether every leaf below holds a region. `region_ranges` is region-major
/// (`r * fields + f`). Nodes that the root does not reach get an empty range and `false`.
pub(crate) fn subtree_tables(
    nodes: &[KdNode],
    region_ranges: &[crate::ValueRange],
    fields: usize,
) -> (Vec<crate::ValueRange>, Vec<bool>) {
    let empty = crate::ValueRange {
        min: f32::INFINITY,
        max: f32::NEG_INFINITY,
    };
    let mut ranges = vec![empty; nodes.len() * fields];
    let mut full = vec![false; nodes.len()];
    // Pre-order with each node once, then children before parents by walking it backwards.
    let mut order = Vec::with_capacity(nodes.len());
    let mut seen = vec![false; nodes.len()];
    let mut stack = vec![0u32];
    while let Some(n) = stack.pop() {
        match seen.get_mut(n as usize) {
            Some(s) if !*s => *s = true,
            _ => continue,
        }
        order.push(n as usize);
        if let KdNode::Inner { left, right, .. } = nodes[n as usize] {
            stack.push(left);
            stack.push(right);
        }
    }
    for &n in order.iter().rev() {
        match nodes[n] {
            KdNode::Leaf { region: Some(r) } => {
                full[n] = true;
                for f in 0..fields {
                    if let Some(v) = region_ranges.get(r as usize * fields + f) {
                        ranges[n * fields + f] = *v;
                    }
                }
            }
            KdNode::Leaf { region: None } => {}
            KdNode::Inner { left, right, .. } => {
                let (l, r) = (left as usize, right as usize);
                full[n] =
                    full.get(l).copied().unwrap_or(false) && full.get(r).copied().unwrap_or(false);
                for f in 0..fields {
                    let mut v = empty;
                    for c in [l, r] {
                        if let Some(cv) = ranges.get(c * fields + f) {
                            v.min = v.min.min(cv.min);
                            v.max = v.max.max(cv.max);
                        }
                    }
                    ranges[n * fields + f] = v;
                }
            }
        }
    }
    (ranges, full)
}
