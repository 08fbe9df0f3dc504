//! The archived root of a `.qbk` file: everything rendering needs and nothing else.
//!
//! Geometry is stored in `f64` world units so that data sets placed far from the origin
//! (1e6 and beyond) keep sub-cell precision; the viewer moves to a local frame itself.
//! Values are `f32`: one contiguous array per field, so that the hot loop of the ray caster
//! (the iso field at every sample) streams through one array and never touches the colour
//! field (speed) except at visible samples. Inside a brick, cells are ordered x fastest
//! (`x + nx * (y + ny * z)`), so a brick's values are one slice of each field array.
//!
//! Layout choices for the ray caster's access pattern (front-to-back along a ray: KD walk
//! → region → its bricks → cell values):
//! - Everything is a flat array of fixed-size records addressed by `u32`/`u64` index: no
//!   pointers to chase inside the archive, and each record type is packed next to its
//!   neighbours. A `Brick` is 64 bytes (one cache line), a `Region` 8 (its brick run), a
//!   `KdNode` 16 (split and two child references).
//! - Structure is kept small next to the values (format 3): a region's box is its KD
//!   leaf's cell and is not stored, leaves are not stored either (a child reference
//!   names the region), and per-node value ranges are not stored: the viewer derives
//!   the ranges it skips by from `region_ranges` when it first walks a field (one pass).
//! - A region's brick ids are one contiguous run of `region_bricks`, so visiting a region
//!   reads one short slice instead of a linked list.
//! - `region_ranges` is region-major (`r * fields.len() + f`): empty-space skipping asks
//!   "can any field of this region matter?", and all fields of one region share a line.
//! - Cell values are per field, x fastest inside a brick: the trilinear/tent stencil of a
//!   sample touches at most 2 × 2 rows of `nx` floats, which small bricks (≤ 8³ cells,
//!   2 KiB per field) keep within L1.
//! - The archive starts 16-byte aligned (see `header`), so value slices can be loaded as
//!   aligned `f32` vectors and every `f64`/`u64` is naturally aligned, as rkyv's
//!   validation demands.

use rkyv::{Archive, Deserialize, Serialize};

/// How far from the origin data may lie, as a power of two of finest cell widths: the
/// viewer refuses to open a file whose bounds reach beyond it, and the baker keeps well
/// inside it (its own bound, `preprocess::error::MAX_BAKE_REACH_LOG2`, is 2^26); the format
/// itself only asks for finite numbers. At 2^40 cells a coordinate's double-precision
/// spacing is 2^-12 of a cell, which is what "sub-cell precision" above can promise; much
/// further out (a grid translated to 1e300 with cells of 0.1) neighbouring cell centres are
/// the same number and the data collapses to a point. Real data sits far inside: 2^40
/// cells of 1 mm are a million kilometres.
pub const MAX_REACH_LOG2: i32 = 40;

/// Most bytes an archive may hold: 1 TiB. Since format 4 its relative pointers are
/// 64-bit (see `header`'s flags), so the root, written last, reaches arrays of any size
/// (format 3's 32-bit pointers stopped at 2 GiB, which 262 M cells of two fields pass, and
/// rkyv panics while writing past the pointers' reach); this bound only keeps an estimate
/// gone wrong from being written. What a machine can bake is bounded by its memory first.
pub const MAX_ARCHIVE_BYTES: u64 = 1 << 40;

