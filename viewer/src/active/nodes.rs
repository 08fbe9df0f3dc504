//! The shape of an active tree while it is built: nodes in a flat list (children before
//! parents, root last), how two subtrees are joined, how leaves are replaced or dropped,
//! a region's parts as a subtree, and the surface-area regrouping of the leaves.

use crate::dual_mask::SubBox;

/// Marker of "no node".
pub(super) const NONE: u32 = u32::MAX;
/// `ActiveNode::axis` of a leaf.
pub(super) const LEAF: u8 = 3;

/// A node of the active tree (local frame).
#[derive(Debug, Clone, Copy)]
pub(super) struct ActiveNode {
    /// Union of the boxes of the regions below (a leaf: its region's box).
    pub(super) min: [f64; 3],
    pub(super) max: [f64; 3],
    /// Inner: the child below the split plane; leaf: the region.
    pub(super) a: u32,
    /// Inner: the child at or above the split plane.
    pub(super) b: u32,
    /// 0..=2: inner node split on this axis; [`LEAF`]: a region.
    pub(super) axis: u8,
    /// Leaf: its region has more cell lattices than `exact` cuts.
    pub(super) inexact: bool,
    /// Leaf: how many of the tree's lattices, from `b` on, are its region's.
    pub(super) lattices: u8,
    /// Leaf: its region's index in the tree's masks, or [`NONE`].
    pub(super) mask: u32,
    /// Leaf of a whole region: its index in the list of the regions' sub-boxes while the
    /// tree is built (see `build`), or [`NONE`].
    pub(super) sub: u32,
    /// Leaf: its region's whole box in the tree's list of them (a part keeps its
    /// region's).
    pub(super) region_box: u32,
}

/// The node that joins the subtrees `lo` (below a split plane on `axis`) and `hi` (at or
/// above it) of `nodes`, either of which may be [`NONE`]: a new inner node around both, the
/// one that is there, or [`NONE`].
pub(super) fn join(nodes: &mut Vec<ActiveNode>, lo: u32, hi: u32, axis: u8) -> u32 {
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
                region_box: NONE,
            });
            (nodes.len() - 1) as u32
        }
    }
}

/// `tree` (children before parents, root last) with every leaf replaced by what `leaf`
/// appends for it and returns `true` (a subtree, children before parents and its root
/// last), or by nothing when it returns `false` (the leaf leaves the tree). An inner node left with one child becomes that child, and
/// inner boxes are those of what remains below them.
pub(super) fn rewrite(
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
pub(super) fn part_tree(parts: &mut [SubBox], leaf: &ActiveNode, out: &mut Vec<ActiveNode>) {
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
pub(super) fn surface_area_tree(tree: &[ActiveNode]) -> Option<Vec<ActiveNode>> {
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
            region_box: NONE,
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
