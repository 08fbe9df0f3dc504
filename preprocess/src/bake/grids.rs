//! The grids a bake takes: decoded ([`AnyGrid`]), or located in their file
//! ([`AnyLocated`]), whose leaves are decoded a batch at a time as they become cells
//! ([`CellSet::from_leaves`]). A bake from a file takes located grids, so that it never
//! holds a grid's decoded leaves whole; the library's [`super::bake`] takes decoded ones.
//! Every check made before the cells (names, extents, counts, memory) reads only the
//! leaves' topology, which both have.

use bytemuck::Pod;

use crate::cells::{CellSet, Keep, Slots};
use crate::error::BakeError;
use crate::grid::{AnyGrid, Grid, GridKind, Transform};
use crate::vdb::codec::VdbValue;
use crate::vdb::{AnyLocated, Located, VdbError};

/// A grid given to the bake.
#[derive(Debug)]
pub enum BakeGrid {
    Decoded(AnyGrid),
    Located(AnyLocated),
}

impl From<AnyGrid> for BakeGrid {
    fn from(g: AnyGrid) -> Self {
        BakeGrid::Decoded(g)
    }
}

impl From<AnyLocated> for BakeGrid {
    fn from(g: AnyLocated) -> Self {
        BakeGrid::Located(g)
    }
}

/// Evaluates `$body` with `$g` bound to the typed grid (`&Grid<V, L>`, leaves decoded or
/// located) inside whichever variant `$any` is: for code that reads the topology only.
macro_rules! with_topology {
    ($any:expr, $g:ident => $body:expr) => {
        match $any {
            BakeGrid::Decoded(AnyGrid::Float($g)) => $body,
            BakeGrid::Decoded(AnyGrid::Double($g)) => $body,
            BakeGrid::Decoded(AnyGrid::Vec3s($g)) => $body,
            BakeGrid::Decoded(AnyGrid::Vec3d($g)) => $body,
            BakeGrid::Located(AnyLocated::Float(Located { grid: $g, .. })) => $body,
            BakeGrid::Located(AnyLocated::Double(Located { grid: $g, .. })) => $body,
            BakeGrid::Located(AnyLocated::Vec3s(Located { grid: $g, .. })) => $body,
            BakeGrid::Located(AnyLocated::Vec3d(Located { grid: $g, .. })) => $body,
        }
    };
}
pub(super) use with_topology;

impl BakeGrid {
    pub fn name(&self) -> &str {
        with_topology!(self, g => &g.name)
    }

    pub fn transform(&self) -> Transform {
        with_topology!(self, g => g.transform)
    }

    /// Active voxels, tiles counted as the voxels they cover.
    pub fn active_voxel_count(&self) -> u64 {
        with_topology!(self, g => g.active_voxel_count())
    }

    /// A vec3 grid (single or double precision).
    pub fn is_vector(&self) -> bool {
        matches!(
            self,
            BakeGrid::Decoded(AnyGrid::Vec3s(_) | AnyGrid::Vec3d(_))
                | BakeGrid::Located(AnyLocated::Vec3s(_) | AnyLocated::Vec3d(_))
        )
    }

    pub fn kind(&self) -> GridKind {
        if self.is_vector() {
            GridKind::Vector
        } else {
            GridKind::Scalar
        }
    }

    /// Bytes of one value as stored (a cell's value at the precision the file has).
    pub fn value_bytes(&self) -> u64 {
        fn size<V, L>(_: &Grid<V, L>) -> u64 {
            std::mem::size_of::<V>() as u64
        }
        with_topology!(self, g => size(g))
    }

    /// Whether its leaves are decoded when it becomes cells, a batch at a time.
    pub fn is_located(&self) -> bool {
        matches!(self, BakeGrid::Located(_))
    }

    /// Bytes of the file its leaves' buffers take, for a grid located in a file.
    pub fn located_bytes(&self) -> Option<u64> {
        let sum = |leaves: &[crate::vdb::tree::LocatedLeaf]| {
            leaves.iter().map(|l| l.bytes.len() as u64).sum::<u64>()
        };
        match self {
            BakeGrid::Decoded(_) => None,
            BakeGrid::Located(AnyLocated::Float(g)) => Some(sum(&g.grid.leaves)),
            BakeGrid::Located(AnyLocated::Double(g)) => Some(sum(&g.grid.leaves)),
            BakeGrid::Located(AnyLocated::Vec3s(g)) => Some(sum(&g.grid.leaves)),
            BakeGrid::Located(AnyLocated::Vec3d(g)) => Some(sum(&g.grid.leaves)),
        }
    }

    /// The grid with every leaf decoded.
    pub fn decode(self) -> Result<AnyGrid, VdbError> {
        match self {
            BakeGrid::Decoded(g) => Ok(g),
            BakeGrid::Located(g) => g.decode(),
        }
    }
}

/// The cell set of a decoded grid and its values converted by `conv`.
pub(super) fn decoded_cells<V: Copy, T: Pod>(
    grid: Grid<V>,
    level: u32,
    conv: impl Fn(V) -> T,
    keep: Keep<'_>,
) -> Result<(CellSet, Slots<T>), BakeError> {
    CellSet::from_leaves(grid, level, conv, keep, Ok)
}

/// The cell set of a located grid and its values converted by `conv`, its leaves decoded a
/// batch at a time.
pub(super) fn located_cells<V: VdbValue, T: Pod>(
    located: Located<V>,
    level: u32,
    conv: impl Fn(V) -> T,
    keep: Keep<'_>,
) -> Result<(CellSet, Slots<T>), BakeError> {
    let Located { grid, source } = located;
    let background = grid.background;
    CellSet::from_leaves(grid, level, conv, keep, |batch| {
        source
            .decode(background, &batch)
            .map_err(|e| BakeError::Vdb(Box::new(e)))
    })
}
