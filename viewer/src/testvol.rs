//! In-memory test volumes: `.qbk` contents made from closed-form fields sampled on one or
//! several nested grids, with leaf cells, bricks, regions and a KD-tree built by simple,
//! obviously correct methods (for tests and benchmarks; the real bake is `qbricks-bake`).
//!
//! Regions: every support boundary coordinate on each axis cuts space into an elementary
//! grid; each elementary cell gets the set of supports containing it; a KD-tree splits the
//! elementary grid at its middle index until a box has one set, and that box is a region.

use format::kd::BuildNode;
use format::{Aabb, Brick, BrickFile, Field, Level, Provenance, Region, SourceGrid, ValueRange};

/// One grid: cell `(i, j, k)` is centred at `origin + (i, j, k) * cell_width`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSpec {
    pub cell_width: f64,
    pub origin: [f64; 3],
    pub dims: [u32; 3],
}

impl GridSpec {
    /// Grid covering the box `min..max` with cells of width `w` (`max - min` a multiple of `w`).
    pub fn covering(min: [f64; 3], max: [f64; 3], w: f64) -> GridSpec {
        GridSpec {
            cell_width: w,
            origin: std::array::from_fn(|a| min[a] + 0.5 * w),
            dims: std::array::from_fn(|a| ((max[a] - min[a]) / w).round().max(1.0) as u32),
        }
    }

    fn cell_box(&self, idx: [u32; 3]) -> ([f64; 3], [f64; 3]) {
        let c: [f64; 3] = std::array::from_fn(|a| self.origin[a] + idx[a] as f64 * self.cell_width);
        (
            c.map(|x| x - 0.5 * self.cell_width),
            c.map(|x| x + 0.5 * self.cell_width),
        )
    }

    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let w = self.cell_width;
        (
            std::array::from_fn(|a| self.origin[a] - 0.5 * w),
            std::array::from_fn(|a| self.origin[a] + (self.dims[a] as f64 - 0.5) * w),
        )
    }
}

/// A closed-form scalar field.
pub type FieldFn<'a> = (&'a str, &'a (dyn Fn([f64; 3]) -> f64 + Sync));

