//! Read access to an opened `.qbk` file, laid out for the ray caster.
//!
//! Field values are read **zero-copy** from the archive: each field is kept as a borrowed
//! slice of archived little-endian `f32`s (a no-op conversion on little-endian hosts), so
//! opening costs nothing proportional to the number of cells and the page cache (or the
//! memory map) is the only copy of the big arrays. The small structural tables — bricks,
//! regions, KD nodes — are copied into native structs at open: they are a few hundred
//! bytes per brick, they are touched at every sample, and converting them once lets us
//! (a) move geometry into a local frame centred on the data (coordinates offset by 1e6
//! keep sub-cell precision), (b) precompute `1 / cell_width`, and (c) check every index
//! once (brick → values, region → bricks, KD children, KD acyclicity) so the hot loops
//! index without ever reading out of bounds or looping forever on a malformed file.

use format::{ArchivedBrickFile, ArchivedKdNode};

/// Archived `f32` as stored in the file.
pub type StoredF32 = rkyv::Archived<f32>;

#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    #[error("{what}: expected {expected}, found {found}")]
    Invalid {
        what: String,
        expected: String,
        found: String,
    },
    #[error("field {0:?} is not in the file (fields: {1})")]
    NoSuchField(String, String),
    /// A view setting names a field the file does not have.
    #[error("{setting}: {source}")]
    Setting {
        setting: &'static str,
        source: Box<VolumeError>,
    },
}

fn invalid(what: impl Into<String>, expected: impl ToString, found: impl ToString) -> VolumeError {
    VolumeError::Invalid {
        what: what.into(),
        expected: expected.to_string(),
        found: found.to_string(),
    }
}

/// A brick in the local frame.
#[derive(Debug, Clone, Copy)]
pub struct BrickN {
    /// Centre of the first cell, local frame.
    pub origin: [f64; 3],
    pub w: f64,
    pub inv_w: f64,
    pub dims: [i64; 3],
    pub first: usize,
    pub level: u32,
}

/// A region in the local frame.
#[derive(Debug, Clone, Copy)]
pub struct RegionN {
    pub min: [f64; 3],
    pub max: [f64; 3],
    pub bricks_start: usize,
    pub bricks_len: usize,
    /// Cell width of the finest brick of the region (the local sampling unit).
    pub finest_w: f64,
    /// All bricks share one level and one lattice.
    pub single_lattice: bool,
}

#[derive(Debug, Clone, Copy)]
pub enum KdN {
    Inner {
        axis: usize,
        split: f64,
        left: u32,
        right: u32,
    },
    Leaf(Option<u32>),
}

/// A KD node packed for traversal with one field's value range (32 bytes: the node,
/// its range and its emptiness flag share a cache line).
#[derive(Debug, Clone, Copy)]
pub struct PackedNode {
    pub split: f64,
    /// Inner: left child; leaf: region or `u32::MAX` for empty space.
    pub a: u32,
    /// Inner: right child.
    pub b: u32,
    pub min: f32,
    pub max: f32,
    /// 0..=2: inner node splitting this axis; 3: leaf.
    pub axis: u8,
    /// Every leaf below holds a region.
    pub full: bool,
}

#[derive(Debug, Clone)]
pub struct FieldInfo {
    pub name: String,
    pub min: f32,
    pub max: f32,
}

/// The volume as the ray caster sees it.
pub struct Volume<'a> {
    /// World position of the local frame's origin (`world = local + frame`).
    pub frame: [f64; 3],
    /// Union of supports, local frame.
    pub bounds_min: [f64; 3],
    pub bounds_max: [f64; 3],
    pub fields: Vec<FieldInfo>,
    pub(crate) values: Vec<&'a [StoredF32]>,
    pub bricks: Vec<BrickN>,
    pub regions: Vec<RegionN>,
    pub region_bricks: Vec<u32>,
    /// `[min, max]` per region and field: entry `r * fields + f`.
    pub region_ranges: Vec<[f32; 2]>,
    pub kd: Vec<KdN>,
    /// The KD tree packed for traversal, one copy per field (ranges of that field).
    pub packed: Vec<Vec<PackedNode>>,
    /// Depth of the KD tree (root alone = 1).
    pub kd_depth: usize,
    /// Finest cell width in the file (reference length for opacity).
    pub finest_w: f64,
}

