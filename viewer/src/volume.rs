//! Read access to an opened `.qbk` file, laid out for the ray caster: the file, and
//! nothing that depends on how it is viewed.
//!
//! Zero-copy: bricks, regions, brick lists, the KD-tree and the field values are all read
//! from the archive as stored (the page cache, or the memory map, is the only copy), so
//! opening costs nothing proportional to the file beyond the checks
//! [`format::BrickFileView`] runs once; for a view opened with
//! [`format::Structure::OnUse`] (every command that renders) not even those: the volume
//! checks each region and the KD-tree where it first reads them. The only conversion is
//! to a local frame centred
//! on the data, applied as each number is read (`local = stored − frame`), so that data
//! placed at 1e6 keeps sub-cell precision; the traversal and point location use the same
//! subtraction ([`format::kd`]), so their edge rules agree.
//!
//! A [`Volume`] is immutable once built and shared by every view of the file. What a view
//! adds (the tree packed with its iso field's ranges, the regions that can hold its iso
//! value, the box of the regions that can contribute to its band) belongs to that view,
//! in its [`crate::accel::Accel`]. The volume only derives, on first use, what depends on
//! the file alone: the tree point location descends (the first packed one, see
//! [`Volume::region_at`]), a byte a region of step width ([`Volume::step_width`]), and,
//! for tools and tests only, the table of every region's box ([`Volume::region`]).

use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, OnceLock};

use format::kd::Descent;
use format::sequence::FieldRange;
use format::{ArchivedBrickFile, BrickFileView};
use rkyv::Archived;

use crate::fields::UnknownField;
use crate::packed::Packed;

/// Archived `f32` as stored in the file.
pub(crate) type StoredF32 = rkyv::Archived<f32>;

/// Why a volume could not be built from a file [`BrickFileView`] has validated (every index
/// the volume reads was checked there, or is checked where it is first read): only data
/// placed where double precision cannot
/// resolve its cells.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    /// The data lies too far from the origin for its cell width (see
    /// [`format::MAX_REACH_LOG2`]): positions there cannot be told apart in double
    /// precision, so no view of it (and no default camera) would mean anything.
    #[error(
        "the data's bounds {min:?}..{max:?} reach {} cells of the finest width {finest} from the origin, more than the 2^{} within which double precision places cells to 1/4096 of a cell; re-bake the data nearer the origin",
        cells(*reach / *finest),
        format::MAX_REACH_LOG2
    )]
    OutOfReach {
        min: [f64; 3],
        max: [f64; 3],
        reach: f64,
        finest: f64,
    },
}

/// A cell count for messages: plain below a million, else `1.2e13`.
fn cells(x: f64) -> String {
    if x < 1e6 {
        format!("{x:.0}")
    } else {
        format!("{x:.1e}")
    }
}

/// A brick in the local frame, as the reconstruction reads it.
#[derive(Debug, Clone, Copy)]
pub struct BrickN {
    /// Centre of the first cell, local frame.
    pub origin: [f64; 3],
    pub w: f64,
    pub(crate) inv_w: f64,
    pub dims: [i64; 3],
    pub first: usize,
    pub level: u32,
}

/// A region and a box within it (local frame, half-open): what a lookup that found the
/// region knows of it, handed to the next lookup near the same point so that it can skip a
/// descent of the tree when the point lies in the box. The box is the region's whole box
/// where the finder knew it, possibly smaller (never larger), or empty (`min > max`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionBox {
    pub region: u32,
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl RegionBox {
    /// Region `region` with no box known.
    pub fn unknown(region: u32) -> RegionBox {
        RegionBox {
            region,
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        }
    }

    /// Whether the local point `q` lies in the box (so in the region).
    #[inline]
    pub fn holds(&self, q: &[f64; 3]) -> bool {
        (0..3).all(|a| q[a] >= self.min[a] && q[a] < self.max[a])
    }
}

/// How many region boxes a [`NearRegions`] keeps.
const NEAR_REGIONS: usize = 8;

/// The last few regions, with their whole boxes, that points beside a shading normal's
/// hit were found in. The hits of neighbouring pixels are a fraction of a cell apart, so
/// their neighbour points mostly fall in the same few regions, and a box test replaces
/// the descent of the tree that finding one from the hit's descent costs (regions are a
/// few cells wide, so most of the six points lie outside the hit's own region). A box
/// is the region's leaf cell: a point it holds descends to that region, so the regions
/// found are the ones a descent finds.
#[derive(Debug, Clone)]
pub(crate) struct NearRegions {
    boxes: [RegionBox; NEAR_REGIONS],
    len: usize,
    next: usize,
}

impl Default for NearRegions {
    fn default() -> Self {
        NearRegions {
            boxes: [RegionBox::unknown(0); NEAR_REGIONS],
            len: 0,
            next: 0,
        }
    }
}

impl NearRegions {
    /// A kept box holding `q`.
    #[inline]
    pub(crate) fn find_box(&self, q: &[f64; 3]) -> Option<RegionBox> {
        self.boxes[..self.len].iter().find(|b| b.holds(q)).copied()
    }

    /// Keeps `b`, in place of the one kept longest once full.
    #[inline]
    pub(crate) fn keep(&mut self, b: RegionBox) {
        self.boxes[self.next] = b;
        self.next = (self.next + 1) % NEAR_REGIONS;
        self.len = (self.len + 1).min(NEAR_REGIONS);
    }
}

