//! What a view without a given camera looks at, and from how far.
//!
//! Issue 26: the default camera framed the regions whose value *range* holds the iso
//! value, fitted as a bounding sphere into a square: the structure then filled 28–50 % of
//! the image width, and a file whose regions reach far past the surface came out
//! off-centre. Here the box is the iso surface's own bound (from the cells, not the
//! regions), and the camera is placed so that this box's projection is centred in the
//! image and fills a set fraction of it.

use glam::DVec3;

use crate::camera::{Camera, Projection};
use crate::volume::Volume;

/// Fraction of the image's width or height (whichever binds) the framed box fills.
pub const DEFAULT_FILL: f64 = 0.8;

/// Boxes (local frame of `vol`, one per block of a brick at most) whose union holds every point
/// where the reconstruction of field `f` equals `iso`; empty when no cell lies on both
/// sides of it (nothing to see).
///
/// The reconstruction is a convex combination of the cells whose tents reach a point
/// (each cell's support is its centre ± one cell width), so a point on the surface is
/// reached by a cell with value ≥ iso *and* one with value ≤ iso: the surface lies in the
/// supports of the first set, within the bounding box of the supports of the second.
/// Per block of [`BLOCK`]³ cells of a brick, the box of its cells of the first set cut
/// by that bounding box is one entry. For Q iso-surfaces around vortex cores these boxes follow the cores closely,
/// while regions' ranges (which cover whole bricks and their neighbours) do not, and the
/// list's corners give the camera the structure's silhouette far better than one box
/// (a ring's box has empty corners). It runs when a file is opened, split over the bricks
/// on all cores, and reads only the cells of bricks that can hold the value: a brick every
/// region of which ranges below `iso` has all its cells below it, so it adds its whole
/// box to the second set without a read ([`bricks_below`]). On a file larger than memory
/// that keeps the first frame's reads to the pages near the surface.
pub fn surface_boxes(vol: &Volume, f: usize, iso: f64) -> Vec<([f64; 3], [f64; 3])> {
    let mut out = Vec::new();
    SurfaceBoxes::of(vol, f, iso).for_each(vol, |lo, hi| out.push((lo, hi)));
    out
}

/// The boxes of [`surface_boxes`], held as which cells of each block reach the value (a
/// byte a block) instead of as boxes (48 bytes each): a billion-cell file has tens of
/// millions of them, and the list, its copy in world coordinates and the camera fit's
/// copy took 6.6 GB before its first frame. [`SurfaceBoxes::for_each`] makes them again,
/// in the same order and with the same arithmetic, as often as a caller needs them.
pub struct SurfaceBoxes {
    /// Bricks with cells at or above the value, and per block of the brick (in the order
    /// [`surface_boxes`] lists them) the cells that are: bit `dx + 2 dy + 4 dz`.
    bricks: Vec<(u32, Box<[u8]>)>,
    /// What every box is cut to: the union of the supports of the cells at or below the
    /// value, within the data's bounds.
    clip: Aabb,
}

impl SurfaceBoxes {
    /// The surface boxes of field `f` at `iso` ([`surface_boxes`]); none for a missing
    /// field or a value that is not finite.
    pub fn of(vol: &Volume, f: usize, iso: f64) -> SurfaceBoxes {
        if f >= vol.fields.len() || !iso.is_finite() {
            return SurfaceBoxes {
                bricks: Vec::new(),
                clip: Aabb::default(),
            };
        }
        Self::of_reading(vol, f, iso, &bricks_below(vol, f, iso))
    }