/// Builds a brick file from `grids` (any order; levels by cell width, finest = 0), sampling
/// every field at leaf-cell centres; bricks hold at most `max_brick` cells per axis.
pub fn build(grids: &[GridSpec], fields: &[FieldFn], max_brick: u32) -> BrickFile {
    let mut widths: Vec<f64> = grids.iter().map(|g| g.cell_width).collect();
    widths.sort_by(f64::total_cmp);
    widths.dedup();
    let level_of = |w: f64| widths.iter().position(|&x| x == w).unwrap_or(0) as u32;
    let max_brick = max_brick.max(1);

    // Leaf cells: not fully inside a finer grid's box.
    let mut bricks: Vec<Brick> = Vec::new();
    let mut values: Vec<Vec<f32>> = vec![Vec::new(); fields.len()];
    for g in grids {
        let finer: Vec<([f64; 3], [f64; 3])> = grids
            .iter()
            .filter(|h| h.cell_width < g.cell_width)
            .map(GridSpec::bounds)
            .collect();
        let leaf = |idx: [u32; 3]| {
            let (lo, hi) = g.cell_box(idx);
            !finer
                .iter()
                .any(|(fl, fh)| (0..3).all(|a| lo[a] >= fl[a] - 1e-9 && hi[a] <= fh[a] + 1e-9))
        };
        let chunks: [u32; 3] = std::array::from_fn(|a| g.dims[a].div_ceil(max_brick));
        for cz in 0..chunks[2] {
            for cy in 0..chunks[1] {
                for cx in 0..chunks[0] {
                    let lo = [cx * max_brick, cy * max_brick, cz * max_brick];
                    let hi: [u32; 3] = std::array::from_fn(|a| (lo[a] + max_brick).min(g.dims[a]));
                    split_leaf_boxes(lo, hi, &leaf, &mut |lo, hi| {
                        let dims: [u32; 3] = std::array::from_fn(|a| hi[a] - lo[a]);
                        let first = values.first().map_or(0, Vec::len) as u64;
                        for k in lo[2]..hi[2] {
                            for j in lo[1]..hi[1] {
                                for i in lo[0]..hi[0] {
                                    let c: [f64; 3] = std::array::from_fn(|a| {
                                        g.origin[a] + [i, j, k][a] as f64 * g.cell_width
                                    });
                                    for (f, (_, func)) in fields.iter().enumerate() {
                                        values[f].push(func(c) as f32);
                                    }
                                }
                            }
                        }
                        bricks.push(Brick {
                            level: level_of(g.cell_width),
                            origin: std::array::from_fn(|a| {
                                g.origin[a] + lo[a] as f64 * g.cell_width
                            }),
                            cell_width: g.cell_width,
                            inv_cell_width: 1.0 / g.cell_width,
                            dims,
                            first_value: first,
                        });
                    });
                }
            }
        }
    }

    // Supports and the elementary grid of their boundaries.
    let supports: Vec<([f64; 3], [f64; 3])> = bricks
        .iter()
        .map(|b| {
            (
                std::array::from_fn(|a| b.origin[a] - b.cell_width),
                std::array::from_fn(|a| b.origin[a] + b.dims[a] as f64 * b.cell_width),
            )
        })
        .collect();
    let coords: [Vec<f64>; 3] = std::array::from_fn(|a| {
        let mut c: Vec<f64> = supports.iter().flat_map(|s| [s.0[a], s.1[a]]).collect();
        c.sort_by(f64::total_cmp);
        c.dedup_by(|x, y| (*x - *y).abs() < 1e-9);
        c
    });
    let n: [usize; 3] = std::array::from_fn(|a| coords[a].len().saturating_sub(1));
    let index = |a: usize, x: f64| {
        coords[a]
            .iter()
            .position(|&c| (c - x).abs() < 1e-9)
            .unwrap_or(0)
    };
    let mut sets: Vec<Vec<u32>> = vec![Vec::new(); n[0] * n[1] * n[2]];
    for (b, (lo, hi)) in supports.iter().enumerate() {
        let l: [usize; 3] = std::array::from_fn(|a| index(a, lo[a]));
        let h: [usize; 3] = std::array::from_fn(|a| index(a, hi[a]));
        for k in l[2]..h[2] {
            for j in l[1]..h[1] {
                for i in l[0]..h[0] {
                    sets[i + n[0] * (j + n[1] * k)].push(b as u32);
                }
            }
        }
    }

    // KD-tree over the elementary grid; uniform boxes become regions.
    let mut out = Builder {
        coords: &coords,
        n,
        sets: &sets,
        kd: Vec::new(),
        regions: Vec::new(),
        region_bricks: Vec::new(),
    };
    if n.iter().all(|&x| x > 0) && !bricks.is_empty() {
        out.node([0, 0, 0], n);
    }
    let Builder {
        kd,
        regions: boxed_regions,
        region_bricks,
        ..
    } = out;
    let (kd_root, kd_nodes, kd_axes) = format::kd::pack(&kd);
    let regions: Vec<Region> = boxed_regions.iter().map(|(_, r)| *r).collect();

    // Region ranges over the cells whose support overlaps the region.
    let mut region_ranges = Vec::with_capacity(regions.len() * fields.len());
    for (bounds, r) in &boxed_regions {
        for (f, vals) in values.iter().enumerate() {
            let _ = f;
            let mut lo = f32::INFINITY;
            let mut hi = f32::NEG_INFINITY;
            for &b in
                &region_bricks[r.bricks_start as usize..(r.bricks_start + r.bricks_len) as usize]
            {
                let br = &bricks[b as usize];
                let w = br.cell_width;
                let range: [(i64, i64); 3] = std::array::from_fn(|a| {
                    let i0 = ((bounds.min[a] - br.origin[a]) / w - 1.0).floor() as i64 + 1;
                    let i1 = ((bounds.max[a] - br.origin[a]) / w + 1.0).ceil() as i64 - 1;
                    (i0.max(0), i1.min(br.dims[a] as i64 - 1))
                });
                for k in range[2].0..=range[2].1 {
                    for j in range[1].0..=range[1].1 {
                        for i in range[0].0..=range[0].1 {
                            let idx = br.first_value as usize
                                + i as usize
                                + br.dims[0] as usize
                                    * (j as usize + br.dims[1] as usize * k as usize);
                            lo = lo.min(vals[idx]);
                            hi = hi.max(vals[idx]);
                        }
                    }
                }
            }
            region_ranges.push(ValueRange { min: lo, max: hi });
        }
    }

    let levels = widths
        .iter()
        .enumerate()
        .map(|(l, &w)| {
            let bs = bricks.iter().filter(|b| b.level == l as u32);
            Level {
                cell_width: w,
                cells: bs
                    .clone()
                    .map(|b| b.dims.iter().map(|&d| d as u64).product::<u64>())
                    .sum(),
                bricks: bs.count() as u32,
            }
        })
        .collect();
    let fields_out = fields
        .iter()
        .zip(values)
        .map(|((name, _), v)| {
            let min = v.iter().copied().fold(f32::INFINITY, f32::min);
            let max = v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let mut histogram = vec![0u64; 16];
            for &x in &v {
                let bin = if max > min {
                    ((x - min) / (max - min) * 16.0) as usize
                } else {
                    0
                };
                histogram[bin.min(15)] += 1;
            }
            Field {
                name: name.to_string(),
                min,
                max,
                histogram,
                values: v,
            }
        })
        .collect();
    let bounds = Aabb {
        min: std::array::from_fn(|a| coords[a].first().copied().unwrap_or(0.0)),
        max: std::array::from_fn(|a| coords[a].last().copied().unwrap_or(0.0)),
    };
    BrickFile {
        provenance: Provenance {
            source: "testvol".into(),
            grids: grids
                .iter()
                .enumerate()
                .map(|(i, g)| SourceGrid {
                    name: format!("grid{i}"),
                    voxel_size: [g.cell_width; 3],
                    level: level_of(g.cell_width),
                })
                .collect(),
            bake_options: "{}".into(),
            tool_version: "testvol".into(),
        },
        bounds,
        levels,
        fields: fields_out,
        bricks,
        regions,
        region_bricks,
        region_ranges,
        kd_root,
        kd_nodes,
        kd_axes,
    }
}