/// A region in the local frame.
#[derive(Debug, Clone, Copy)]
pub struct RegionN {
    pub min: [f64; 3],
    pub max: [f64; 3],
    /// Cell width of the finest brick of the region (the local sampling unit).
    pub finest_w: f64,
}

/// The volume as the ray caster sees it.
pub struct Volume<'a> {
    /// World position of the local frame's origin (`world = local + frame`).
    pub frame: [f64; 3],
    /// Union of supports, local frame.
    pub bounds_min: [f64; 3],
    pub bounds_max: [f64; 3],
    /// Name and range of every field, in the file's order (the values' index).
    pub fields: Vec<FieldRange>,
    pub(crate) values: Vec<&'a [StoredF32]>,
    pub(crate) file: &'a ArchivedBrickFile,
    /// Cell width per level.
    level_w: Vec<f64>,
    /// Every region's box (its KD leaf's cell) and step width, derived on first use: the
    /// file stores neither. 56 bytes a region (0.9 GB for a billion cells), so nothing a
    /// render does asks for it: the walks and descents that find a region find its box on
    /// the way ([`Volume::region_box_at`], the active tree's leaves), and a step width is
    /// read from the region's bricks. Tools and tests that list regions by index build it.
    region_table: OnceLock<Vec<RegionN>>,
    /// The KD-tree packed with one field's ranges, and that field, for point location
    /// ([`Volume::region_at`]): a denser read than the archived tree, which shading
    /// normals and refinement probes descend for every hit. Point location reads no
    /// ranges, so any field's packing serves: it is the first packed tree a view asks for
    /// ([`Volume::packed`]), whichever its field, or field 0's when a lookup comes first.
    /// So a view of another field than the first packs one tree, not two (about 40
    /// bytes a region: 0.6 GiB each for a billion cells). `None` for a file without
    /// fields (point location then reads the archived tree).
    locate: OnceLock<Option<(usize, Arc<Packed>)>>,
    /// Finest cell width in the file (reference length for opacity).
    pub finest_w: f64,
    /// Per region, what [`Volume::step_width`] found: its finest level + 1, [`NO_LEVEL`]
    /// for a region without bricks, 0 before it was asked (or for a level past 253,
    /// read each time). One byte a region, made on first use (16 MB for a billion cells).
    finest_levels: OnceLock<Box<[AtomicU8]>>,
    /// For a view opened with [`format::Structure::OnUse`], what has been checked so far;
    /// `None` when every index was checked at open.
    checks: Option<Checks>,
}

/// The checks of a view opened with [`format::Structure::OnUse`], run where the volume
/// first reads each part: a region (its list of bricks and those bricks) before its
/// bricks are read, the KD-tree before it is packed. A part that fails reads as empty
/// (nothing of it is indexed), and the first failure is kept for the command to report
/// after its frame ([`Volume::structure_error`]). So opening costs the same for any size,
/// and a frame checks only the regions it reads.
#[derive(Default)]
struct Checks {
    /// One bit a region, set once its check passed (2 MB for a billion cells).
    regions: OnceLock<Box<[AtomicU64]>>,
    /// Whether the KD-tree passed, once checked.
    kd: OnceLock<bool>,
    /// The first check that failed.
    broken: OnceLock<format::validate::ValidationError>,
}

/// [`Volume::finest_levels`] of a region that lists no brick.
const NO_LEVEL: u8 = u8::MAX;

/// Fills `table` from the walk of `tree` cut into subtrees, on `threads` threads, each
/// subtree's regions into its own stretch of the table; `false` (part of it filled) when
/// the regions are not numbered in leaf order, so that a subtree's are no stretch.
#[allow(clippy::too_many_arguments)]
fn fill_in_stretches<T: format::kd::KdTree + Copy + Send>(
    table: &mut [RegionN],
    tree: T,
    lo: [f64; 3],
    hi: [f64; 3],
    shift: [f64; 3],
    threads: usize,
    region: &(dyn Fn(u32, [f64; 3], [f64; 3]) -> RegionN + Sync),
) -> bool {
    use format::kd::LeafCells;
    // Several subtrees a thread, so that uneven ones even out.
    let depth = (threads * 8).next_power_of_two().trailing_zeros();
    // Each subtree's stretch: from its first region to the next subtree's first.
    let mut starts: Vec<(usize, LeafCells<T>)> = Vec::new();
    for part in LeafCells::split(tree, lo, hi, shift, depth) {
        let Some((first, _, _)) = part.clone().next() else {
            continue;
        };
        if starts.last().is_some_and(|&(s, _)| s >= first as usize) {
            return false;
        }
        starts.push((first as usize, part));
    }
    let mut work = Vec::new();
    let mut rest = table;
    let mut at = 0;
    for i in 0..starts.len() {
        let start = starts[i].0;
        let end = starts.get(i + 1).map_or(at + rest.len(), |s| s.0);
        if start < at || end > at + rest.len() {
            return false;
        }
        let (_, from_start) = std::mem::take(&mut rest).split_at_mut(start - at);
        let (stretch, after) = from_start.split_at_mut(end - start);
        rest = after;
        at = end;
        work.push((start, stretch));
    }
    let jobs = starts
        .into_iter()
        .zip(work)
        .map(|((_, part), (start, stretch))| {
            move || {
                for (r, min, max) in part {
                    let Some(slot) = (r as usize)
                        .checked_sub(start)
                        .and_then(|i| stretch.get_mut(i))
                    else {
                        return false;
                    };
                    *slot = region(r, min, max);
                }
                true
            }
        });
    format::kd::on_threads(jobs, threads)
        .into_iter()
        .all(|ordered| ordered)
}

