//! The file's KD-tree over the regions (format 3): inner nodes in depth-first, left-first
//! order (node 0 is the root, parents before children), inner nodes send `coordinate <
//! split` left, and a leaf is a child reference naming a region or empty space
//! ([`format::kd::LEAF`]). Regions are numbered in the same depth-first, left-first order,
//! and each sits in one leaf whose cell is its box.
//!
//! [`crate::regions::build`] writes the tree straight into this layout as it splits, one
//! [`Part`] per thread, instead of building a tree of boxed nodes first and copying it out:
//! a bake of a billion cells makes 16.6 M regions, and boxed nodes with a list each cost
//! about 350 bytes a region while the tree stood whole, against the 55 bytes or so the
//! file's arrays and the value ranges take.

use std::sync::Arc;

use format::kd::{self, EMPTY, LEAF, MAX_REGION};
use format::{Aabb, KdNode, Region};

use crate::spilled::{SpillTo, Store};

/// The stored tree: root reference, inner nodes, their axes (the file's `kd_root`,
/// `kd_nodes`, `kd_axes`), in memory or in scratch files ([`Store`]).
pub(crate) type Tree = (u32, Store<KdNode>, Store<u8>);

/// Regions as the tree numbers them, laid out as the file stores them: region `r`'s sorted
/// brick ids are the run `runs[r]` of `bricks`. Flat, so that a bake's millions of regions
/// cost their ids and a few bytes each, not a heap allocation each. A region's box is its
/// leaf's cell, which [`leaf_boxes`] derives in region order when it is needed (the file
/// does not store it, and at 48 bytes a region it was the largest part of the structure
/// a bake held).
#[derive(Debug, Default, PartialEq)]
pub(crate) struct Regions {
    pub runs: Store<Region>,
    pub bricks: Store<u32>,
}

impl Regions {
    pub(crate) fn len(&self) -> usize {
        self.runs.len()
    }

    /// Lets the pages of arrays kept on disk go (see [`Store::release_all`]).
    pub(crate) fn release_all(&self) {
        self.runs.release_all();
        self.bricks.release_all();
    }

    /// The sorted brick ids of region `r`.
    pub(crate) fn bricks_of(&self, r: usize) -> &[u32] {
        let run = &self.runs[r];
        let start = run.bricks_start as usize;
        &self.bricks[start..start + run.bricks_len as usize]
    }
}

/// Why a tree cannot be stored: more regions (or inner nodes) than a child reference can
/// name, counted whole, or more brick references than a region's `u32` run can reach; or
/// the scratch file holding it failed (a full disk).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum TooLarge {
    Regions(u64),
    BrickRefs(u64),
    Scratch(std::io::ErrorKind),
}

/// How many regions, inner nodes and brick references a stored tree may hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Limits {
    pub regions: u64,
    pub nodes: u64,
    pub refs: u64,
}

impl Limits {
    /// What the file's references reach: region indices up to [`MAX_REGION`], node
    /// indices below [`LEAF`], brick runs within `u32`.
    pub(crate) const FILE: Limits = Limits {
        regions: MAX_REGION as u64 + 1,
        nodes: LEAF as u64,
        refs: u32::MAX as u64,
    };
}

/// How much a [`Part`] holds: inner nodes, regions, brick references. Also a point to
/// [`Part::rollback`] to.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Mark {
    nodes: u64,
    regions: u64,
    refs: u64,
}

/// A tree, or the part of one a thread builds, in the file's layout: its own nodes and
/// regions numbered from 0, appended to the part before it once done ([`Part::append`]).
/// Past its [`Limits`] it only counts, so that a tree too large to store is reported with
/// its size instead of wrapping its references; while within them, what it stores is
/// exactly what it counts.
#[derive(Debug)]
pub(crate) struct Part {
    limits: Limits,
    to: Option<Arc<SpillTo>>,
    nodes: Store<KdNode>,
    axes: Store<u8>,
    regions: Regions,
    count: Mark,
}

impl Part {
    /// An empty part, its arrays kept in memory unless `to` says where to move them.
    pub(crate) fn new(limits: Limits, to: Option<Arc<SpillTo>>) -> Self {
        Part {
            limits,
            nodes: Store::new(to.clone()),
            axes: Store::new(to.clone()),
            regions: Regions {
                runs: Store::new(to.clone()),
                bricks: Store::new(to.clone()),
            },
            to,
            count: Mark::default(),
        }
    }

    /// An empty part with this one's limits and storage, for another thread.
    pub(crate) fn another(&self) -> Part {
        Part::new(self.limits, self.to.clone())
    }

    /// The first failure of a scratch file holding one of the part's arrays.
    fn failed(&self) -> Option<std::io::ErrorKind> {
        self.nodes
            .failed()
            .or(self.axes.failed())
            .or(self.regions.runs.failed())
            .or(self.regions.bricks.failed())
    }

    fn fits(&self) -> bool {
        let (c, l) = (&self.count, &self.limits);
        c.nodes <= l.nodes && c.regions <= l.regions && c.refs <= l.refs
    }

    /// What the part holds now, to roll back to.
    pub(crate) fn mark(&self) -> Mark {
        self.count
    }

    /// Drops everything added since `mark` was taken (marks are rolled back to in the
    /// reverse order they were taken, as a recursion does).
    pub(crate) fn rollback(&mut self, mark: Mark) {
        self.count = mark;
        self.nodes.truncate(mark.nodes as usize);
        self.axes.truncate(mark.nodes as usize);
        self.regions.runs.truncate(mark.regions as usize);
        self.regions.bricks.truncate(mark.refs as usize);
    }