    /// [`SurfaceBoxes::of`], reading the cells of every brick but those `below_only` marks.
    fn of_reading(vol: &Volume, f: usize, iso: f64, below_only: &[bool]) -> SurfaceBoxes {
        use rayon::prelude::*;
        let per_brick: Vec<(Option<Box<[u8]>>, Aabb)> = (0..vol.brick_count() as u32)
            .into_par_iter()
            .map(|b| {
                // Every brick by index, not through a region's list: checked here when
                // the file was opened to be checked where it is read.
                let Some(br) = vol.brick_checked(b) else {
                    return (None, Aabb::default());
                };
                let [nx, ny, nz] = br.dims;
                if below_only[b as usize] {
                    // The box the loop below would grow from every cell, from its corners.
                    let last = [nx, ny, nz].map(|n| (n - 1).max(0) as f64);
                    let mut below = Aabb::default();
                    if nx > 0 && ny > 0 && nz > 0 {
                        for c in [[0.0; 3], last] {
                            let centre: [f64; 3] =
                                std::array::from_fn(|a| br.origin[a] + c[a] * br.w);
                            below.grow(centre, br.w);
                        }
                    }
                    return (None, below);
                }
                let nb = br.dims.map(|n| (n + BLOCK - 1) / BLOCK);
                let mut above = vec![0u8; (nb[0] * nb[1] * nb[2]) as usize];
                let mut below = Aabb::default();
                let mut idx = br.first;
                for k in 0..nz {
                    for j in 0..ny {
                        for i in 0..nx {
                            let v = f64::from(vol.value(f, idx));
                            idx += 1;
                            if v.is_nan() {
                                continue;
                            }
                            if v >= iso {
                                let block =
                                    (i / BLOCK) + nb[0] * ((j / BLOCK) + nb[1] * (k / BLOCK));
                                let bit = (i % BLOCK) + BLOCK * ((j % BLOCK) + BLOCK * (k % BLOCK));
                                above[block as usize] |= 1 << bit;
                            }
                            if v <= iso {
                                let c = [i, j, k].map(|n| n as f64);
                                let centre: [f64; 3] =
                                    std::array::from_fn(|a| br.origin[a] + c[a] * br.w);
                                below.grow(centre, br.w);
                            }
                        }
                    }
                }
                let any = above.iter().any(|&m| m != 0);
                (any.then(|| above.into_boxed_slice()), below)
            })
            .collect();
        let below = per_brick
            .iter()
            .fold(Aabb::default(), |u, (_, b)| u.union(*b));
        // Clip to the data too: a support reaches half a cell past the bounds.
        let clip = Aabb {
            min: std::array::from_fn(|a| below.min[a].max(vol.bounds_min[a])),
            max: std::array::from_fn(|a| below.max[a].min(vol.bounds_max[a])),
        };
        let bricks = per_brick
            .into_iter()
            .enumerate()
            .filter_map(|(b, (above, _))| Some((b as u32, above?)))
            .collect();
        SurfaceBoxes { bricks, clip }
    }

    /// Every box (local frame of `vol`, the volume they were made from), brick after brick
    /// and block after block.
    pub fn iter<'a>(&'a self, vol: &'a Volume) -> impl Iterator<Item = ([f64; 3], [f64; 3])> + 'a {
        self.bricks
            .iter()
            .flat_map(move |(b, masks)| self.brick_boxes(vol, *b, masks))
    }

    /// The boxes of brick `b`'s blocks whose cells `masks` marks, block after block.
    fn brick_boxes<'a>(
        &'a self,
        vol: &'a Volume,
        b: u32,
        masks: &'a [u8],
    ) -> impl Iterator<Item = ([f64; 3], [f64; 3])> + 'a {
        let br = vol.brick(b);
        let nb = br.dims.map(|n| (n + BLOCK - 1) / BLOCK);
        masks.iter().enumerate().filter_map(move |(block, &mask)| {
            if mask == 0 {
                return None;
            }
            let block = block as i64;
            let at = [
                block % nb[0],
                (block / nb[0]) % nb[1],
                block / (nb[0] * nb[1]),
            ];
            // A cell's support edges grow with its index (every step of their
            // arithmetic is monotonic), so the box of the marked cells is that of
            // their lowest and highest index per axis.
            let mut above = Aabb::default();
            for corner in [low_cell(mask), high_cell(mask)] {
                let c: [f64; 3] = std::array::from_fn(|a| (at[a] * BLOCK + corner[a]) as f64);
                let centre: [f64; 3] = std::array::from_fn(|a| br.origin[a] + c[a] * br.w);
                above.grow(centre, br.w);
            }
            let lo: [f64; 3] = std::array::from_fn(|a| above.min[a].max(self.clip.min[a]));
            let hi: [f64; 3] = std::array::from_fn(|a| above.max[a].min(self.clip.max[a]));
            (0..3).all(|a| lo[a] <= hi[a]).then_some((lo, hi))
        })
    }

    /// [`fit_boxes_from`] for these boxes in world coordinates (`vol`'s), the same camera,
    /// with the two passes over the boxes (their union and count, then the merge) split
    /// over the bricks on all cores: a billion-cell file has tens of millions of boxes,
    /// and the passes took two to three seconds of its first picture on one core. The
    /// union, the count and each merged box are the same whatever order the bricks are
    /// taken in (minima and maxima of finite numbers), so the camera is too.
    pub fn fit(&self, vol: &Volume, aspect: f64, fill: f64, projection: Projection) -> Camera {
        let (union, merged) = self.merged(vol);
        fit_merged(union, &merged, aspect, fill, projection)
    }

    /// The union of the boxes (world frame) and the boxes [`merge_boxes`] makes of them,
    /// each pass split over the bricks.
    fn merged(&self, vol: &Volume) -> Gathered {
        use rayon::prelude::*;
        let world = |(lo, hi): ([f64; 3], [f64; 3])| {
            let (a, b) = (
                DVec3::from_array(vol.to_world(lo)),
                DVec3::from_array(vol.to_world(hi)),
            );
            ordered(a, b)
        };
        let (count, union) = self
            .bricks
            .par_iter()
            .map(|(b, masks)| {
                self.brick_boxes(vol, *b, masks)
                    .filter_map(world)
                    .fold((0usize, None), |(n, u), bx| (n + 1, union_with(u, bx)))
            })
            .reduce(
                || (0, None),
                |(n, u), (m, v)| (n + m, v.map_or(u, |v| union_with(u, v))),
            );
        let Some(bounds) = union else {
            return (None, Vec::new());
        };
        let merged = if count <= MAX_FIT_BOXES {
            self.iter(vol).filter_map(world).collect()
        } else {
            let grid = self
                .bricks
                .par_iter()
                .fold(MergeGrid::new, |mut grid, (b, masks)| {
                    for (a, b) in self.brick_boxes(vol, *b, masks).filter_map(world) {
                        grid.add(bounds, a, b);
                    }
                    grid
                })
                .reduce(MergeGrid::new, MergeGrid::join);
            grid.boxes()
        };
        (union, merged)
    }

    /// Calls `each` with every box, as [`SurfaceBoxes::iter`] gives them.
    pub fn for_each(&self, vol: &Volume, mut each: impl FnMut([f64; 3], [f64; 3])) {
        self.iter(vol).for_each(|(lo, hi)| each(lo, hi));
    }

    /// Whether there is no box: no cell on both sides of the value (an empty picture).
    pub fn is_empty(&self, vol: &Volume) -> bool {
        self.iter(vol).next().is_none()
    }
}