impl<'a> Volume<'a> {
    /// Builds the ray caster's view of a validated archive, checking every index once.
    pub fn new(file: &'a ArchivedBrickFile) -> Result<Volume<'a>, VolumeError> {
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
        let loc = |p: [f64; 3]| -> [f64; 3] { std::array::from_fn(|a| p[a] - frame[a]) };

        let fields: Vec<FieldInfo> = file
            .fields
            .iter()
            .map(|f| FieldInfo {
                name: f.name.as_str().to_string(),
                min: f.min.to_native(),
                max: f.max.to_native(),
            })
            .collect();
        let values: Vec<&[StoredF32]> = file.fields.iter().map(|f| f.values.as_slice()).collect();
        let n_values = values.first().map_or(0, |v| v.len());
        for (f, v) in values.iter().enumerate() {
            if v.len() != n_values {
                return Err(invalid(
                    format!("field {:?} values", fields[f].name),
                    n_values,
                    v.len(),
                ));
            }
        }

        // Bricks.
        let mut bricks = Vec::with_capacity(file.bricks.len());
        let mut finest_w = f64::INFINITY;
        for (i, br) in file.bricks.iter().enumerate() {
            let w = br.cell_width.to_native();
            if !(w.is_finite() && w > 0.0) {
                return Err(invalid(format!("brick {i} cell_width"), "> 0", w));
            }
            let dims: [u32; 3] = std::array::from_fn(|a| br.dims[a].to_native());
            if dims.contains(&0) {
                return Err(invalid(
                    format!("brick {i} dims"),
                    "each >= 1",
                    format!("{dims:?}"),
                ));
            }
            let Some(n) = dims
                .iter()
                .try_fold(1u64, |acc, &d| acc.checked_mul(d as u64))
            else {
                return Err(invalid(
                    format!("brick {i} dims"),
                    "a cell count that fits 64 bits",
                    format!("{dims:?}"),
                ));
            };
            let first = br.first_value.to_native();
            if !fields.is_empty() && first.checked_add(n).is_none_or(|end| end > n_values as u64) {
                return Err(invalid(
                    format!("brick {i} values {first}+{n}"),
                    format!("<= {n_values}"),
                    first.saturating_add(n),
                ));
            }
            let origin = loc(std::array::from_fn(|a| br.origin[a].to_native()));
            if origin.iter().any(|o| !o.is_finite()) {
                return Err(invalid(format!("brick {i} origin"), "finite", "non-finite"));
            }
            finest_w = finest_w.min(w);
            bricks.push(BrickN {
                origin,
                w,
                inv_w: 1.0 / w,
                dims: dims.map(i64::from),
                first: first as usize,
                level: br.level.to_native(),
            });
        }

        // Regions.
        let region_bricks: Vec<u32> = file.region_bricks.iter().map(|b| b.to_native()).collect();
        if let Some(bad) = region_bricks.iter().find(|&&b| b as usize >= bricks.len()) {
            return Err(invalid(
                "region brick id",
                format!("< {}", bricks.len()),
                bad,
            ));
        }
        let mut regions = Vec::with_capacity(file.regions.len());
        for (i, r) in file.regions.iter().enumerate() {
            let start = r.bricks_start.to_native() as usize;
            let len = r.bricks_len.to_native() as usize;
            if start + len > region_bricks.len() {
                return Err(invalid(
                    format!("region {i} bricks {start}+{len}"),
                    format!("<= {}", region_bricks.len()),
                    start + len,
                ));
            }
            let list = &region_bricks[start..start + len];
            let finest = list
                .iter()
                .map(|&b| bricks[b as usize].w)
                .fold(f64::INFINITY, f64::min);
            let single_lattice = list.windows(2).all(|p| {
                let (x, y) = (&bricks[p[0] as usize], &bricks[p[1] as usize]);
                x.w == y.w
                    && (0..3).all(|a| {
                        let d = (x.origin[a] - y.origin[a]) * x.inv_w;
                        (d - d.round()).abs() < 1e-6
                    })
            });
            regions.push(RegionN {
                min: loc(std::array::from_fn(|a| r.bounds.min[a].to_native())),
                max: loc(std::array::from_fn(|a| r.bounds.max[a].to_native())),
                bricks_start: start,
                bricks_len: len,
                finest_w: if finest.is_finite() { finest } else { 1.0 },
                single_lattice,
            });
        }
        let nf = fields.len();
        if file.region_ranges.len() != regions.len() * nf {
            return Err(invalid(
                "region_ranges length",
                regions.len() * nf,
                file.region_ranges.len(),
            ));
        }
        let region_ranges: Vec<[f32; 2]> = file
            .region_ranges
            .iter()
            .map(|r| [r.min.to_native(), r.max.to_native()])
            .collect();

        // KD tree: children in range, every node reached at most once (a tree, no cycles).
        let mut kd: Vec<KdN> = file
            .kd_nodes
            .iter()
            .map(|n| match n {
                ArchivedKdNode::Inner {
                    axis,
                    split,
                    left,
                    right,
                } => KdN::Inner {
                    axis: *axis as usize,
                    split: split.to_native(),
                    left: left.to_native(),
                    right: right.to_native(),
                },
                ArchivedKdNode::Leaf { region } => {
                    KdN::Leaf(region.as_ref().map(|r| r.to_native()))
                }
            })
            .collect();
        if kd.is_empty() && !regions.is_empty() {
            return Err(invalid("kd_nodes", "a tree over the regions", "none"));
        }
        let mut seen = vec![false; kd.len()];
        let mut stack: Vec<(u32, usize)> = if kd.is_empty() { vec![] } else { vec![(0, 1)] };
        let mut kd_depth = 0;
        let mut order = Vec::with_capacity(kd.len());
        while let Some((n, depth)) = stack.pop() {
            let idx = n as usize;
            if idx >= kd.len() {
                return Err(invalid("kd child index", format!("< {}", kd.len()), n));
            }
            if seen[idx] {
                return Err(invalid(
                    format!("kd node {n}"),
                    "reached once",
                    "reached twice",
                ));
            }
            seen[idx] = true;
            order.push(n);
            kd_depth = kd_depth.max(depth);
            match &mut kd[idx] {
                KdN::Inner {
                    axis,
                    split,
                    left,
                    right,
                } => {
                    if *axis > 2 || !split.is_finite() {
                        return Err(invalid(
                            format!("kd node {n}"),
                            "axis 0..2, finite split",
                            *axis,
                        ));
                    }
                    *split -= frame[*axis];
                    stack.push((*left, depth + 1));
                    stack.push((*right, depth + 1));
                }
                KdN::Leaf(Some(r)) if *r as usize >= regions.len() => {
                    return Err(invalid(
                        format!("kd leaf {n} region"),
                        format!("< {}", regions.len()),
                        *r,
                    ));
                }
                KdN::Leaf(_) => {}
            }
        }

        // Per node: value range of every field over its subtree's regions, and whether
        // every leaf below holds a region (no empty space inside the node's cell).
        let mut kd_ranges = vec![[f32::INFINITY, f32::NEG_INFINITY]; kd.len() * nf];
        let mut kd_full = vec![false; kd.len()];
        for &n in order.iter().rev() {
            let n = n as usize;
            match kd[n] {
                KdN::Leaf(Some(r)) => {
                    kd_full[n] = true;
                    for f in 0..nf {
                        kd_ranges[n * nf + f] = region_ranges[r as usize * nf + f];
                    }
                }
                KdN::Leaf(None) => {}
                KdN::Inner { left, right, .. } => {
                    let (l, r) = (left as usize, right as usize);
                    kd_full[n] = kd_full[l] && kd_full[r];
                    for f in 0..nf {
                        let (a, b) = (kd_ranges[l * nf + f], kd_ranges[r * nf + f]);
                        kd_ranges[n * nf + f] = [a[0].min(b[0]), a[1].max(b[1])];
                    }
                }
            }
        }

        let packed = (0..nf.max(1))
            .map(|f| {
                kd.iter()
                    .enumerate()
                    .map(|(n, node)| {
                        let r = if nf > 0 {
                            kd_ranges[n * nf + f]
                        } else {
                            [0.0, 0.0]
                        };
                        let (split, a, b, axis) = match *node {
                            KdN::Inner {
                                axis,
                                split,
                                left,
                                right,
                            } => (split, left, right, axis as u8),
                            KdN::Leaf(r) => (0.0, r.unwrap_or(u32::MAX), 0, 3),
                        };
                        PackedNode {
                            split,
                            a,
                            b,
                            min: r[0],
                            max: r[1],
                            axis,
                            full: kd_full[n],
                        }
                    })
                    .collect()
            })
            .collect();

        Ok(Volume {
            packed,
            frame,
            bounds_min: loc(bmin),
            bounds_max: loc(bmax),
            fields,
            values,
            bricks,
            regions,
            region_bricks,
            region_ranges,
            kd,
            kd_depth,
            finest_w: if finest_w.is_finite() { finest_w } else { 1.0 },
        })
    }

    /// Index of the field called `name`.
    pub fn field_index(&self, name: &str) -> Result<usize, VolumeError> {
        self.fields
            .iter()
            .position(|f| f.name == name)
            .ok_or_else(|| {
                let names: Vec<&str> = self.fields.iter().map(|f| f.name.as_str()).collect();
                VolumeError::NoSuchField(name.to_string(), names.join(", "))
            })
    }

    /// World → local frame.
    pub fn to_local(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| p[a] - self.frame[a])
    }

