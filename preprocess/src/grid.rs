//! In-memory sparse grids: what the VDB reader yields, what `synth` writes, what `bake` eats.
//!
//! The layout mirrors a VDB tree's leaves (8³ voxel blocks with an active mask) plus active
//! tiles kept as tiles, so a constant region costs one entry rather than one value per
//! voxel. Nothing here knows the file format.

/// Edge length of a leaf block in voxels.
pub const LEAF_DIM: i32 = 8;
/// Voxels per leaf block.
pub const LEAF_VOXELS: usize = 512;

/// Index space → world space: `world = voxel_size * ijk + translation` per axis. A VDB
/// voxel `(i, j, k)` is *centred* at that point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    pub voxel_size: [f64; 3],
    pub translation: [f64; 3],
}

impl Transform {
    pub fn index_to_world(&self, ijk: [f64; 3]) -> [f64; 3] {
        [
            self.voxel_size[0] * ijk[0] + self.translation[0],
            self.voxel_size[1] * ijk[1] + self.translation[1],
            self.voxel_size[2] * ijk[2] + self.translation[2],
        ]
    }
}

/// Offset of voxel `(x, y, z)` (each `0..8`, relative to the leaf origin) inside a leaf:
/// VDB order, z fastest.
pub fn leaf_offset(x: usize, y: usize, z: usize) -> usize {
    (x << 6) | (y << 3) | z
}

/// An 8³ block of voxels; origin is a multiple of 8 in index space.
#[derive(Debug, Clone, PartialEq)]
pub struct Leaf<V> {
    pub origin: [i32; 3],
    /// Bit `n` of word `n / 64` is set when voxel `n` (see [`leaf_offset`]) is active.
    pub active: [u64; 8],
    /// All 512 values (inactive ones hold whatever the file stored, usually background).
    pub values: Box<[V; LEAF_VOXELS]>,
}

/// What is known of a leaf before its values are decoded: where it is and which of its
/// voxels are active. The bake's checks and its cells' layout need no more than this, so
/// they are made before any value is decoded.
pub trait LeafTopology {
    fn origin(&self) -> [i32; 3];
    fn active(&self) -> &[u64; 8];
    fn active_count(&self) -> u32 {
        self.active().iter().map(|w| w.count_ones()).sum()
    }
}

impl<V> LeafTopology for Leaf<V> {
    fn origin(&self) -> [i32; 3] {
        self.origin
    }
    fn active(&self) -> &[u64; 8] {
        &self.active
    }
}

impl<V: Copy> Leaf<V> {
    pub fn is_active(&self, n: usize) -> bool {
        (self.active[n >> 6] >> (n & 63)) & 1 == 1
    }

    /// Active voxels as (index-space coordinate, value), in offset order.
    pub fn active_voxels(&self) -> impl Iterator<Item = ([i32; 3], V)> + '_ {
        (0..LEAF_VOXELS)
            .filter(|&n| self.is_active(n))
            .map(move |n| {
                let ijk = [
                    self.origin[0] + (n >> 6) as i32,
                    self.origin[1] + ((n >> 3) & 7) as i32,
                    self.origin[2] + (n & 7) as i32,
                ];
                (ijk, self.values[n])
            })
    }
}

/// An active constant cube of `size³` voxels starting at `origin` (index space).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tile<V> {
    pub origin: [i32; 3],
    /// Edge length in voxels (8, 128, 4096 for a standard 5-4-3 tree).
    pub size: u32,
    pub value: V,
}

/// One grid's active values: its leaves decoded ([`Leaf`]), or only located in a file
/// (`crate::vdb::LocatedLeaf`) until the bake decodes them into its cells.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid<V, L = Leaf<V>> {
    pub name: String,
    pub transform: Transform,
    pub background: V,
    pub leaves: Vec<L>,
    pub tiles: Vec<Tile<V>>,
}

impl<V: Copy, L: LeafTopology> Grid<V, L> {
    /// Active voxels, tiles counted as the voxels they cover.
    pub fn active_voxel_count(&self) -> u64 {
        let leaves: u64 = self.leaves.iter().map(|l| l.active_count() as u64).sum();
        let tiles: u64 = self.tiles.iter().map(|t| (t.size as u64).pow(3)).sum();
        leaves + tiles
    }
}

/// Vector value of a vec3 grid (single precision on disk or widened from double).
pub type Vec3 = [f32; 3];

/// A grid of any supported value type, as read from a file.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyGrid {
    Float(Grid<f32>),
    Double(Grid<f64>),
    Vec3s(Grid<[f32; 3]>),
    Vec3d(Grid<[f64; 3]>),
}

/// Evaluates `$body` with `$g` bound to the typed grid inside whichever variant `$any` is:
/// for code that does not depend on the value type.
macro_rules! with_grid {
    ($any:expr, $g:ident => $body:expr) => {
        match $any {
            AnyGrid::Float($g) => $body,
            AnyGrid::Double($g) => $body,
            AnyGrid::Vec3s($g) => $body,
            AnyGrid::Vec3d($g) => $body,
        }
    };
}

impl AnyGrid {
    pub(crate) fn transform(&self) -> Transform {
        with_grid!(self, g => g.transform)
    }

    /// Gives the grid another name and transform, keeping its tree: how an instanced grid
    /// (one that shares another grid's tree in the file) is made from its parent.
    pub(crate) fn rename(&mut self, name: &str, transform: Transform) {
        with_grid!(self, g => {
            g.name = name.to_string();
            g.transform = transform;
        })
    }
}

/// Kind of an input grid, for selection and for messages about it (which the errors
/// name, so it lives here, below both).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GridKind {
    Vector,
    Scalar,
    /// A grid type the baker cannot read (listed, never selected by default).
    Other,
}