/// Cells of a 2³ block: bit `dx + 2 dy + 4 dz` of a mask. The bits with offset 1 along
/// each axis.
const UPPER: [u8; 3] = [0b1010_1010, 0b1100_1100, 0b1111_0000];

/// Per axis, the lowest offset of a cell `mask` marks (not empty).
fn low_cell(mask: u8) -> [i64; 3] {
    UPPER.map(|upper| i64::from(mask & !upper == 0))
}

/// Per axis, the highest offset of a cell `mask` marks (not empty).
fn high_cell(mask: u8) -> [i64; 3] {
    UPPER.map(|upper| i64::from(mask & upper != 0))
}

/// Per brick, whether every region that lists it has field `f`'s range below `iso`
/// (strictly, and not NaN): then so has every cell of the brick, since each cell lies in
/// the support of one of them. One pass over the regions' brick lists and ranges, which
/// are small beside the values.
fn bricks_below(vol: &Volume, f: usize, iso: f64) -> Vec<bool> {
    // 0: listed by no region yet, 1: every region so far below, 2: some region not.
    let mut state = vec![0u8; vol.brick_count()];
    for r in 0..vol.region_count() {
        let [_, max] = vol.range(r, f);
        let below = f64::from(max) < iso;
        for id in vol.region_brick_ids(r) {
            if let Some(s) = state.get_mut(id.to_native() as usize) {
                *s = if below && *s != 2 { 1 } else { 2 };
            }
        }
    }
    state.into_iter().map(|s| s == 1).collect()
}

/// Side, in cells, of the blocks of a brick that [`surface_boxes`] bounds separately:
/// small enough to follow a ring's curve inside a brick (whole 8³ bricks made a ring in
/// a 32³ grid fill 55 % of the image width where its blocks fill more), large enough
/// that the list stays a small fraction of the cells.
const BLOCK: i64 = 2;
const _: () = assert!(BLOCK == 2, "a block's cells are one byte of SurfaceBoxes");

/// The bounding box of `boxes`, `None` for none.
pub fn union(boxes: &[([f64; 3], [f64; 3])]) -> Option<([f64; 3], [f64; 3])> {
    let u = boxes.iter().fold(Aabb::default(), |u, (lo, hi)| {
        u.union(Aabb { min: *lo, max: *hi })
    });
    (0..3)
        .all(|a| u.min[a] <= u.max[a])
        .then_some((u.min, u.max))
}

/// An axis-aligned box, empty (`min > max`) until grown.
#[derive(Clone, Copy)]
struct Aabb {
    min: [f64; 3],
    max: [f64; 3],
}

impl Default for Aabb {
    fn default() -> Self {
        Aabb {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        }
    }
}

impl Aabb {
    fn grow(&mut self, centre: [f64; 3], half: f64) {
        for a in 0..3 {
            self.min[a] = self.min[a].min(centre[a] - half);
            self.max[a] = self.max[a].max(centre[a] + half);
        }
    }

    fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: std::array::from_fn(|a| self.min[a].min(o.min[a])),
            max: std::array::from_fn(|a| self.max[a].max(o.max[a])),
        }
    }
}

