//! Building an active tree: the regions of the field's packed tree whose range holds the
//! value, their cell lattices, the dual-cell masks of the regions of one lattice and the
//! parts those masks cut them into, regrouped by the surface area heuristic.

use format::kd::{Node, WalkNodes};
use rayon::prelude::*;

use super::nodes::{join, part_tree, rewrite, surface_area_tree, ActiveNode, LEAF, NONE};
use super::range_holds;
use super::tree::{ActiveTree, Walk};
use crate::dual_mask::{DualMask, SubBox, MAX_TREE_WORK};
use crate::lattice::{Lattice, Lattices};
use crate::packed::Packed;
use crate::volume::Volume;

impl ActiveTree {
    /// The tree of the regions of `vol` whose range of `field` holds `value`, built from
    /// `packed`, the file's tree packed with the field's ranges (its per-node ranges prune
    /// whole subtrees), each region of one cell lattice cut into the parts where its dual
    /// cells can hold the value ([`DualMask::sub_boxes`]). `None` when the file's tree
    /// cannot be walked as a tree (the caller then walks the file's tree itself).
    /// `parallel` builds the regions' masks on the current rayon pool: only for a caller
    /// that holds no lock another job of that pool may wait for.
    pub(crate) fn build(
        vol: &Volume,
        packed: &Packed,
        field: usize,
        value: f64,
        parallel: bool,
    ) -> Option<ActiveTree> {
        Self::build_with(vol, packed, field, value, parallel, true, MAX_TREE_WORK)
    }

    /// [`ActiveTree::build`] with every region whole (what the cut tree is compared with).
    #[cfg(test)]
    pub(crate) fn uncut(vol: &Volume, field: usize, value: f64) -> Option<ActiveTree> {
        let packed = vol.packed(field)?;
        Self::build_with(vol, &packed, field, value, false, false, MAX_TREE_WORK)
    }

    /// [`ActiveTree::build`] with the field's packed tree taken from `vol` (tests).
    #[cfg(test)]
    pub(crate) fn of(vol: &Volume, field: usize, value: f64) -> Option<ActiveTree> {
        let packed = vol.packed(field)?;
        Self::build(vol, &packed, field, value, false)
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
        let packed = vol.packed(field)?;
        let tree = Self::build_with(vol, &packed, field, value, false, true, mask_work)?;
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
    #[allow(clippy::too_many_arguments)]
    fn build_with(
        vol: &Volume,
        packed: &Packed,
        field: usize,
        value: f64,
        parallel: bool,
        cut: bool,
        mask_work: usize,
    ) -> Option<ActiveTree> {
        let tree = packed;
        let holds = |mn: f32, mx: f32| range_holds(mn, mx, value);
        let mut nodes: Vec<ActiveNode> = Vec::new();
        let mut lattices: Vec<Lattice> = Vec::new();
        let mut region_boxes: Vec<([f64; 3], [f64; 3])> = Vec::new();
        // Post-order without recursion (a valid tree may still be deep): `(node, expanded,
        // its cell)`; a leaf's cell is its region's box (the volume keeps no table of them).
        let mut todo: Vec<(u32, bool, [f64; 3], [f64; 3])> = Vec::with_capacity(64);
        // The active-tree node each finished subtree became, or `NONE`.
        let mut done: Vec<u32> = Vec::with_capacity(64);
        // The root may be a leaf (a file of one region), or empty space.
        let (lo, hi) = vol.root_cell();
        todo.push((tree.root(), false, lo, hi));
        // An inner node is visited twice and a leaf once, and a tree of `n` inner nodes
        // has `n + 1` leaves; more visits mean it is not a tree.
        let mut budget = tree.node_count().saturating_mul(3).saturating_add(2);
        while let Some((n, expanded, cmin, cmax)) = todo.pop() {
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
                Node::Inner {
                    axis,
                    split,
                    left,
                    right,
                } => {
                    let (lhi, rlo) = format::kd::cut_cell(axis, split, vol.frame, cmin, cmax);
                    todo.push((n, true, cmin, cmax));
                    todo.push((right, false, rlo, cmax));
                    todo.push((left, false, cmin, lhi));
                }
                Node::Leaf(Some(r)) if (r as usize) < vol.region_count() => {
                    let [mn, mx] = vol.range(r as usize, field);
                    if holds(mn, mx) {
                        let l = Lattices::of(vol, r as usize);
                        let first = u32::try_from(lattices.len()).ok()?;
                        lattices.extend_from_slice(l.as_slice());
                        let region_box = u32::try_from(region_boxes.len()).ok()?;
                        region_boxes.push((cmin, cmax));
                        nodes.push(ActiveNode {
                            min: cmin,
                            max: cmax,
                            a: r,
                            b: first,
                            axis: LEAF,
                            inexact: l.inexact,
                            lattices: l.as_slice().len() as u8,
                            mask: NONE,
                            sub: NONE,
                            region_box,
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
            lattices,
            masks,
            region_boxes,
            walk,
        })
    }
}