impl<'a> Volume<'a> {
    /// The ray caster's view of a file that [`BrickFileView`] has validated: every index
    /// the hot loops use was checked there, once, or for a view opened with
    /// [`format::Structure::OnUse`] is checked by the volume where it first reads it
    /// ([`Checks`]). Reads nothing that grows with the data.
    pub fn new(view: &'a BrickFileView) -> Result<Volume<'a>, VolumeError> {
        let file = view.file();
        let b = &file.bounds;
        let bmin: [f64; 3] = std::array::from_fn(|a| b.min[a].to_native());
        let bmax: [f64; 3] = std::array::from_fn(|a| b.max[a].to_native());
        let frame: [f64; 3] = std::array::from_fn(|a| {
            let c = 0.5 * (bmin[a] + bmax[a]);
            if c.is_finite() {
                c
            } else {
                0.0
            }
        });
        let fields: Vec<FieldRange> = file
            .fields
            .iter()
            .map(|f| FieldRange {
                name: f.name.as_str().to_string(),
                min: f.min.to_native(),
                max: f.max.to_native(),
            })
            .collect();
        let values: Vec<&[StoredF32]> = file.fields.iter().map(|f| f.values.as_slice()).collect();
        let level_w: Vec<f64> = file
            .levels
            .iter()
            .map(|l| l.cell_width.to_native())
            .collect();
        // The finest width of a level that has bricks (a brick's width is its level's to
        // 1e-3, see `format::validate::check_brick`): read from the levels, not the
        // bricks, so that making a volume reads nothing that grows with the data.
        let finest_of = |with_bricks: bool| {
            file.levels
                .iter()
                .filter(|l| !with_bricks || l.bricks.to_native() > 0)
                .map(|l| l.cell_width.to_native())
                .fold(f64::INFINITY, f64::min)
        };
        let finest_w = match finest_of(true) {
            w if w.is_finite() => w,
            _ => finest_of(false),
        };
        let reach = bmin
            .iter()
            .chain(&bmax)
            .map(|x| x.abs())
            .fold(0.0f64, f64::max);
        if finest_w.is_finite() && reach / finest_w > (1u64 << format::MAX_REACH_LOG2) as f64 {
            return Err(VolumeError::OutOfReach {
                min: bmin,
                max: bmax,
                reach,
                finest: finest_w,
            });
        }
        Ok(Volume {
            frame,
            bounds_min: std::array::from_fn(|a| bmin[a] - frame[a]),
            bounds_max: std::array::from_fn(|a| bmax[a] - frame[a]),
            fields,
            values,
            file,
            level_w,
            region_table: OnceLock::new(),
            locate: OnceLock::new(),
            finest_levels: OnceLock::new(),
            finest_w: if finest_w.is_finite() { finest_w } else { 1.0 },
            checks: (view.structure() == format::Structure::OnUse).then(Checks::default),
        })
    }

    /// Index of the field called `name` (see [`crate::fields`]).
    pub fn field_index(&self, name: &str) -> Result<usize, UnknownField> {
        crate::fields::find(&self.fields, name).map(|(i, _)| i)
    }

    /// World → local frame.
    pub fn to_local(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| p[a] - self.frame[a])
    }