    /// Local frame → world.
    pub fn to_world(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| p[a] + self.frame[a])
    }

    /// Local cell width of a segment's region (the finest width for a skipped subtree).
    #[inline]
    pub fn step_width(&self, region: u32) -> f64 {
        self.regions
            .get(region as usize)
            .map_or(self.finest_w, |r| r.finest_w)
    }

    /// Bricks of region `r`.
    #[inline]
    pub fn region_brick_ids(&self, r: usize) -> &[u32] {
        let reg = &self.regions[r];
        &self.region_bricks[reg.bricks_start..reg.bricks_start + reg.bricks_len]
    }

    /// `[min, max]` of field `f` over region `r`.
    #[inline]
    pub fn range(&self, r: usize, f: usize) -> [f32; 2] {
        self.region_ranges[r * self.fields.len() + f]
    }

    /// Region containing the local point `p` (half-open boxes), by KD descent.
    pub fn region_at(&self, p: [f64; 3]) -> Option<u32> {
        let mut n = 0usize;
        // The KD tree was checked acyclic, so this loop ends within `kd_depth` steps.
        for _ in 0..=self.kd_depth {
            match self.kd.get(n)? {
                KdN::Inner {
                    axis,
                    split,
                    left,
                    right,
                } => n = if p[*axis] < *split { *left } else { *right } as usize,
                KdN::Leaf(r) => {
                    let r = (*r)?;
                    let reg = &self.regions[r as usize];
                    let inside = (0..3).all(|a| p[a] >= reg.min[a] && p[a] < reg.max[a]);
                    return inside.then_some(r);
                }
            }
        }
        None
    }

    /// Value of field `f`, cell `idx` (checked at open to be in range for every brick cell).
    #[inline]
    pub(crate) fn value(&self, f: usize, idx: usize) -> f32 {
        self.values[f][idx].to_native()
    }
}
