//! Read-only queries shared by both programs.
//!
//! All queries take the archived root (`&ArchivedBrickFile`, from
//! [`crate::BrickFileView::file`]) and use checked indexing only: on an archive that passed
//! [`crate::validate::check`] they find everything; on any other archive they return
//! less (`None`, empty slices, fewer segments) but never panic or loop forever.
//!
//! Boxes are half-open, `[min, max)` on every axis, like KD splits (`< split` goes left):
//! a point on a face shared by two regions belongs to the upper one.

use rkyv::Archived;

use crate::schema::{Aabb, ArchivedAabb, ArchivedBrick, ArchivedBrickFile, ArchivedKdNode};

/// The part of a ray inside one region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionSegment {
    pub region: u32,
    pub t_enter: f64,
    pub t_exit: f64,
}

/// Native copy of an archived box.
pub fn aabb(b: &ArchivedAabb) -> Aabb {
    Aabb {
        min: b.min.map(|v| v.to_native()),
        max: b.max.map(|v| v.to_native()),
    }
}

/// Whether `p` lies in the half-open box `[min, max)`.
pub fn contains(b: &ArchivedAabb, p: [f64; 3]) -> bool {
    (0..3).all(|a| p[a] >= b.min[a].to_native() && p[a] < b.max[a].to_native())
}

/// The global bounds: union of all brick supports.
pub fn bounds(file: &ArchivedBrickFile) -> Aabb {
    aabb(&file.bounds)
}

/// Region containing `p`, found by descending the KD-tree (`O(depth)`).
pub fn region_at(file: &ArchivedBrickFile, p: [f64; 3]) -> Option<u32> {
    let nodes = &file.kd_nodes;
    let mut node = 0u32;
    // A tree visits each node at most once on the way down; the budget stops cycles in
    // archives that skipped `validate::check`.
    for _ in 0..nodes.len() {
        match nodes.get(node as usize)? {
            ArchivedKdNode::Inner {
                axis,
                split,
                left,
                right,
            } => {
                let c = *p.get(usize::from(*axis))?;
                node = if c < split.to_native() {
                    left.to_native()
                } else {
                    right.to_native()
                };
            }
            ArchivedKdNode::Leaf { region } => {
                let r = region.as_ref()?.to_native();
                let reg = file.regions.get(r as usize)?;
                // A leaf's cell may be larger than its region (empty space around it).
                return contains(&reg.bounds, p).then_some(r);
            }
        }
    }
    None
}

/// Entry and exit distances of the ray `origin + t * dir` through the box, clipped to
/// `[t_min, t_max]`; `None` when that part is empty. A ray parallel to an axis is inside
/// the slab when `min <= origin < max` on that axis (half-open, like [`contains`]).
pub fn ray_box(
    b: &ArchivedAabb,
    origin: [f64; 3],
    dir: [f64; 3],
    t_min: f64,
    t_max: f64,
) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (t_min, t_max);
    for a in 0..3 {
        let (lo, hi) = (b.min[a].to_native(), b.max[a].to_native());
        if dir[a] == 0.0 {
            if origin[a] < lo || origin[a] >= hi {
                return None;
            }
            continue;
        }
        // Same expression as the KD traversal's plane distance, so that a region face on
        // a split plane gives bit-identical distances on both sides.
        let ta = plane_t(lo, origin[a], dir[a]);
        let tb = plane_t(hi, origin[a], dir[a]);
        let (near, far) = if dir[a] > 0.0 { (ta, tb) } else { (tb, ta) };
        t0 = t0.max(near);
        t1 = t1.min(far);
    }
    (t0 < t1).then_some((t0, t1))
}

#[inline]
fn plane_t(plane: f64, origin: f64, dir: f64) -> f64 {
    (plane - origin) / dir
}

/// Regions crossed by the ray `origin + t * dir` for `t` in `[t_min, t_max]`, front to
/// back, with entry and exit distances. Allocates the result; see [`RayRegions`] for the
/// allocation-free iterator.
pub fn ray_regions(
    file: &ArchivedBrickFile,
    origin: [f64; 3],
    dir: [f64; 3],
    t_min: f64,
    t_max: f64,
) -> Vec<RegionSegment> {
    RayRegions::new(file, origin, dir, t_min, t_max).collect()
}