/// A camera looking at the box `min..max` (world) from [`Camera::frame`]'s direction, with
/// the box's projection centred in an image of `aspect` = width / height and filling
/// `fill` of its width or height, whichever binds. `projection` picks the kind: a
/// perspective one keeps its field of view, an orthographic one gets the width that fits.
///
/// [`Camera::frame`] fits the corners into a square with a margin, which leaves a wide
/// image a third empty; here the look-at point moves so the projected box is centred
/// (a perspective projection of a box is not symmetric about its centre), and the
/// distance is refined a few times since the projected size goes as one over the depth.
/// The eye stays in front of every corner, so a very flat view fills less rather than
/// cutting the box.
pub fn fit(min: [f64; 3], max: [f64; 3], aspect: f64, fill: f64, projection: Projection) -> Camera {
    fit_boxes(&[(min, max)], aspect, fill, projection)
}

/// Most boxes [`fit_boxes`] fits one by one; more are merged first ([`merge_boxes`]).
const MAX_FIT_BOXES: usize = 4096;
/// Cells per axis of the grid [`merge_boxes`] merges boxes on (16³ = [`MAX_FIT_BOXES`]).
const MERGE_GRID: usize = 16;

/// The boxes `source` gives as they are when there are at most [`MAX_FIT_BOXES`] (`count`),
/// else merged: each box goes to the cell of a [`MERGE_GRID`]³ grid over their union
/// (`bounds`) that holds its centre, and each occupied cell becomes the union of its boxes.
/// Every box lies inside its merged box, so a camera that frames the merged boxes frames
/// them all, a little less tightly. A 262 M-cell file has millions of surface boxes, and
/// fitting their corners one by one (eight refinements over every corner) took 14 s of a
/// 30 s first frame.
fn merge_boxes(
    source: &BoxSource<'_>,
    count: usize,
    bounds: (DVec3, DVec3),
) -> Vec<(DVec3, DVec3)> {
    if count <= MAX_FIT_BOXES {
        let mut boxes = Vec::with_capacity(count);
        source(&mut |a, b| boxes.push((a, b)));
        return boxes;
    }
    let mut grid = MergeGrid::new();
    source(&mut |a, b| grid.add(bounds, a, b));
    grid.boxes()
}

/// What a camera fit reads of its boxes: their union (none when no box is finite) and the
/// boxes [`merge_boxes`] makes of them.
type Gathered = (Option<(DVec3, DVec3)>, Vec<(DVec3, DVec3)>);

/// The cells of [`merge_boxes`]' grid, each the union of the boxes whose centre it holds.
struct MergeGrid(Vec<Option<(DVec3, DVec3)>>);

impl MergeGrid {
    fn new() -> Self {
        MergeGrid(vec![None; MERGE_GRID * MERGE_GRID * MERGE_GRID])
    }

    /// Adds box `a..b` to the cell of the grid over `bounds` that holds its centre.
    fn add(&mut self, (lo, hi): (DVec3, DVec3), a: DVec3, b: DVec3) {
        let size = (hi - lo).max(DVec3::splat(f64::MIN_POSITIVE));
        let n = MERGE_GRID;
        let rel = ((0.5 * a + 0.5 * b - lo) / size * n as f64).to_array();
        let [i, j, k] = rel.map(|x| (x.max(0.0) as usize).min(n - 1));
        let cell = &mut self.0[i + n * (j + n * k)];
        *cell = Some(union_with(*cell, (a, b)).unwrap_or((a, b)));
    }

    /// Both grids' boxes, cell by cell.
    fn join(mut self, other: MergeGrid) -> MergeGrid {
        for (c, o) in self.0.iter_mut().zip(other.0) {
            if let Some(o) = o {
                *c = union_with(*c, o);
            }
        }
        self
    }

    /// The occupied cells' boxes, in cell order.
    fn boxes(self) -> Vec<(DVec3, DVec3)> {
        self.0.into_iter().flatten().collect()
    }
}

/// `u` grown by box `b` (or `b` when `u` is none).
fn union_with(u: Option<(DVec3, DVec3)>, (a, b): (DVec3, DVec3)) -> Option<(DVec3, DVec3)> {
    Some(u.map_or((a, b), |(lo, hi)| (lo.min(a), hi.max(b))))
}

/// A box with its corners ordered; none when a corner is not finite.
fn ordered(a: DVec3, b: DVec3) -> Option<(DVec3, DVec3)> {
    let (lo, hi) = (a.min(b), a.max(b));
    (lo.is_finite() && hi.is_finite()).then_some((lo, hi))
}

/// Boxes given one at a time to the function it is called with, as often as it is called
/// (the same boxes, in the same order): what [`fit_boxes_from`] fits, without a list of
/// them all.
pub type BoxSource<'a> = dyn Fn(&mut dyn FnMut(DVec3, DVec3)) + 'a;