    /// Local frame → world.
    pub fn to_world(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| p[a] + self.frame[a])
    }

    /// The KD-tree packed with field `f`'s ranges, for a view's acceleration; `None` for
    /// a field the file does not have. The first one packed becomes the point-location
    /// tree too (see `locate`), shared.
    pub(crate) fn packed(&self, f: usize) -> Option<Arc<Packed>> {
        if f >= self.fields.len() {
            return None;
        }
        let (g, p) = self
            .locate
            .get_or_init(|| Some((f, Arc::new(self.pack(f)))))
            .as_ref()?;
        Some(if *g == f {
            Arc::clone(p)
        } else {
            Arc::new(self.pack(f))
        })
    }

    /// The file's tree packed with field `f`'s ranges, or an empty tree when the tree
    /// fails its check ([`Volume::kd_checked`]).
    fn pack(&self, f: usize) -> Packed {
        if self.kd_checked() {
            Packed::build(self.file, f)
        } else {
            Packed::empty()
        }
    }

    /// The point-location tree (the first packed tree, or field 0's), packed on first use.
    pub(crate) fn locate_tree(&self) -> Option<&Packed> {
        self.locate
            .get_or_init(|| (!self.fields.is_empty()).then(|| (0, Arc::new(self.pack(0)))))
            .as_ref()
            .map(|(_, p)| &**p)
    }

    /// The field the point-location tree was packed with (tests of what is packed).
    #[cfg(test)]
    pub(crate) fn locate_field(&self) -> Option<usize> {
        self.locate.get().and_then(|l| l.as_ref().map(|(f, _)| *f))
    }

    /// Number of bricks.
    pub fn brick_count(&self) -> usize {
        self.file.bricks.len()
    }

    /// Brick `b` in the local frame.
    #[inline(always)]
    pub fn brick(&self, b: u32) -> BrickN {
        let br = &self.file.bricks[b as usize];
        let w = br.cell_width.to_native();
        BrickN {
            origin: std::array::from_fn(|a| br.origin[a].to_native() - self.frame[a]),
            w,
            inv_w: br.inv_cell_width.to_native(),
            dims: std::array::from_fn(|a| i64::from(br.dims[a].to_native())),
            first: br.first_value.to_native() as usize,
            level: br.level.to_native(),
        }
    }

    /// Number of regions.
    pub fn region_count(&self) -> usize {
        self.file.regions.len()
    }

    /// Every region in the local frame, by index (derived on first use, one walk over
    /// the tree: a region's box is its leaf's cell, its step width its finest brick's
    /// level's; see `region_table`: for tools and tests, not for rendering).
    fn region_table(&self) -> &[RegionN] {
        self.region_table.get_or_init(|| {
            // A billion cells have tens of millions of regions: a second or more on one
            // core, in the first frame.
            let threads = if self.file.regions.len() >= 1 << 16 {
                std::thread::available_parallelism().map_or(1, |n| n.get())
            } else {
                1
            };
            self.derive_region_table(threads)
        })
    }

    /// The region table on `threads` threads: the KD walk cut into subtrees
    /// ([`format::kd::LeafCells::split`]), each filling its own stretch of the table. The
    /// regions of a subtree are a stretch of their own when the file numbers regions in
    /// leaf order (as the baker does); for a file that does not, one walk fills the table.
    /// Plain threads, not rayon: this runs inside a `OnceLock` initialiser, and a rayon
    /// worker waiting on its pool could be handed a task that asks for this very table.
    pub(crate) fn derive_region_table(&self, threads: usize) -> Vec<RegionN> {
        let file = self.file;
        let empty = RegionN {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
            finest_w: self.finest_w,
        };
        let mut table = vec![empty; file.regions.len()];
        if !self.kd_checked() {
            return table;
        }
        let b = &file.bounds;
        let (lo, hi): ([f64; 3], [f64; 3]) = (
            std::array::from_fn(|a| b.min[a].to_native()),
            std::array::from_fn(|a| b.max[a].to_native()),
        );
        let tree = format::kd::file_tree(file);
        let region = |r: u32, min: [f64; 3], max: [f64; 3]| {
            let finest = format::query::region_bricks(file, r)
                .iter()
                .filter_map(|&id| file.bricks.get(id.to_native() as usize))
                .map(|br| br.level.to_native())
                .min();
            RegionN {
                min,
                max,
                finest_w: finest
                    .and_then(|l| self.level_w.get(l as usize).copied())
                    .unwrap_or(self.finest_w),
            }
        };
        if threads > 1 && fill_in_stretches(&mut table, tree, lo, hi, self.frame, threads, &region)
        {
            return table;
        }
        // Every slot a stretch filled is filled again, with the same region.
        for (r, min, max) in format::kd::LeafCells::new(tree, lo, hi, self.frame) {
            if let Some(slot) = table.get_mut(r as usize) {
                *slot = region(r, min, max);
            }
        }
        table
    }

    /// Whether the table of every region has been built (tests of what asks for it).
    #[cfg(test)]
    pub(crate) fn region_table_built(&self) -> bool {
        self.region_table.get().is_some()
    }

    /// Region `r` in the local frame (builds the table of every region on first call;
    /// a lookup by point, [`Volume::region_box_at`], needs none).
    #[inline]
    pub fn region(&self, r: usize) -> RegionN {
        self.region_table()[r]
    }

    /// Every region in the local frame, by index.
    pub fn regions(&self) -> impl Iterator<Item = RegionN> + '_ {
        self.region_table().iter().copied()
    }

    /// The box (local frame) of every region whose range of field `f` meets `[lo, hi]`;
    /// empty (`min > max`) when none does. A view computes it once, for its band, from
    /// its packed tree ([`Volume::active_box_in`]); this packs field `f`'s tree for the
    /// one call (field 0's is the volume's own).
    pub fn active_box(&self, f: usize, lo: f64, hi: f64) -> ([f64; 3], [f64; 3]) {
        match self.packed(f) {
            Some(packed) => self.active_box_in(&packed, f, lo, hi),
            None => ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
        }
    }

    /// [`Volume::active_box`] from `packed`, the file's tree packed with field `f`'s
    /// ranges: a walk that keeps each node's cell and steps over every subtree whose range
    /// does not meet `[lo, hi]`, testing each region it reaches by its own range. So a
    /// band that few regions meet costs a walk of the few subtrees that hold them.
    pub(crate) fn active_box_in(
        &self,
        packed: &Packed,
        f: usize,
        lo: f64,
        hi: f64,
    ) -> ([f64; 3], [f64; 3]) {
        use format::kd::{KdTree, Node, WalkNodes};
        let mut min = [f64::INFINITY; 3];
        let mut max = [f64::NEG_INFINITY; 3];
        if f >= self.fields.len() || KdTree::node_count(packed) == 0 {
            return (min, max);
        }
        let meets = |mn: f32, mx: f32| crate::transfer::range_meets(mn, mx, lo, hi);
        let (rmin, rmax) = self.root_cell();
        let mut stack = vec![(KdTree::root(packed), rmin, rmax)];
        // Each node is pushed once in a tree; the count only bounds a malformed one.
        let mut budget = KdTree::node_count(packed)
            .saturating_mul(2)
            .saturating_add(1);
        while let Some((n, cmin, cmax)) = stack.pop() {
            if budget == 0 {
                break;
            }
            budget -= 1;
            let Some((node, range, _)) = packed.get(n) else {
                continue;
            };
            if range.is_some_and(|(mn, mx)| !meets(mn, mx)) {
                continue;
            }
            match node {
                Node::Inner {
                    axis,
                    split,
                    left,
                    right,
                } => {
                    let (lhi, rlo) = format::kd::cut_cell(axis, split, self.frame, cmin, cmax);
                    stack.push((right, rlo, cmax));
                    stack.push((left, cmin, lhi));
                }
                Node::Leaf(Some(r)) if (r as usize) < self.region_count() => {
                    let [mn, mx] = self.range(r as usize, f);
                    if meets(mn, mx) {
                        for a in 0..3 {
                            min[a] = min[a].min(cmin[a]);
                            max[a] = max[a].max(cmax[a]);
                        }
                    }
                }
                Node::Leaf(_) => {}
            }
        }
        (min, max)
    }

    /// Local cell width of a segment's region: its finest brick's level's (the finest
    /// width for a skipped subtree). Read from the region's bricks the first time, then
    /// from one byte a region ([`Volume::finest_levels`]): a region of a fragmented
    /// layout lists dozens of bricks, and the sampled strategies ask at every segment.
    #[inline]
    pub fn step_width(&self, region: u32) -> f64 {
        use std::sync::atomic::Ordering::Relaxed;
        let r = region as usize;
        if r >= self.region_count() {
            return self.finest_w;
        }
        let known = self
            .finest_levels
            .get_or_init(|| (0..self.region_count()).map(|_| AtomicU8::new(0)).collect());
        let level = match known[r].load(Relaxed) {
            0 => {
                let file = self.file;
                let level = self
                    .region_brick_ids(r)
                    .iter()
                    .filter_map(|&id| file.bricks.get(id.to_native() as usize))
                    .map(|br| br.level.to_native())
                    .min();
                match level {
                    Some(l) if l < u32::from(NO_LEVEL) - 1 => known[r].store(l as u8 + 1, Relaxed),
                    Some(_) => {}
                    None => known[r].store(NO_LEVEL, Relaxed),
                }
                level
            }
            NO_LEVEL => None,
            k => Some(u32::from(k) - 1),
        };
        level
            .and_then(|l| self.level_w.get(l as usize).copied())
            .unwrap_or(self.finest_w)
    }

    /// Bricks of region `r` (none for a region that failed its check, see [`Checks`]).
    #[inline]
    pub fn region_brick_ids(&self, r: usize) -> &'a [Archived<u32>] {
        if !self.region_checked(r) {
            return &[];
        }
        let reg = &self.file.regions[r];
        let start = reg.bricks_start.to_native() as usize;
        &self.file.region_bricks[start..start + reg.bricks_len.to_native() as usize]
    }

    /// Whether region `r`'s list and its bricks may be indexed: checked at open, or by
    /// the first call for it ([`Checks`]).
    #[inline(always)]
    fn region_checked(&self, r: usize) -> bool {
        let Some(checks) = &self.checks else {
            return true;
        };
        let bits = checks.regions.get_or_init(|| {
            (0..self.file.regions.len().div_ceil(64))
                .map(|_| AtomicU64::new(0))
                .collect()
        });
        match bits.get(r / 64) {
            Some(w) if w.load(Ordering::Relaxed) & (1 << (r % 64)) != 0 => true,
            Some(w) => self.check_region(checks, w, r),
            None => false,
        }
    }

    /// Checks region `r` (its bit in `word`) the first time it is read.
    #[cold]
    #[inline(never)]
    fn check_region(&self, checks: &Checks, word: &AtomicU64, r: usize) -> bool {
        match format::validate::check_region(self.file, r) {
            Ok(()) => {
                word.fetch_or(1 << (r % 64), Ordering::Relaxed);
                true
            }
            Err(e) => {
                let _ = checks.broken.set(e);
                false
            }
        }
    }

    /// Whether the KD-tree may be walked with the file's regions: checked at open, or on
    /// the first call ([`Checks`]); a tree that failed reads as empty.
    pub(crate) fn kd_checked(&self) -> bool {
        let Some(checks) = &self.checks else {
            return true;
        };
        *checks
            .kd
            .get_or_init(|| match format::validate::check_kd(self.file) {
                Ok(()) => true,
                Err(e) => {
                    let _ = checks.broken.set(e);
                    false
                }
            })
    }

    /// Brick `b` in the local frame, or `None` when it fails its check: for readers that
    /// go through the bricks by index, not through a region's list (whose bricks
    /// [`Volume::region_brick_ids`] checked).
    pub fn brick_checked(&self, b: u32) -> Option<BrickN> {
        if let Some(checks) = &self.checks {
            if let Err(e) = format::validate::check_brick(self.file, b as usize) {
                let _ = checks.broken.set(e);
                return None;
            }
        }
        Some(self.brick(b))
    }

    /// The first part of the file that failed its check since the view was opened with
    /// [`format::Structure::OnUse`] (it read as empty): every command reports it after its
    /// frame, as an open would have. `None` when all read so far passed.
    pub fn structure_error(&self) -> Option<&format::validate::ValidationError> {
        self.checks.as_ref().and_then(|c| c.broken.get())
    }

    /// [`Volume::structure_error`] as the error an open that checked everything would
    /// have given for the file at `path`, for commands to report after their frames.
    pub fn check_structure(&self, path: &std::path::Path) -> Result<(), format::FormatError> {
        match self.structure_error() {
            None => Ok(()),
            Some(e) => Err(format::FormatError {
                path: path.to_path_buf(),
                kind: format::FormatErrorKind::Invalid(e.clone()),
            }),
        }
    }

    /// `[min, max]` of field `f` over region `r`.
    #[inline]
    pub fn range(&self, r: usize, f: usize) -> [f32; 2] {
        let v = &self.file.region_ranges[r * self.fields.len() + f];
        [v.min.to_native(), v.max.to_native()]
    }

    /// Region containing the local point `p` (half-open boxes), by KD descent (of the
    /// point-location tree, see `locate`).
    pub fn region_at(&self, p: [f64; 3]) -> Option<u32> {
        // The packed copy of field 0's tree (when there is one) is the denser read.
        // Inside the bounds a leaf's cell is its region's box.
        if !self.inside(&p) {
            return None;
        }
        match self.locate_tree() {
            Some(packed) => format::kd::locate(packed, p, self.frame),
            None => format::kd::locate(&self.archived_tree(), p, self.frame),
        }
    }

    /// [`Volume::region_at`] with the region's box, found on the way down (the same
    /// descent, which keeps the cell it is in): a caller that looks up points near `p`
    /// next tests them against the box before it descends again.
    pub fn region_box_at(&self, p: [f64; 3]) -> Option<RegionBox> {
        if !self.inside(&p) {
            return None;
        }
        let (lo, hi) = self.file_bounds();
        let found = match self.locate_tree() {
            Some(packed) => format::kd::locate_cell(packed, p, lo, hi, self.frame),
            None => format::kd::locate_cell(&self.archived_tree(), p, lo, hi, self.frame),
        };
        found.map(|(region, min, max)| RegionBox { region, min, max })
    }

    /// The file's bounds as stored (world units): the root cell the tree's cells are cut
    /// from.
    fn file_bounds(&self) -> ([f64; 3], [f64; 3]) {
        let b = &self.file.bounds;
        (
            std::array::from_fn(|a| b.min[a].to_native()),
            std::array::from_fn(|a| b.max[a].to_native()),
        )
    }

    /// [`Volume::region_box_at`] of `p`, looked up first in the boxes `kept` holds; a
    /// region found by descent is kept there with its box.
    pub(crate) fn region_box_kept(&self, p: [f64; 3], kept: &mut NearRegions) -> Option<RegionBox> {
        if !self.inside(&p) {
            return None;
        }
        if let Some(b) = kept.find_box(&p) {
            return Some(b);
        }
        let b = self.region_box_at(p)?;
        kept.keep(b);
        Some(b)
    }

    /// The file's own tree, for a file without fields (which packs none); empty when the
    /// tree fails its check ([`Volume::kd_checked`]).
    fn archived_tree(&self) -> format::kd::Stored<'a, format::ArchivedKdNode> {
        if self.kd_checked() {
            format::kd::file_tree(self.file)
        } else {
            format::kd::Stored {
                root: format::kd::EMPTY,
                nodes: &[],
                axes: &[],
            }
        }
    }

    /// The KD root's cell in the local frame as every walk of the tree starts it: the
    /// file's bounds minus the frame, so that the cells cut from it are the regions'
    /// boxes bit for bit ([`format::kd::LeafCells`]).
    pub(crate) fn root_cell(&self) -> ([f64; 3], [f64; 3]) {
        let b = &self.file.bounds;
        (
            std::array::from_fn(|a| b.min[a].to_native() - self.frame[a]),
            std::array::from_fn(|a| b.max[a].to_native() - self.frame[a]),
        )
    }

    /// Whether the local point `p` lies inside the file's bounds (half-open).
    fn inside(&self, p: &[f64; 3]) -> bool {
        (0..3).all(|a| p[a] >= self.bounds_min[a] && p[a] < self.bounds_max[a])
    }

    /// The KD descent of the local point `p`, for [`Volume::region_near_kept`].
    pub(crate) fn descent(&self, p: [f64; 3]) -> Descent {
        match self.locate_tree() {
            Some(packed) => Descent::of(packed, p, self.frame),
            None => Descent::of(&self.archived_tree(), p, self.frame),
        }
    }

    /// [`Volume::region_at`] of `q`, looked up first in the boxes `kept` holds, else
    /// found from the descent `near` of the point `p` near it (made on first need; see
    /// [`Descent`]); a region found by descent is kept there with its box.
    pub(crate) fn region_near_kept(
        &self,
        near: &mut Option<Descent>,
        p: [f64; 3],
        q: [f64; 3],
        kept: &mut NearRegions,
    ) -> Option<u32> {
        if !self.inside(&q) {
            return None;
        }
        if let Some(b) = kept.find_box(&q) {
            return Some(b.region);
        }
        let near = near.get_or_insert_with(|| self.descent(p));
        let (lo, hi) = self.file_bounds();
        let (region, min, max) = match self.locate_tree() {
            Some(packed) => near.locate_cell(packed, q, lo, hi, self.frame),
            None => near.locate_cell(&self.archived_tree(), q, lo, hi, self.frame),
        }?;
        kept.keep(RegionBox { region, min, max });
        Some(region)
    }

    /// Value of field `f`, cell `idx` (in range for every cell of a checked brick).
    #[inline]
    pub(crate) fn value(&self, f: usize, idx: usize) -> f32 {
        self.values[f][idx].to_native()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testvol;

    /// A step width read from the region's bricks, first or later (from the byte kept),
    /// is the table's, on a file of two levels; a segment that is no region steps at
    /// the finest width.
    #[test]
    fn step_widths_kept_per_region_are_the_tables() {
        let noise = |p: [f64; 3]| (p[0] * 1.3).sin() + p[1] * p[2];
        let file = testvol::nested(8, [0.5, -3.0, 2.0], &[("n", &noise)], 3);
        let view = testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let widths: std::collections::BTreeSet<u64> = (0..vol.region_count())
            .map(|r| vol.region(r).finest_w.to_bits())
            .collect();
        assert!(widths.len() >= 2, "regions of both levels: {widths:?}");
        for _ in 0..2 {
            for r in 0..vol.region_count() {
                assert_eq!(
                    vol.step_width(r as u32).to_bits(),
                    vol.region(r).finest_w.to_bits(),
                    "region {r}"
                );
            }
        }
        assert_eq!(vol.step_width(u32::MAX), vol.finest_w);
    }

    /// A shading gradient whose neighbour points are looked up in the regions kept from
    /// earlier points is the one found by descent alone, bit for bit: along rows of
    /// points a fraction of a cell apart (as neighbouring pixels' hits are), on cell faces
    /// and the fine level's boundary, beside the data's faces and at random points, on a
    /// file of many small regions over two levels. The kept boxes must answer most
    /// lookups, or the test would not test them.
    #[test]
    fn shading_gradients_from_kept_regions_are_the_descents() {
        let noise = |p: [f64; 3]| ((p[0] * 3.1).sin() + (p[1] * 1.7).cos() * p[2]).fract();
        let offset = [0.5, -3.0, 2.0];
        let file = testvol::nested(8, offset, &[("n", &noise)], 3);
        let view = testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let lo = vol.to_local(offset);
        let mut points = Vec::new();
        // Rows of points 0.037 cells apart, along each axis, through both levels.
        for a in 0..3 {
            for row in 0..6 {
                let mut p = lo;
                p[(a + 1) % 3] += 1.3 + 2.45 * row as f64;
                p[(a + 2) % 3] += [4.0, 7.77, 12.0, 0.02, 15.99, 9.5][row];
                for k in 0..440 {
                    let mut q = p;
                    q[a] = lo[a] + 0.037 * k as f64;
                    points.push(q);
                }
            }
        }
        let mut seed = 5u64;
        for _ in 0..500 {
            points.push(std::array::from_fn(|a| {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
                lo[a] - 0.5 + 17.0 * ((seed >> 11) as f64 / (1u64 << 53) as f64)
            }));
        }
        // With a hint (a hit's region), and without one (a dvr sample's point, whose own
        // region is looked up in the kept boxes too).
        let (mut kept, mut kept_unhinted) = (NearRegions::default(), NearRegions::default());
        let (mut from_kept, mut lookups, mut p_kept) = (0, 0, 0);
        for &p in &points {
            for a in 0..3 {
                for s in [-1.0, 1.0] {
                    let mut q = p;
                    q[a] += s * vol.finest_w;
                    lookups += 1;
                    from_kept += usize::from(vol.inside(&q) && kept.find_box(&q).is_some());
                }
            }
            p_kept += usize::from(kept_unhinted.find_box(&p).is_some());
            let alone = vol.shading_gradient(p, 0).map(|g| g.map(f64::to_bits));
            let hint = vol.region_box_at(p);
            let near = vol.shading_gradient_near(hint, p, 0, &mut kept);
            assert_eq!(near.map(|g| g.map(f64::to_bits)), alone, "at {p:?}");
            let unhinted = vol.shading_gradient_near(None, p, 0, &mut kept_unhinted);
            assert_eq!(
                unhinted.map(|g| g.map(f64::to_bits)),
                alone,
                "at {p:?}, no hint"
            );
        }
        assert!(
            from_kept * 2 > lookups,
            "only {from_kept} of {lookups} neighbour points were in kept regions"
        );
        assert!(
            p_kept * 2 > points.len(),
            "only {p_kept} of {} points were in kept regions",
            points.len()
        );
    }

    /// The region table filled on several threads, stretch by stretch, is the one walk's
    /// bit for bit, on a file of many small regions over two levels.
    #[test]
    fn the_region_table_on_several_threads_is_the_one_walks() {
        let noise = |p: [f64; 3]| ((p[0] * 3.1).sin() + (p[1] * 1.7).cos() * p[2]).fract();
        let file = testvol::nested(8, [0.5, -3.0, 2.0], &[("n", &noise)], 3);
        let view = testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let bits = |t: Vec<RegionN>| {
            t.iter()
                .map(|r| {
                    (
                        r.min.map(f64::to_bits),
                        r.max.map(f64::to_bits),
                        r.finest_w.to_bits(),
                    )
                })
                .collect::<Vec<_>>()
        };
        let one = bits(vol.derive_region_table(1));
        assert!(one.len() > 200, "{} regions", one.len());
        assert!(one.iter().all(|r| r.0 != [f64::INFINITY.to_bits(); 3]));
        for threads in [2, 3, 8] {
            assert_eq!(
                bits(vol.derive_region_table(threads)),
                one,
                "{threads} threads"
            );
        }
    }

    /// A tree of two leaves (and an empty one) and the regions they hold.
    struct Leaves(Vec<format::kd::Node>);
    impl format::kd::KdTree for &Leaves {
        fn node_count(&self) -> usize {
            self.0.len()
        }
        fn root(&self) -> u32 {
            0
        }
        fn node(&self, i: u32) -> Option<format::kd::Node> {
            self.0.get(i as usize).copied()
        }
    }

    /// Stretches are only taken when the leaves number their regions in order: a tree
    /// whose left leaf holds the higher region is refused (the one walk fills its table).
    #[test]
    fn regions_out_of_leaf_order_are_left_to_the_one_walk() {
        use format::kd::Node;
        let tree = |first: u32, second: u32| {
            Leaves(vec![
                Node::Inner {
                    axis: 0,
                    split: 0.5,
                    left: 1,
                    right: 2,
                },
                Node::Leaf(Some(first)),
                Node::Inner {
                    axis: 1,
                    split: 0.5,
                    left: 3,
                    right: 4,
                },
                Node::Leaf(None),
                Node::Leaf(Some(second)),
            ])
        };
        let region = |r: u32, min: [f64; 3], max: [f64; 3]| RegionN {
            min,
            max,
            finest_w: f64::from(r),
        };
        let empty = RegionN {
            min: [0.0; 3],
            max: [0.0; 3],
            finest_w: -1.0,
        };
        let (lo, hi) = ([0.0; 3], [1.0; 3]);
        let mut table = vec![empty; 2];
        let ordered = tree(0, 1);
        assert!(fill_in_stretches(
            &mut table, &ordered, lo, hi, [0.0; 3], 2, &region
        ));
        assert_eq!((table[0].max[0], table[1].min[0]), (0.5, 0.5));
        assert_eq!((table[0].finest_w, table[1].finest_w), (0.0, 1.0));
        assert_eq!(table[1].max[1], 1.0);
        assert_eq!(table[1].min[1], 0.5);
        let swapped = tree(1, 0);
        let mut table = vec![empty; 2];
        assert!(!fill_in_stretches(
            &mut table, &swapped, lo, hi, [0.0; 3], 2, &region
        ));
    }

    /// Issue 32: a view setting naming a missing field said the field twice wherever a
    /// report prints the chain of sources (`{:#}`, as both programs do): the error is one
    /// message with no source, naming the setting and the field once.
    #[test]
    fn a_setting_error_names_the_missing_field_once() {
        let file = testvol::nested(4, [0.0; 3], &[("q", &|p: [f64; 3]| p[0])], 4);
        let view = testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let e = vol
            .field_index("nope")
            .unwrap_err()
            .named_by("colormap.field");
        assert!(std::error::Error::source(&e).is_none());
        let m = e.to_string();
        assert_eq!(m.matches("nope").count(), 1, "{m}");
        assert!(
            m.starts_with("colormap.field: field \"nope\" is not in the file (fields: q"),
            "{m}"
        );
    }

    /// Issue 32: a file of data at 1e300 (valid as a file) rendered nonsense and then
    /// failed with "camera.up is parallel to the view direction". Data beyond 2^40 finest
    /// cells from the origin is refused at open, saying so; at 2^38 it opens.
    #[test]
    fn data_too_far_from_the_origin_is_refused_with_its_reach() {
        let f = |p: [f64; 3]| p[0];
        for (offset, opens) in [
            (2f64.powi(38), true),
            (2f64.powi(45), false),
            (1e300, false),
        ] {
            let file = testvol::nested(4, [offset; 3], &[("f", &f)], 4);
            let Ok(view) = testvol::open(&file) else {
                assert!(!opens, "{offset:e}: the file should open");
                continue;
            };
            match Volume::new(&view) {
                Ok(_) => assert!(opens, "{offset:e}: opened"),
                Err(e) => {
                    assert!(!opens, "{offset:e}: {e}");
                    let m = e.to_string();
                    assert!(
                        m.starts_with("the data's bounds [")
                            && m.contains("from the origin, more than the 2^40 within"),
                        "{m}"
                    );
                }
            }
        }
    }

    /// The box of the regions that can contribute is the union over exactly those regions
    /// (checked by brute force over every region), for bands that meet some, all or none;
    /// asking again gives the same answer, and other bands and fields get their own.
    #[test]
    fn active_box_is_the_union_of_the_regions_meeting_the_band() {
        let f = |p: [f64; 3]| p[0] + 0.25 * p[1] - 0.5 * p[2];
        let g = |p: [f64; 3]| -p[0];
        let file = testvol::nested(6, [3.0, -2.0, 1e5], &[("f", &f), ("g", &g)], 3);
        let view = testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        // f runs over about -50003..-49982 and g over -15..-3 in the grid.
        for (field, lo, hi, some) in [
            (0, -49995.0, -49995.0, true),
            (0, -49990.0, -49985.0, true),
            (1, -10.0, -8.0, true),
            (0, -1e9, 1e9, true),
            (0, 1e9, 2e9, false),
        ] {
            let (mut min, mut max) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            let mut any = false;
            for r in 0..vol.region_count() {
                let [mn, mx] = vol.range(r, field);
                if (mx as f64) >= lo && (mn as f64) <= hi {
                    any = true;
                    let reg = vol.region(r);
                    for a in 0..3 {
                        min[a] = min[a].min(reg.min[a]);
                        max[a] = max[a].max(reg.max[a]);
                    }
                }
            }
            let got = vol.active_box(field, lo, hi);
            assert_eq!(got, (min, max), "field {field}, band {lo}..{hi}");
            assert_eq!(any, some, "field {field}, band {lo}..{hi}");
            assert_eq!(any, (0..3).all(|a| got.0[a] <= got.1[a]));
            if field == 1 {
                // g = -x between -10 and -8: a slab, narrower in x than the data.
                assert!(
                    (0..3).any(|a| got.0[a] > vol.bounds_min[a] || got.1[a] < vol.bounds_max[a])
                );
            }
            assert_eq!(vol.active_box(field, lo, hi), got, "kept");
        }
        // A field the file does not have: nothing contributes.
        let (min, max) = vol.active_box(7, -1e9, 1e9);
        assert!(min[0] > max[0]);
    }
}