/// Nodes kept on the iterator itself before the stack spills to the heap; a balanced
/// tree over 2^32 regions is 32 deep, so spilling means a degenerate tree.
const INLINE_STACK: usize = 32;

type StackEntry = (u32, f64, f64);

/// A stack of pending far children that lives inline until it is deeper than
/// [`INLINE_STACK`].
struct Stack {
    inline: [StackEntry; INLINE_STACK],
    len: usize,
    spill: Vec<StackEntry>,
}

impl Stack {
    fn new() -> Self {
        Self {
            inline: [(0, 0.0, 0.0); INLINE_STACK],
            len: 0,
            spill: Vec::new(),
        }
    }

    fn push(&mut self, e: StackEntry) {
        match self.inline.get_mut(self.len) {
            Some(slot) => {
                *slot = e;
                self.len += 1;
            }
            None => self.spill.push(e),
        }
    }

    fn pop(&mut self) -> Option<StackEntry> {
        if let Some(e) = self.spill.pop() {
            return Some(e);
        }
        self.len = self.len.checked_sub(1)?;
        self.inline.get(self.len).copied()
    }

    fn clear(&mut self) {
        self.len = 0;
        self.spill.clear();
    }
}

/// Front-to-back KD-tree traversal of a ray, yielding one [`RegionSegment`] per region
/// crossed, in increasing `t_enter`. No heap allocation unless the tree is deeper than 32.
///
/// The classic recursive walk: at an inner node the ray interval `[t0, t1]` is cut at the
/// split plane's distance; the child on the ray's near side is walked first, the far one
/// is pushed. A region cut by a split plane (possible when regions cannot be separated
/// by axis planes alone) sits in several leaves; its consecutive pieces are merged, so
/// every region appears once.
pub struct RayRegions<'a> {
    file: &'a ArchivedBrickFile,
    origin: [f64; 3],
    dir: [f64; 3],
    stack: Stack,
    pending: Option<RegionSegment>,
    budget: usize,
}

impl<'a> RayRegions<'a> {
    pub fn new(
        file: &'a ArchivedBrickFile,
        origin: [f64; 3],
        dir: [f64; 3],
        t_min: f64,
        t_max: f64,
    ) -> Self {
        let mut stack = Stack::new();
        let finite = origin.iter().chain(dir.iter()).all(|v| v.is_finite());
        if finite && t_min < t_max && !file.kd_nodes.is_empty() {
            stack.push((0, t_min, t_max));
        }
        Self {
            file,
            origin,
            dir,
            stack,
            pending: None,
            // Each node is visited at most once per ray in a tree.
            budget: file.kd_nodes.len(),
        }
    }

    /// Walks from `node` over `[t0, t1]` down to a leaf; returns the segment it holds.
    fn descend(&mut self, mut node: u32, t0: f64, mut t1: f64) -> Option<RegionSegment> {
        let nodes = &self.file.kd_nodes;
        loop {
            if self.budget == 0 {
                self.stack.clear();
                return None;
            }
            self.budget -= 1;
            match nodes.get(node as usize)? {
                ArchivedKdNode::Inner {
                    axis,
                    split,
                    left,
                    right,
                } => {
                    let a = usize::from(*axis);
                    let (o, d) = (*self.origin.get(a)?, *self.dir.get(a)?);
                    let split = split.to_native();
                    let (left, right) = (left.to_native(), right.to_native());
                    if d == 0.0 {
                        node = if o < split { left } else { right };
                        continue;
                    }
                    let (first, second) = if d > 0.0 {
                        (left, right)
                    } else {
                        (right, left)
                    };
                    let ts = plane_t(split, o, d);
                    if ts >= t1 {
                        node = first;
                    } else if ts <= t0 {
                        node = second;
                    } else {
                        self.stack.push((second, ts, t1));
                        node = first;
                        t1 = ts;
                    }
                }
                ArchivedKdNode::Leaf { region } => {
                    let r = region.as_ref()?.to_native();
                    let reg = self.file.regions.get(r as usize)?;
                    let (t_enter, t_exit) = ray_box(&reg.bounds, self.origin, self.dir, t0, t1)?;
                    return Some(RegionSegment {
                        region: r,
                        t_enter,
                        t_exit,
                    });
                }
            }
        }
    }
}