/// [`fit`] for the union of `boxes` (such as [`surface_boxes`]): the camera looks from
/// the direction [`Camera::frame`] takes for their bounding box, and every corner of every
/// box counts for centring and filling, so a structure whose bounding box has empty
/// corners (a ring, a tilted row of rings) still fills the image. No boxes, or
/// non-finite ones, frame the unit box.
pub fn fit_boxes(
    boxes: &[([f64; 3], [f64; 3])],
    aspect: f64,
    fill: f64,
    projection: Projection,
) -> Camera {
    let v = DVec3::from_array;
    fit_boxes_from(
        &|each: &mut dyn FnMut(DVec3, DVec3)| {
            for (a, b) in boxes {
                each(v(*a), v(*b));
            }
        },
        aspect,
        fill,
        projection,
    )
}

/// [`fit_boxes`] for the boxes `source` gives (world frame): read twice, once for their
/// union and count, once to merge them, so that tens of millions of them ([`SurfaceBoxes`])
/// need not be listed.
pub fn fit_boxes_from(
    source: &BoxSource<'_>,
    aspect: f64,
    fill: f64,
    projection: Projection,
) -> Camera {
    // Every box with its corners ordered; boxes with a corner not finite are left out.
    let ordered = |each: &mut dyn FnMut(DVec3, DVec3)| {
        source(&mut |a, b| {
            if let Some((lo, hi)) = ordered(a, b) {
                each(lo, hi);
            }
        })
    };
    let (union, boxes) = gather(&ordered);
    fit_merged(union, &boxes, aspect, fill, projection)
}

/// The union of the boxes `source` gives and the boxes [`merge_boxes`] makes of them.
fn gather(source: &BoxSource<'_>) -> Gathered {
    let mut count = 0usize;
    let mut union: Option<(DVec3, DVec3)> = None;
    source(&mut |a, b| {
        count += 1;
        union = union_with(union, (a, b));
    });
    let boxes = match union {
        Some(bounds) => merge_boxes(source, count, bounds),
        None => Vec::new(),
    };
    (union, boxes)
}

/// The camera of [`fit_boxes_from`] for boxes whose union is `union` (none: no finite
/// box), merged into `boxes` ([`merge_boxes`]).
fn fit_merged(
    union: Option<(DVec3, DVec3)>,
    boxes: &[(DVec3, DVec3)],
    aspect: f64,
    fill: f64,
    projection: Projection,
) -> Camera {
    let (min, max) = union.map_or(([f64::NAN; 3], [f64::NAN; 3]), |(a, b)| {
        (a.to_array(), b.to_array())
    });
    let v = DVec3::from_array;
    let mut cam = Camera::frame(min, max);
    let (fov_deg, ortho) = match projection {
        Projection::Perspective { fov_deg } if fov_deg > 0.0 && fov_deg < 180.0 => (fov_deg, false),
        Projection::Perspective { .. } => (crate::camera::DEFAULT_FOV_DEG, false),
        Projection::Orthographic { .. } => (crate::camera::DEFAULT_FOV_DEG, true),
    };
    let aspect = if aspect.is_finite() && aspect > 0.0 {
        aspect
    } else {
        1.0
    };
    let fill = if fill.is_finite() && fill > 0.0 {
        fill.min(1.0)
    } else {
        DEFAULT_FILL
    };
    let (lo, hi) = (v(min), v(max));
    if !(lo.is_finite() && hi.is_finite()) {
        return cam;
    }
    let centre = 0.5 * lo + 0.5 * hi;
    let half = 0.5 * hi - 0.5 * lo;
    // Corners relative to the centre, so boxes far from the origin keep their precision.
    let corners: Vec<DVec3> = boxes
        .iter()
        .flat_map(|&(a, b)| {
            (0..8).map(move |i| {
                DVec3::new(
                    if i & 1 == 0 { a.x } else { b.x },
                    if i & 2 == 0 { a.y } else { b.y },
                    if i & 4 == 0 { a.z } else { b.z },
                ) - centre
            })
        })
        .collect();
    let b = cam.basis();
    if ortho {
        // Parallel rays: centre the projected extents, width from the binding axis.
        let (u0, u1) = extent(&corners, |c| c.dot(b.right));
        let (w0, w1) = extent(&corners, |c| c.dot(b.up));
        let shift = 0.5 * (u0 + u1) * b.right + 0.5 * (w0 + w1) * b.up;
        let width = ((u1 - u0).max((w1 - w0) * aspect) / fill).max(f64::MIN_POSITIVE);
        let look = centre + shift;
        let dist = scaled_length(v(cam.eye) - v(cam.look_at));
        cam.look_at = look.to_array();
        cam.eye = (look - dist * b.forward).to_array();
        cam.projection = Projection::Orthographic { width };
        return cam;
    }
    let tan_v = (0.5 * fov_deg.to_radians()).tan();
    let tan_h = tan_v * aspect;
    // Look-at relative to the centre, and distance from it to the eye.
    let mut look = DVec3::ZERO;
    let mut dist = scaled_length(v(cam.eye) - v(cam.look_at));
    for _ in 0..8 {
        // The eye must stay in front of every corner (depth > 5 % of the box's size).
        let nearest = corners
            .iter()
            .map(|c| (*c - look).dot(b.forward))
            .fold(f64::NEG_INFINITY, f64::max);
        // The largest half-side, not the diagonal: its square overflows for boxes far out.
        let min_dist = nearest + 0.05 * half.abs().max_element().max(f64::MIN_POSITIVE);
        dist = dist.max(min_dist);
        let eye = look - dist * b.forward;
        let proj = |c: &DVec3, axis: DVec3, t: f64| {
            let d = *c - eye;
            d.dot(axis) / (d.dot(b.forward) * t)
        };
        let (u0, u1) = extent(&corners, |c| proj(c, b.right, tan_h));
        let (w0, w1) = extent(&corners, |c| proj(c, b.up, tan_v));
        let size = (u1 - u0).max(w1 - w0) * 0.5;
        if !(size.is_finite() && size > 0.0) {
            break;
        }
        // Move sideways so the middle of the projection lands on the image centre, then
        // scale the distance towards the wanted size.
        look += dist * (0.5 * (u0 + u1) * tan_h * b.right + 0.5 * (w0 + w1) * tan_v * b.up);
        dist = (dist * size / fill).max(min_dist);
    }
    let look = centre + look;
    let eye = look - dist * b.forward;
    cam.projection = Projection::Perspective { fov_deg };
    // Boxes so far out that squares overflow (the refinement, or validation's check of
    // the view direction) keep [`Camera::frame`]'s pose, which is built for them.
    if look.is_finite() && eye.is_finite() && centre.abs().max_element() < 1e150 {
        cam.look_at = look.to_array();
        cam.eye = eye.to_array();
    }
    cam
}