/// Root of the archive.
#[derive(Archive, Serialize, Deserialize, Debug, Clone, PartialEq)]
#[rkyv(derive(Debug))]
pub struct BrickFile {
    /// Where the data came from and how it was baked.
    pub provenance: Provenance,
    /// Union of all brick supports (world units).
    pub bounds: Aabb,
    /// Levels by index; level 0 is the finest. A level with no bricks may be present.
    pub levels: Vec<Level>,
    /// The baked fields (e.g. `q`, `speed`), each with its values for every leaf cell.
    pub fields: Vec<Field>,
    /// Dense boxes of leaf cells of one level.
    pub bricks: Vec<Brick>,
    /// Active brick regions: disjoint boxes partitioning the union of supports. A region's
    /// box is its KD leaf's cell (the file's bounds cut by the splits on the way down), so
    /// it is not stored (see [`crate::kd::leaf_cells`]).
    pub regions: Vec<Region>,
    /// Brick ids per region: region `r` owns
    /// `region_bricks[r.bricks_start .. r.bricks_start + r.bricks_len]`, sorted ascending.
    pub region_bricks: Vec<u32>,
    /// Exact value range of every field over every cell that can contribute to a region:
    /// entry `r * fields.len() + f` is field `f` of region `r`.
    pub region_ranges: Vec<ValueRange>,
    /// The KD-tree's root as a child reference (see [`crate::kd::LEAF`]): inner node 0,
    /// or a leaf when the tree has no inner node.
    pub kd_root: u32,
    /// Inner nodes of the KD-tree over the regions. Leaves are not stored: a child
    /// reference with the [`crate::kd::LEAF`] bit names a region (or empty space), so
    /// every leaf holds exactly one region or nothing. Every node is stored before its
    /// children (depth first), which is what lets validation check that it is a tree in
    /// one pass.
    pub kd_nodes: Vec<KdNode>,
    /// Split axis (0, 1, 2) of every inner node, kept beside the 16-byte nodes.
    pub kd_axes: Vec<u8>,
}

/// Provenance of a baked file.
#[derive(Archive, Serialize, Deserialize, Debug, Clone, PartialEq)]
#[rkyv(derive(Debug))]
pub struct Provenance {
    /// File name (not the full path) of the source VDB.
    pub source: String,
    /// Source grids that were baked, in file order.
    pub grids: Vec<SourceGrid>,
    /// Bake options as a JSON object, for display and reproduction.
    pub bake_options: String,
    /// `qbricks-bake` version that wrote the file.
    pub tool_version: String,
}

/// One source grid of the VDB file.
#[derive(Archive, Serialize, Deserialize, Debug, Clone, PartialEq)]
#[rkyv(derive(Debug))]
pub struct SourceGrid {
    pub name: String,
    pub voxel_size: [f64; 3],
    /// Level this grid was assigned to.
    pub level: u32,
}

/// Axis-aligned box in world units, the one float box of every crate: the file's bounds
/// and regions, the baker's brick supports and synthetic domains, the viewer's mesh BVH.
/// Stored boxes have `min <= max` on every axis; `min > max` on some axis is an empty box
/// (see [`Aabb::EMPTY`]). Everything is `f64`, so scenes placed far from the origin keep
/// their precision. Methods do not change the archived layout.
#[derive(Archive, Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[rkyv(derive(Debug))]
pub struct Aabb {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl Aabb {
    /// The box of no points, where [`Aabb::grow`] and [`Aabb::union`] start.
    pub const EMPTY: Aabb = Aabb {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };

    /// The box grown to hold `p`.
    pub fn grow(self, p: [f64; 3]) -> Aabb {
        Aabb {
            min: std::array::from_fn(|a| self.min[a].min(p[a])),
            max: std::array::from_fn(|a| self.max[a].max(p[a])),
        }
    }

    /// The smallest box holding both.
    pub fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: std::array::from_fn(|a| self.min[a].min(o.min[a])),
            max: std::array::from_fn(|a| self.max[a].max(o.max[a])),
        }
    }

    /// `min > max` on some axis (a NaN bound does not make a box empty).
    pub fn is_empty(&self) -> bool {
        (0..3).any(|a| self.min[a] > self.max[a])
    }

    /// Whether the open interiors intersect: boxes that only share a face do not overlap.
    pub fn overlaps(&self, o: &Aabb) -> bool {
        (0..3).all(|a| self.min[a] < o.max[a] && self.max[a] > o.min[a])
    }

    pub fn centre(&self) -> [f64; 3] {
        std::array::from_fn(|a| 0.5 * (self.min[a] + self.max[a]))
    }

    /// Half the surface area (a surface area heuristic only needs ratios); 0 for an empty
    /// box.
    pub fn half_area(&self) -> f64 {
        if self.is_empty() {
            return 0.0;
        }
        let d: [f64; 3] = std::array::from_fn(|a| self.max[a] - self.min[a]);
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
}