    /// Adds an inner node splitting at `split` on `axis`, its children empty until
    /// [`Part::close`]; returns its reference.
    pub(crate) fn open(&mut self, axis: u8, split: f64) -> u32 {
        let id = self.count.nodes;
        self.count.nodes += 1;
        if !self.fits() {
            return EMPTY;
        }
        self.nodes.push(KdNode {
            split,
            left: EMPTY,
            right: EMPTY,
        });
        self.axes.push(axis);
        id as u32
    }

    /// Sets the children of the node `open` returned `node` for.
    pub(crate) fn close(&mut self, node: u32, left: u32, right: u32) {
        if let Some(n) = self.nodes.get_mut(node as usize) {
            n.left = left;
            n.right = right;
        }
    }

    /// Adds a region with its sorted brick ids; returns its leaf reference.
    pub(crate) fn region(&mut self, bricks: &[u32]) -> u32 {
        let (r, start) = (self.count.regions, self.count.refs);
        self.count.regions += 1;
        self.count.refs += bricks.len() as u64;
        if !self.fits() {
            return EMPTY;
        }
        let rs = &mut self.regions;
        rs.runs.push(Region {
            bricks_start: start as u32,
            bricks_len: bricks.len() as u32,
        });
        rs.bricks.extend_from_slice(bricks);
        LEAF | r as u32
    }

    /// Appends `other` after everything this part holds; returns the reference `root`
    /// (one of `other`'s) as this part numbers it.
    pub(crate) fn append(&mut self, other: Part, root: u32) -> u32 {
        let at = self.count;
        self.count.nodes += other.count.nodes;
        self.count.regions += other.count.regions;
        self.count.refs += other.count.refs;
        if !self.fits() || !other.fits() {
            return EMPTY;
        }
        // Within the limits, so every shifted index still fits its reference.
        let shift = |r: u32| match r {
            EMPTY => EMPTY,
            r if r & LEAF != 0 => LEAF | ((r & !LEAF) + at.regions as u32),
            r => r + at.nodes as u32,
        };
        // A chunk at a time, letting the other part's pages go behind (when on disk).
        const CHUNK: usize = 1 << 16;
        for (k, chunk) in other.nodes.chunks(CHUNK).enumerate() {
            self.nodes.extend(chunk.iter().map(|n| KdNode {
                split: n.split,
                left: shift(n.left),
                right: shift(n.right),
            }));
            other.nodes.release(k * CHUNK..(k + 1) * CHUNK);
        }
        for (k, chunk) in other.axes.chunks(CHUNK).enumerate() {
            self.axes.extend_from_slice(chunk);
            other.axes.release(k * CHUNK..(k + 1) * CHUNK);
        }
        if let Some(e) = other.failed() {
            // The other part's arrays stopped short: this one cannot be whole either.
            self.nodes.fail(e);
        }
        let rs = &mut self.regions;
        for (k, chunk) in other.regions.runs.chunks(CHUNK).enumerate() {
            rs.runs.extend(chunk.iter().map(|r| Region {
                bricks_start: r.bricks_start + at.refs as u32,
                bricks_len: r.bricks_len,
            }));
            other.regions.runs.release(k * CHUNK..(k + 1) * CHUNK);
        }
        for (k, chunk) in other.regions.bricks.chunks(CHUNK).enumerate() {
            rs.bricks.extend_from_slice(chunk);
            other.regions.bricks.release(k * CHUNK..(k + 1) * CHUNK);
        }
        shift(root)
    }

    /// The stored tree with root reference `root`, and its regions; or what is too large
    /// to store.
    pub(crate) fn finish(self, root: u32) -> Result<(Tree, Regions), TooLarge> {
        if let Some(e) = self.failed() {
            return Err(TooLarge::Scratch(e));
        }
        let (c, l) = (self.count, self.limits);
        if c.regions > l.regions || c.nodes > l.nodes {
            return Err(TooLarge::Regions(c.regions));
        }
        if c.refs > l.refs {
            return Err(TooLarge::BrickRefs(c.refs));
        }
        Ok(((root, self.nodes, self.axes), self.regions))
    }
}

/// The box of every region of `tree`, in region order: the cells of its region leaves,
/// depth-first and left-first from `root` (the box of the whole tree), cut at each inner
/// node's split as the build cut them, so each is bit for bit the box the region was made
/// for ([`format::kd::LeafCells`], the walk the viewer derives its region table with).
pub(crate) fn leaf_boxes(tree: &Tree, root: Aabb) -> impl Iterator<Item = Aabb> + '_ {
    kd::LeafCells::new(stored(tree), root.min, root.max, [0.0; 3])
        .map(|(_, min, max)| Aabb { min, max })
}

/// The packed tree as the file's walks read it.
pub(crate) fn stored(tree: &Tree) -> kd::Stored<'_, KdNode> {
    let (root, nodes, axes) = tree;
    kd::Stored {
        root: *root,
        nodes: nodes.as_slice(),
        axes: axes.as_slice(),
    }
}

/// Region containing `p` by descending the tree (for tests and the baker's self-check):
/// the file's own descent, [`format::kd::locate`].
#[cfg(test)]
pub(crate) fn locate(tree: &Tree, p: [f64; 3]) -> Option<u32> {
    format::kd::locate(&stored(tree), p, [0.0; 3])
}