/// Length of `d` without squaring its components (they overflow for boxes far out).
fn scaled_length(d: DVec3) -> f64 {
    let m = d.abs().max_element();
    if m > 0.0 && m.is_finite() {
        m * (d / m).length()
    } else {
        d.length()
    }
}

/// Smallest and largest of `f` over the corners.
fn extent(corners: &[DVec3], f: impl Fn(&DVec3) -> f64) -> (f64, f64) {
    corners
        .iter()
        .map(f)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Projected extents of the box's corners in the image, in pixels.
    fn projected(cam: &Camera, min: [f64; 3], max: [f64; 3], w: u32, h: u32) -> [f64; 4] {
        let b = cam.basis();
        let eye = DVec3::from_array(cam.eye);
        let Projection::Perspective { fov_deg } = cam.projection else {
            unreachable!()
        };
        let tan_v = (0.5 * fov_deg.to_radians()).tan();
        let aspect = f64::from(w) / f64::from(h);
        let mut e = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for i in 0..8 {
            let c = DVec3::new(
                if i & 1 == 0 { min[0] } else { max[0] },
                if i & 2 == 0 { min[1] } else { max[1] },
                if i & 4 == 0 { min[2] } else { max[2] },
            );
            let d = c - eye;
            let z = d.dot(b.forward);
            let x = (d.dot(b.right) / (z * tan_v * aspect) + 1.0) * 0.5 * f64::from(w);
            let y = (1.0 - d.dot(b.up) / (z * tan_v)) * 0.5 * f64::from(h);
            e = [e[0].min(x), e[1].max(x), e[2].min(y), e[3].max(y)];
        }
        e
    }

    fn persp(fov_deg: f64) -> Projection {
        Projection::Perspective { fov_deg }
    }

    #[test]
    fn the_fitted_box_is_centred_and_fills_the_binding_axis() {
        for (min, max) in [
            ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
            ([-1.0, -0.2, -0.2], [4.0, 0.2, 0.3]),
            ([1e6, 1e6, 1e6], [1e6 + 0.1, 1e6 + 3.0, 1e6 + 0.2]),
        ] {
            let (w, h) = (800, 600);
            let cam = fit(min, max, 800.0 / 600.0, 0.8, persp(35.0));
            let [x0, x1, y0, y1] = projected(&cam, min, max, w, h);
            let fw = (x1 - x0) / f64::from(w);
            let fh = (y1 - y0) / f64::from(h);
            assert!(
                (fw.max(fh) - 0.8).abs() < 0.02,
                "{min:?}: fills {fw:.3} × {fh:.3}"
            );
            assert!(
                ((x0 + x1) / 2.0 - 400.0).abs() < 4.0,
                "{min:?}: x {x0}..{x1}"
            );
            assert!(
                ((y0 + y1) / 2.0 - 300.0).abs() < 3.0,
                "{min:?}: y {y0}..{y1}"
            );
        }
    }

    /// Past [`MAX_FIT_BOXES`] the boxes are merged before fitting: every corner of every
    /// one of 100 000 small boxes along a tilted ring still lands inside the image, and
    /// the ring still fills most of it.
    #[test]
    fn many_boxes_are_merged_and_all_stay_in_the_picture() {
        let boxes: Vec<([f64; 3], [f64; 3])> = (0..100_000)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / 100_000.0;
                let c = [10.0 + 3.0 * a.cos(), -2.0 + 3.0 * a.sin(), 0.8 * a.sin()];
                (c.map(|x| x - 0.01), c.map(|x| x + 0.01))
            })
            .collect();
        let (w, h) = (800, 600);
        let cam = fit_boxes(&boxes, 800.0 / 600.0, 0.8, persp(35.0));
        let mut all = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for (min, max) in &boxes {
            let e = projected(&cam, *min, *max, w, h);
            all = [
                all[0].min(e[0]),
                all[1].max(e[1]),
                all[2].min(e[2]),
                all[3].max(e[3]),
            ];
        }
        assert!(
            all[0] >= 0.0 && all[1] <= f64::from(w) && all[2] >= 0.0 && all[3] <= f64::from(h),
            "{all:?}"
        );
        let fill = ((all[1] - all[0]) / f64::from(w)).max((all[3] - all[2]) / f64::from(h));
        assert!(fill > 0.6, "fills {fill:.3}");
        let ten = |each: &mut dyn FnMut(DVec3, DVec3)| {
            for _ in 0..10 {
                each(DVec3::ZERO, DVec3::ONE);
            }
        };
        assert!(merge_boxes(&ten, 10, (DVec3::ZERO, DVec3::ONE)).len() == 10);
    }

    #[test]
    fn an_orthographic_fit_spans_the_box() {
        let ortho = Projection::Orthographic { width: 1.0 };
        let cam = fit([0.0; 3], [2.0, 1.0, 1.0], 1.0, 0.5, ortho);
        let Projection::Orthographic { width } = cam.projection else {
            panic!("not orthographic")
        };
        assert!(width > 2.0 && width < 8.0, "{width}");
        // Degenerate input still gives a usable camera.
        let c = fit([f64::NAN; 3], [1.0; 3], 0.0, f64::NAN, persp(f64::NAN));
        assert!(c.eye.iter().all(|x| x.is_finite()));
    }

    #[test]
    fn the_surface_box_holds_the_surface_and_not_the_domain() {
        use crate::testvol;
        // A ball of radius 3 around (16, 16, 16) in a 32³ domain.
        let ball = |p: [f64; 3]| {
            let r2: f64 = (0..3).map(|a| (p[a] - 16.0) * (p[a] - 16.0)).sum();
            1.0 - r2 / 9.0
        };
        let file = testvol::nested(16, [0.0; 3], &[("q", &ball)], 8);
        let view = testvol::open(&file).expect("open");
        let vol = Volume::new(&view).expect("volume");
        let boxes = surface_boxes(&vol, 0, 0.0);
        assert!(boxes.len() > 1, "{boxes:?}");
        let (lo, hi) = union(&boxes).expect("a surface");
        for a in 0..3 {
            let (l, h) = (vol.to_world(lo)[a], vol.to_world(hi)[a]);
            assert!(l <= 13.0 && h >= 19.0, "axis {a}: {l}..{h} misses the ball");
            assert!(l >= 11.0 && h <= 21.0, "axis {a}: {l}..{h} is loose");
        }
        assert!(surface_boxes(&vol, 0, 2.0).is_empty(), "above the maximum");
        assert!(surface_boxes(&vol, 0, -1e9).is_empty(), "below the minimum");
        assert!(surface_boxes(&vol, 5, 0.0).is_empty(), "no such field");
    }

    /// The box of a block's marked cells from their lowest and highest offsets is the box
    /// grown from every one of them, bit for bit, for every mask, at awkward origins and
    /// widths.
    #[test]
    fn a_blocks_box_from_its_extreme_cells_is_the_box_of_all_of_them() {
        for (origin, w) in [
            (0.0, 1.0),
            (1e6 + 0.1, 0.1),
            (-3.7, 1.0 / 3.0),
            (1e-300, 7e-301),
        ] {
            for at in [0i64, 5] {
                for mask in 1u8..=255 {
                    let centre = |c: [i64; 3]| -> [f64; 3] {
                        std::array::from_fn(|a| origin + ((at * BLOCK + c[a]) as f64) * w)
                    };
                    let mut all = Aabb::default();
                    for bit in 0..8 {
                        if mask & (1 << bit) != 0 {
                            all.grow(centre([bit & 1, (bit >> 1) & 1, bit >> 2]), w);
                        }
                    }
                    let mut ends = Aabb::default();
                    for c in [low_cell(mask), high_cell(mask)] {
                        ends.grow(centre(c), w);
                    }
                    assert_eq!((all.min, all.max), (ends.min, ends.max), "mask {mask:08b}");
                }
            }
        }
    }

    /// Bricks whose regions all range below the value are not read, and the boxes are the
    /// same as when every cell is read: on three levels, at values that cut many bricks,
    /// few, none, and at a brick's exact maximum.
    #[test]
    fn bricks_below_the_value_are_not_read_and_change_nothing() {
        use crate::testvol;
        let waves = |p: [f64; 3]| (0.4 * p[0]).sin() * (0.3 * p[1]).cos() + 0.05 * p[2];
        let file = testvol::nested(16, [0.0; 3], &[("q", &waves)], 4);
        let view = testvol::open(&file).expect("open");
        let vol = Volume::new(&view).expect("volume");
        let max = (0..vol.region_count())
            .map(|r| vol.range(r, 0)[1])
            .fold(f32::NEG_INFINITY, f32::max);
        let mut skipped_some = false;
        for iso in [-0.5, 0.0, 0.5, 0.9, f64::from(max), f64::from(max) + 1.0] {
            let below = bricks_below(&vol, 0, iso);
            let skipped = below.iter().filter(|&&b| b).count();
            skipped_some |= skipped > 0 && skipped < below.len();
            let read_all = vec![false; vol.brick_count()];
            let mut all = Vec::new();
            SurfaceBoxes::of_reading(&vol, 0, iso, &read_all)
                .for_each(&vol, |lo, hi| all.push((lo, hi)));
            assert_eq!(
                surface_boxes(&vol, 0, iso),
                all,
                "iso {iso}: {skipped} of {} bricks skipped",
                below.len()
            );
            // A skipped brick has no cell at or above the value.
            for (b, _) in below.iter().enumerate().filter(|(_, &s)| s) {
                let br = vol.brick(b as u32);
                let n = (br.dims[0] * br.dims[1] * br.dims[2]) as usize;
                for idx in br.first..br.first + n {
                    assert!(f64::from(vol.value(0, idx)) < iso, "brick {b}");
                }
            }
        }
        assert!(skipped_some, "no value skipped part of the bricks");
    }

    /// [`SurfaceBoxes::fit`], which splits its passes over the bricks, gives the camera
    /// [`fit_boxes_from`] gives for the same boxes read one by one: with few boxes (kept
    /// as they are) and with many (merged on the grid), perspective and orthographic.
    #[test]
    fn the_surface_fit_over_all_cores_is_the_one_box_at_a_time_fit() {
        use crate::testvol;
        let waves =
            |p: [f64; 3]| (0.9 * p[0]).sin() * (0.7 * p[1]).cos() + 0.2 * (0.5 * p[2]).sin();
        let file = testvol::nested(24, [0.3, -2.0, 5.0], &[("q", &waves)], 3);
        let view = testvol::open(&file).expect("open");
        let vol = Volume::new(&view).expect("volume");
        let ortho = Projection::Orthographic { width: 1.0 };
        let mut sizes = Vec::new();
        for iso in [0.0, 0.7, 1.05] {
            let boxes = SurfaceBoxes::of(&vol, 0, iso);
            let n = boxes.iter(&vol).count();
            sizes.push(n);
            let v = DVec3::from_array;
            let source = |each: &mut dyn FnMut(DVec3, DVec3)| {
                boxes.for_each(&vol, |lo, hi| {
                    each(v(vol.to_world(lo)), v(vol.to_world(hi)))
                });
            };
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(3)
                .build()
                .expect("pool");
            // Grids of boxes taken alternately (so that both hold boxes of every cell)
            // join into the grid of them all.
            if let (Some(bounds), true) = (union(&boxes.iter(&vol).collect::<Vec<_>>()), n > 1) {
                let bounds = (v(bounds.0), v(bounds.1));
                let (mut all, mut even, mut odd) =
                    (MergeGrid::new(), MergeGrid::new(), MergeGrid::new());
                for (i, (lo, hi)) in boxes.iter(&vol).enumerate() {
                    let (a, b) = (v(lo), v(hi));
                    all.add(bounds, a, b);
                    [&mut even, &mut odd][i % 2].add(bounds, a, b);
                }
                assert_eq!(even.join(odd).boxes(), all.boxes(), "iso {iso}");
            }
            // The same union and merged boxes, in the same order (the corners are
            // ordered and finite here, so the one-at-a-time pass takes them as given).
            assert_eq!(
                pool.install(|| boxes.merged(&vol)),
                gather(&source),
                "iso {iso}"
            );
            for projection in [persp(30.0), ortho] {
                let one = fit_boxes_from(&source, 1.5, 0.8, projection);
                let all = pool.install(|| boxes.fit(&vol, 1.5, 0.8, projection));
                assert_eq!(
                    (all.eye, all.look_at, all.up, all.projection),
                    (one.eye, one.look_at, one.up, one.projection),
                    "iso {iso}, {n} boxes"
                );
            }
        }
        assert!(
            sizes.iter().any(|&n| n > MAX_FIT_BOXES)
                && sizes.iter().any(|&n| (1..=MAX_FIT_BOXES).contains(&n)),
            "{sizes:?}"
        );
    }
}