/// A resolution level.
#[derive(Archive, Serialize, Deserialize, Debug, Clone, PartialEq)]
#[rkyv(derive(Debug))]
pub struct Level {
    /// Cell edge length in world units (cells are cubes).
    pub cell_width: f64,
    /// Leaf cells of this level stored in the file.
    pub cells: u64,
    /// Bricks of this level.
    pub bricks: u32,
}

/// One baked scalar field.
#[derive(Archive, Serialize, Deserialize, Debug, Clone, PartialEq)]
#[rkyv(derive(Debug))]
pub struct Field {
    /// `q`, `speed`, `velocity_x`, … or the name of a baked scalar grid.
    pub name: String,
    /// Range over all finite leaf-cell values.
    pub min: f32,
    pub max: f32,
    /// Histogram of leaf-cell values over `[min, max]` in equal bins.
    pub histogram: Vec<u64>,
    /// One value per leaf cell, brick after brick (see [`Brick::first_value`]).
    pub values: Vec<f32>,
}

/// A dense box of leaf cells of one level. Fields are ordered so that the archived record
/// is exactly 64 bytes.
#[derive(Archive, Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[rkyv(derive(Debug))]
pub struct Brick {
    /// Centre of the brick's first cell (lowest x, y, z) in world units.
    pub origin: [f64; 3],
    /// Cell edge length (equal to its level's `cell_width`).
    pub cell_width: f64,
    /// `1 / cell_width`, exactly as computed in `f64`: the reconstruction maps every sample
    /// into every brick of its region with it, and a multiplication is cheaper than the
    /// division there.
    pub inv_cell_width: f64,
    /// Index of the brick's first cell in every field's `values`.
    pub first_value: u64,
    /// Cells per axis, each >= 1.
    pub dims: [u32; 3],
    pub level: u32,
}

/// An active brick region: a box (its KD leaf's cell) listing every brick whose support
/// overlaps it. Mostly the set of supports holding a point is the same all over the box;
/// where many small supports cross, the baker merges their regions (see
/// `preprocess::regions`), and a listed brick may then add nothing in part of the box. Its
/// finest level (the local sampling unit) is the finest of its bricks' levels.
// Plain data (`repr(C)`, no padding), so a bake may keep millions of them in a scratch
// file and read them back as a slice ([`crate::streamed::Structure`]).
#[derive(
    Archive,
    Serialize,
    Deserialize,
    Debug,
    Clone,
    Copy,
    PartialEq,
    bytemuck::Pod,
    bytemuck::Zeroable,
)]
#[rkyv(derive(Debug))]
#[repr(C)]
pub struct Region {
    pub bricks_start: u32,
    pub bricks_len: u32,
}

/// Inclusive value range.
// Plain data, as `Region`.
#[derive(
    Archive,
    Serialize,
    Deserialize,
    Debug,
    Clone,
    Copy,
    PartialEq,
    bytemuck::Pod,
    bytemuck::Zeroable,
)]
#[rkyv(derive(Debug))]
#[repr(C)]
pub struct ValueRange {
    pub min: f32,
    pub max: f32,
}

/// Inner KD-tree node (16 bytes). Points with coordinate `< split` on the node's axis
/// (`kd_axes`) go to `left`. The children are references: an inner node's index, or
/// [`crate::kd::LEAF`] `| region`, or [`crate::kd::EMPTY`] for empty space.
// Plain data, as `Region`.
#[derive(
    Archive,
    Serialize,
    Deserialize,
    Debug,
    Clone,
    Copy,
    PartialEq,
    bytemuck::Pod,
    bytemuck::Zeroable,
)]
#[rkyv(derive(Debug))]
#[repr(C)]
pub struct KdNode {
    pub split: f64,
    pub left: u32,
    pub right: u32,
}