/// Splits the index box `lo..hi` into boxes of leaf cells only.
fn split_leaf_boxes(
    lo: [u32; 3],
    hi: [u32; 3],
    leaf: &dyn Fn([u32; 3]) -> bool,
    emit: &mut dyn FnMut([u32; 3], [u32; 3]),
) {
    let (mut all, mut none) = (true, true);
    for k in lo[2]..hi[2] {
        for j in lo[1]..hi[1] {
            for i in lo[0]..hi[0] {
                if leaf([i, j, k]) {
                    none = false;
                } else {
                    all = false;
                }
            }
        }
    }
    if none {
        return;
    }
    if all {
        emit(lo, hi);
        return;
    }
    let a = (0..3).max_by_key(|&a| hi[a] - lo[a]).unwrap_or(0);
    let mid = lo[a] + (hi[a] - lo[a]) / 2;
    let mut h1 = hi;
    h1[a] = mid;
    let mut l2 = lo;
    l2[a] = mid;
    split_leaf_boxes(lo, h1, leaf, emit);
    split_leaf_boxes(l2, hi, leaf, emit);
}

struct Builder<'a> {
    coords: &'a [Vec<f64>; 3],
    n: [usize; 3],
    sets: &'a [Vec<u32>],
    kd: Vec<format::kd::BuildNode>,
    /// Each region with its box (the file derives the box from the tree).
    regions: Vec<(Aabb, Region)>,
    region_bricks: Vec<u32>,
}

