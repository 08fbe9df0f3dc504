//! Grids whose leaves are located in the file but not decoded: what the bake reads, so that
//! a grid becomes cells a batch of decoded leaves at a time and its decoded leaves are never
//! held all at once (a billion single-precision velocities are 12 GiB decoded).
//!
//! Everything the bake checks before it makes cells (names, transforms, extents, counts,
//! its memory estimate) needs only the leaves' origins and active masks, which the tree's
//! topology holds.

use std::sync::Arc;

use files::input::Whole;

use super::codec::VdbValue;
use super::tree::{batch_bytes, decode_all, decode_leaves, LocatedLeaf, LocatedTree};
use super::values::Codec;
use super::VdbError;
use crate::grid::{AnyGrid, Grid, Leaf};

/// Where a grid's leaf buffers are, and how to decode them.
#[derive(Debug, Clone)]
pub struct LeafSource {
    data: Arc<Whole>,
    /// The end of the grid's bytes (a leaf is never read past it).
    end: usize,
    codec: Codec,
    file: String,
    grid: String,
}

impl LeafSource {
    /// Decodes `batch` (leaves of this source, in file order), then lets the file's pages
    /// they came from go ([`Whole::release`]).
    pub(crate) fn decode<V: VdbValue>(
        &self,
        background: V,
        batch: &[LocatedLeaf],
    ) -> Result<Vec<Leaf<V>>, VdbError> {
        let leaves = decode_leaves(&self.data[..self.end], self.codec, background, batch)
            .map_err(|e| e.locate(&self.file, Some(&self.grid)))?;
        self.data.release(batch_bytes(batch));
        Ok(leaves)
    }
}

/// One grid of a file, its leaves located.
#[derive(Debug, Clone)]
pub struct Located<V> {
    pub grid: Grid<V, LocatedLeaf>,
    pub source: LeafSource,
}

/// Every leaf of `located` decoded (a batch at a time, the file's pages let go behind).
fn decode<V: VdbValue>(located: Located<V>) -> Result<Grid<V>, VdbError> {
    let Located { grid, source } = located;
    let tree = LocatedTree {
        background: grid.background,
        tiles: grid.tiles,
        leaves: grid.leaves,
    };
    let release = |r| source.data.release(r);
    let leaves = decode_all(&source.data[..source.end], source.codec, &tree, &release)
        .map_err(|e| e.locate(&source.file, Some(&source.grid)))?;
    Ok(Grid {
        name: grid.name,
        transform: grid.transform,
        background: tree.background,
        leaves,
        tiles: tree.tiles,
    })
}

/// A located grid of any supported value type.
#[derive(Debug, Clone)]
pub enum AnyLocated {
    Float(Located<f32>),
    Double(Located<f64>),
    Vec3s(Located<[f32; 3]>),
    Vec3d(Located<[f64; 3]>),
}

impl AnyLocated {
    /// The grid with every leaf decoded.
    pub fn decode(self) -> Result<AnyGrid, VdbError> {
        Ok(match self {
            AnyLocated::Float(g) => AnyGrid::Float(decode(g)?),
            AnyLocated::Double(g) => AnyGrid::Double(decode(g)?),
            AnyLocated::Vec3s(g) => AnyGrid::Vec3s(decode(g)?),
            AnyLocated::Vec3d(g) => AnyGrid::Vec3d(decode(g)?),
        })
    }
}

pub(super) fn source(
    data: &Arc<Whole>,
    end: usize,
    codec: Codec,
    file: &str,
    grid: &str,
) -> LeafSource {
    LeafSource {
        data: Arc::clone(data),
        end,
        codec,
        file: file.to_string(),
        grid: grid.to_string(),
    }
}