impl Iterator for RayRegions<'_> {
    type Item = RegionSegment;

    fn next(&mut self) -> Option<RegionSegment> {
        while let Some((node, t0, t1)) = self.stack.pop() {
            let Some(seg) = self.descend(node, t0, t1) else {
                continue;
            };
            match self.pending.as_mut() {
                Some(p) if p.region == seg.region && seg.t_enter <= p.t_exit => {
                    p.t_exit = p.t_exit.max(seg.t_exit);
                }
                Some(_) => return self.pending.replace(seg),
                None => self.pending = Some(seg),
            }
        }
        self.pending.take()
    }
}

/// Brick ids of region `r` (ascending); empty when `r` is out of range.
pub fn region_bricks(file: &ArchivedBrickFile, r: u32) -> &[Archived<u32>] {
    file.regions
        .get(r as usize)
        .and_then(|reg| {
            let start = reg.bricks_start.to_native() as usize;
            let len = reg.bricks_len.to_native() as usize;
            file.region_bricks.get(start..start.checked_add(len)?)
        })
        .unwrap_or_default()
}

/// Value range of field `f` over everything that can contribute to region `r`.
pub fn region_range(file: &ArchivedBrickFile, r: u32, f: usize) -> Option<(f32, f32)> {
    let i = (r as usize)
        .checked_mul(file.fields.len())?
        .checked_add(f)?;
    if f >= file.fields.len() {
        return None;
    }
    let range = file.region_ranges.get(i)?;
    Some((range.min.to_native(), range.max.to_native()))
}

/// Number of cells of a brick.
pub fn brick_cells(brick: &ArchivedBrick) -> u64 {
    brick
        .dims
        .iter()
        .map(|d| u64::from(d.to_native()))
        .product()
}

/// Values of field `field` over the cells of brick `brick` (x fastest, see
/// [`cell_index`]); `None` when either is out of range.
pub fn brick_values(
    file: &ArchivedBrickFile,
    brick: u32,
    field: usize,
) -> Option<&[Archived<f32>]> {
    let b = file.bricks.get(brick as usize)?;
    let first = usize::try_from(b.first_value.to_native()).ok()?;
    let n = usize::try_from(brick_cells(b)).ok()?;
    file.fields
        .get(field)?
        .values
        .get(first..first.checked_add(n)?)
}

/// Index of cell `(i, j, k)` in a brick's value slice: `i + nx * (j + ny * k)`.
pub fn cell_index(brick: &ArchivedBrick, ijk: [u32; 3]) -> Option<usize> {
    let [nx, ny, nz] = brick.dims.map(|d| d.to_native() as usize);
    let [i, j, k] = ijk.map(|c| c as usize);
    (i < nx && j < ny && k < nz).then(|| i + nx * (j + ny * k))
}

/// World-space centre of cell `(i, j, k)` of a brick (no range check: cells outside the
/// brick extrapolate the lattice).
pub fn cell_center(brick: &ArchivedBrick, ijk: [u32; 3]) -> [f64; 3] {
    let w = brick.cell_width.to_native();
    std::array::from_fn(|a| brick.origin[a].to_native() + f64::from(ijk[a]) * w)
}

/// A brick's support: its cells' boxes grown by half a cell, i.e. from
/// `origin - cell_width` to `origin + dims * cell_width` on each axis.
pub fn brick_support(brick: &ArchivedBrick) -> Aabb {
    let w = brick.cell_width.to_native();
    Aabb {
        min: std::array::from_fn(|a| brick.origin[a].to_native() - w),
        max: std::array::from_fn(|a| {
            brick.origin[a].to_native() + f64::from(brick.dims[a].to_native()) * w
        }),
    }
}
