//! Tiles: the unit of work of a frame and what one rendered tile hands back, shared by
//! the frame loop ([`crate::render`]) that renders them and the film
//! ([`crate::film`]) that sums them.

use std::ops::Range;

use crate::ray::FirstSurface;
use crate::sampling::Stats;

/// Tile edge in pixels.
pub(crate) const TILE: u32 = 16;

/// A rectangle of pixels `[x0, x1) × [y0, y1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tile {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl Tile {
    /// The `edge`×`edge` groups of the tile's pixels, row by row from its top left, the
    /// last of each row and column cut at the tile's edge, as rectangles `(x0, y0, x1,
    /// y1)` in pixels: the groups of camera rays that share a frustum.
    pub(crate) fn groups(&self, edge: u32) -> impl Iterator<Item = (f64, f64, f64, f64)> {
        let Tile { x0, y0, x1, y1 } = *self;
        let edge = edge.max(1);
        (y0..y1).step_by(edge as usize).flat_map(move |gy| {
            (x0..x1).step_by(edge as usize).map(move |gx| {
                let (gx1, gy1) = ((gx + edge).min(x1), (gy + edge).min(y1));
                (f64::from(gx), f64::from(gy), f64::from(gx1), f64::from(gy1))
            })
        })
    }

    /// The whole `width`×`height` image as one tile.
    #[cfg(test)]
    pub(crate) fn image(width: u32, height: u32) -> Tile {
        Tile {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        }
    }
}

/// The [`TILE`]-sized tiles of a `width`×`height` image, row by row from the top left.
pub fn tiles(width: u32, height: u32) -> Vec<Tile> {
    let (tx, ty) = (width.div_ceil(TILE), height.div_ceil(TILE));
    (0..ty)
        .flat_map(|j| {
            (0..tx).map(move |i| Tile {
                x0: i * TILE,
                y0: j * TILE,
                x1: ((i + 1) * TILE).min(width),
                y1: ((j + 1) * TILE).min(height),
            })
        })
        .collect()
}

/// One rendered tile: per pixel (row-major inside the tile) the sum of the colours of
/// samples `samples`, plus the work it took.
#[derive(Debug, Clone)]
pub struct TileResult {
    pub tile: Tile,
    pub samples: Range<u32>,
    pub sum: Vec<[f64; 3]>,
    /// Per pixel (row-major inside the tile), how many of `samples` hit.
    pub(crate) hit_samples: Vec<u32>,
    /// Per pixel, what sample 0 met first; empty when `samples` does not hold sample 0.
    pub(crate) first: Vec<FirstSurface>,
    pub stats: Stats,
    pub rays: u64,
    pub hits: u64,
}