impl Builder<'_> {
    fn set(&self, i: usize, j: usize, k: usize) -> &[u32] {
        &self.sets[i + self.n[0] * (j + self.n[1] * k)]
    }

    fn node(&mut self, lo: [usize; 3], hi: [usize; 3]) -> u32 {
        let id = self.kd.len() as u32;
        self.kd.push(BuildNode::Leaf { region: None });
        let first = self.set(lo[0], lo[1], lo[2]).to_vec();
        let uniform = (lo[2]..hi[2]).all(|k| {
            (lo[1]..hi[1]).all(|j| (lo[0]..hi[0]).all(|i| self.set(i, j, k) == first.as_slice()))
        });
        if uniform {
            if !first.is_empty() {
                let r = self.regions.len() as u32;
                self.regions.push((
                    Aabb {
                        min: std::array::from_fn(|a| self.coords[a][lo[a]]),
                        max: std::array::from_fn(|a| self.coords[a][hi[a]]),
                    },
                    Region {
                        bricks_start: self.region_bricks.len() as u32,
                        bricks_len: first.len() as u32,
                    },
                ));
                self.region_bricks.extend_from_slice(&first);
                self.kd[id as usize] = BuildNode::Leaf { region: Some(r) };
            }
            return id;
        }
        let a = (0..3).max_by_key(|&a| hi[a] - lo[a]).unwrap_or(0);
        let mid = lo[a] + (hi[a] - lo[a]) / 2;
        let mut h1 = hi;
        h1[a] = mid;
        let mut l2 = lo;
        l2[a] = mid;
        let left = self.node(lo, h1);
        let right = self.node(l2, hi);
        self.kd[id as usize] = BuildNode::Inner {
            axis: a as u8,
            split: self.coords[a][mid],
            left,
            right,
        };
        id
    }
}

/// The bytes of the valid `.qbk` file `good` with one field value's lowest mantissa bit
/// flipped: the archive stays valid, its payload checksum fails (what the checksum tests
/// of the commands and the window open).
pub fn with_one_value_flipped(good: &[u8]) -> Vec<u8> {
    let view = format::BrickFileView::from_bytes(std::path::Path::new("good.qbk"), good)
        .expect("a valid file");
    let values = &view.file().fields[0].values;
    let probe = values[values.len() / 2].to_native().to_le_bytes();
    let at = good
        .windows(4)
        .position(|w| w == probe)
        .expect("the value's bytes are in the file");
    let mut flipped = good.to_vec();
    flipped[at] ^= 1;
    flipped
}

/// Serialises `file` and opens it the way the viewer opens a file on disk.
pub fn open(file: &BrickFile) -> Result<format::BrickFileView, format::FormatError> {
    let path = std::path::Path::new("testvol.qbk");
    let bytes = format::writer::to_bytes(file).map_err(|kind| format::FormatError {
        path: path.to_path_buf(),
        kind,
    })?;
    format::BrickFileView::from_bytes(path, &bytes)
}

/// Two levels: a coarse grid of `n`³ cells of width 2 over `[0, 2n]`³ and a fine grid of
/// `n`³ cells of width 1 over `[n/2, 3n/2]`³ (coarse cells under it are dropped), plus
/// `offset` added to every coordinate.
pub fn nested(n: u32, offset: [f64; 3], fields: &[FieldFn], max_brick: u32) -> BrickFile {
    let nf = n as f64;
    let coarse = GridSpec::covering(offset, offset.map(|o| o + 2.0 * nf), 2.0);
    let fine = GridSpec::covering(
        offset.map(|o| o + 0.5 * nf),
        offset.map(|o| o + 1.5 * nf),
        1.0,
    );
    build(&[coarse, fine], fields, max_brick)
}

/// Tracing parameters for tests: `strategy` at `step` cells in `mode` around `iso` on field
/// 0, a band of σ 0.1 (peak 1.6, ±2σ), no colour field, no clipping, point-sampled opacity.
pub fn params(
    vol: &crate::volume::Volume,
    strategy: crate::sampling::Strategy,
    step: f64,
    mode: crate::transfer::Mode,
    iso: f64,
) -> crate::sampling::Params {
    crate::sampling::Params {
        strategy,
        step,
        tf: crate::transfer::Transfer {
            mode,
            iso,
            band: crate::transfer::Band {
                sigma: 0.1,
                peak_opacity: 1.6,
                k: 2.0,
            },
        },
        field: 0,
        colour_field: None,
        delta0: 0.5 * vol.finest_w,
        clip: None,
        preintegrated: None,
    }
}
