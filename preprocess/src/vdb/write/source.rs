//! What the writer writes a grid from: the grid's shape (name, transform, background,
//! tiles, and every leaf's origin and active mask) held in memory, and its leaf values
//! asked for one leaf at a time while the buffers are written.
//!
//! The shape is what the topology and the grid metadata need before the first buffer is
//! written (about 80 bytes a leaf); the values are the file's bulk (6 kB a leaf of
//! 3-vectors). Asking for them on demand is what lets `synth` write a grid of a billion
//! voxels without holding it: the writer keeps one batch of leaves at a time. A grid that
//! is in memory already is written through the same code ([`GridSource::of`]).

use std::borrow::Cow;

use crate::grid::{AnyGrid, Grid, Tile, Transform, LEAF_VOXELS};

/// A leaf without its values: where it is and which of its voxels are active.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LeafShape {
    /// A multiple of 8 on every axis.
    pub origin: [i32; 3],
    /// Bit `n` of word `n / 64` is set when voxel `n` is active (as [`crate::grid::Leaf`]).
    pub active: [u64; 8],
}

impl LeafShape {
    pub fn active_count(&self) -> u64 {
        self.active.iter().map(|w| u64::from(w.count_ones())).sum()
    }
}

/// The values of leaf `index` (all 512, in VDB order; inactive ones should hold the
/// background). Called from several threads, in no particular order.
pub type LeafValues<'a, V> = dyn Fn(usize) -> Cow<'a, [V; LEAF_VOXELS]> + Sync + 'a;

/// One grid to write: its shape, and its leaves' values on demand.
pub struct GridSource<'a, V: Clone> {
    pub name: String,
    pub transform: Transform,
    pub background: V,
    pub tiles: Cow<'a, [Tile<V>]>,
    pub leaves: Vec<LeafShape>,
    pub values: Box<LeafValues<'a, V>>,
}

impl<'a, V: Copy + Sync> GridSource<'a, V> {
    /// A grid held in memory, its values lent as they are.
    pub fn of(grid: &'a Grid<V>) -> Self {
        GridSource {
            name: grid.name.clone(),
            transform: grid.transform,
            background: grid.background,
            tiles: Cow::Borrowed(&grid.tiles),
            leaves: grid
                .leaves
                .iter()
                .map(|l| LeafShape {
                    origin: l.origin,
                    active: l.active,
                })
                .collect(),
            values: Box::new(move |i| Cow::Borrowed(&*grid.leaves[i].values)),
        }
    }

    /// Active voxels, tiles counted as the voxels they cover.
    pub fn active_voxel_count(&self) -> u64 {
        let leaves: u64 = self.leaves.iter().map(LeafShape::active_count).sum();
        let tiles: u64 = self.tiles.iter().map(|t| u64::from(t.size).pow(3)).sum();
        leaves + tiles
    }
}

/// A grid to write of any value type the writer knows.
pub enum AnySource<'a> {
    Float(GridSource<'a, f32>),
    Double(GridSource<'a, f64>),
    Vec3s(GridSource<'a, [f32; 3]>),
    Vec3d(GridSource<'a, [f64; 3]>),
}

/// Evaluates `$body` with `$g` bound to the typed source inside `$any`.
macro_rules! with_source {
    ($any:expr, $g:ident => $body:expr) => {
        match $any {
            AnySource::Float($g) => $body,
            AnySource::Double($g) => $body,
            AnySource::Vec3s($g) => $body,
            AnySource::Vec3d($g) => $body,
        }
    };
}
pub(super) use with_source;

impl<'a> AnySource<'a> {
    /// A grid held in memory.
    pub fn of(grid: &'a AnyGrid) -> Self {
        match grid {
            AnyGrid::Float(g) => AnySource::Float(GridSource::of(g)),
            AnyGrid::Double(g) => AnySource::Double(GridSource::of(g)),
            AnyGrid::Vec3s(g) => AnySource::Vec3s(GridSource::of(g)),
            AnyGrid::Vec3d(g) => AnySource::Vec3d(GridSource::of(g)),
        }
    }

    pub fn name(&self) -> &str {
        with_source!(self, g => &g.name)
    }

    pub fn transform(&self) -> Transform {
        with_source!(self, g => g.transform)
    }

    pub fn leaf_count(&self) -> usize {
        with_source!(self, g => g.leaves.len())
    }

    pub fn tile_count(&self) -> usize {
        with_source!(self, g => g.tiles.len())
    }

    pub fn active_voxel_count(&self) -> u64 {
        with_source!(self, g => g.active_voxel_count())
    }
}
