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

use crate::kd;
use crate::schema::{Aabb, ArchivedAabb, ArchivedBrick, ArchivedBrickFile};

/// The part of a ray inside one region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionSegment {
    pub region: u32,
    pub t_enter: f64,
    pub t_exit: f64,
}

/// Native copy of an archived box.
pub(crate) fn aabb(b: &ArchivedAabb) -> Aabb {
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

/// Region containing the world point `p`, found by descending the KD-tree (`O(depth)`,
/// see [`crate::kd::locate`]).
pub fn region_at(file: &ArchivedBrickFile, p: [f64; 3]) -> Option<u32> {
    // Inside the bounds a leaf's cell is its region's box.
    if !contains(&file.bounds, p) {
        return None;
    }
    kd::locate(&kd::file_tree(file), p, [0.0; 3])
}

/// Every region's box (its KD leaf's cell), by region index; regions in no leaf (none,
/// in a validated file) get [`Aabb::EMPTY`]. One walk over the tree.
pub fn region_boxes(file: &ArchivedBrickFile) -> Vec<Aabb> {
    let mut out = vec![Aabb::EMPTY; file.regions.len()];
    let b = bounds(file);
    kd::leaf_cells(
        &kd::file_tree(file),
        b.min,
        b.max,
        [0.0; 3],
        |r, min, max| {
            if let Some(slot) = out.get_mut(r as usize) {
                *slot = Aabb { min, max };
            }
        },
    );
    out
}

/// Entry and exit distances of the ray `origin + t * dir` through the box, clipped to
/// `[t_min, t_max]`; `None` when that part is empty. A ray parallel to an axis is inside
/// the slab when `min <= origin < max` (half-open, like [`contains`]). The same slab
/// test as the traversal's ([`crate::kd::ray_box`]).
pub fn ray_box(
    b: &ArchivedAabb,
    origin: [f64; 3],
    dir: [f64; 3],
    t_min: f64,
    t_max: f64,
) -> Option<(f64, f64)> {
    let b = aabb(b);
    kd::ray_box(&b.min, &b.max, &origin, &kd::inverse(&dir), t_min, t_max)
}

/// Regions crossed by the ray `origin + t * dir` (world) for `t` in `[t_min, t_max]`,
/// front to back, with entry and exit distances. Allocates the result; [`crate::kd::segments`] is the allocation-free
/// walk it is built on.
pub fn ray_regions(
    file: &ArchivedBrickFile,
    origin: [f64; 3],
    dir: [f64; 3],
    t_min: f64,
    t_max: f64,
) -> Vec<RegionSegment> {
    RayRegions::new(file, origin, dir, t_min, t_max).collect()
}

/// The segments of [`ray_regions`] as an iterator.
pub struct RayRegions {
    segments: std::vec::IntoIter<RegionSegment>,
}

impl RayRegions {
    pub fn new(
        file: &ArchivedBrickFile,
        origin: [f64; 3],
        dir: [f64; 3],
        t_min: f64,
        t_max: f64,
    ) -> Self {
        let mut out: Vec<RegionSegment> = Vec::new();
        let finite = origin.iter().chain(dir.iter()).all(|v| v.is_finite());
        if finite && t_min < t_max {
            let mut stack = Vec::new();
            kd::segments(
                file,
                &kd::FileNodes::new(file, 0),
                [0.0; 3],
                origin,
                dir,
                t_min,
                t_max,
                &mut stack,
                &kd::keep_all(),
                |s| {
                    out.push(RegionSegment {
                        region: s.region,
                        t_enter: s.t0,
                        t_exit: s.t1,
                    });
                    true
                },
            );
        }
        Self {
            segments: out.into_iter(),
        }
    }
}

impl Iterator for RayRegions {
    type Item = RegionSegment;

    fn next(&mut self) -> Option<RegionSegment> {
        self.segments.next()
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

/// Number of cells of a brick, `u64::MAX` for dims whose product a `u64` cannot hold
/// (three `u32`s can: such a brick fails `validate::check_brick`, but a view whose bricks
/// are checked where they are read may still be summarised, found by the `qbk_open` fuzz
/// target).
pub fn brick_cells(brick: &ArchivedBrick) -> u64 {
    brick
        .dims
        .iter()
        .fold(1u64, |n, d| n.saturating_mul(u64::from(d.to_native())))
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

/// The same queries on a file in memory (what the baker holds before writing, and what
/// its tests read back), with the same edge rules.
impl crate::BrickFile {
    /// The KD-tree as [`kd`]'s walks read it.
    pub fn kd_tree(&self) -> kd::Stored<'_, crate::KdNode> {
        kd::Stored {
            root: self.kd_root,
            nodes: &self.kd_nodes,
            axes: &self.kd_axes,
        }
    }

    /// Region containing the world point `p` (as [`region_at`]).
    pub fn region_at(&self, p: [f64; 3]) -> Option<u32> {
        let b = &self.bounds;
        if !(0..3).all(|a| p[a] >= b.min[a] && p[a] < b.max[a]) {
            return None;
        }
        kd::locate(&self.kd_tree(), p, [0.0; 3])
    }

    /// Brick ids of region `r` (as [`region_bricks`]); empty when `r` is out of range.
    pub fn bricks_of(&self, r: u32) -> &[u32] {
        self.regions
            .get(r as usize)
            .and_then(|reg| {
                let start = reg.bricks_start as usize;
                self.region_bricks
                    .get(start..start.checked_add(reg.bricks_len as usize)?)
            })
            .unwrap_or_default()
    }
}
