//! Checks of the schema's invariants, run after rkyv's structural validation (bytecheck).
//!
//! bytecheck proves that every pointer, length and enum tag in the archive is in bounds
//! and well-formed, so reading the archive cannot go wrong in a memory-safety sense. It
//! does not know what the numbers mean: a brick may still point past the end of the
//! value arrays, a KD node at a node that does not exist, or the KD "tree" may have a
//! cycle. This module checks exactly the invariants the queries and the viewer index
//! with, so that after [`check`] they can slice without further range checks failing
//! (they still use checked access, returning nothing rather than panicking, so that an
//! archive obtained without this check cannot crash them either).
//!
//! Errors are [`ValidationError`]s, one variant per check, whose messages name the
//! element, e.g. `regions[12].bricks[3]: brick 9001 out of range (512 bricks)`.

use crate::kd::{EMPTY, LEAF};
use crate::schema::ArchivedBrickFile;

/// A broken schema invariant, naming the element (`regions[12].bricks[3]`) and holding
/// what was expected and found. One variant per check, so callers and tests can match by
/// kind; the message is one line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ValidationError {
    /// The file's `bounds` with `min > max`, NaN or an infinity on an axis (every region's
    /// box is cut from it).
    #[error("bounds: expected finite min <= max on axis {axis}, found {min} > {max}")]
    BadBox { axis: usize, min: f64, max: f64 },
    #[error("levels[{level}].cell_width: expected > 0, found {width}")]
    LevelCellWidth { level: usize, width: f64 },
    /// Every field holds as many values as `fields[0]`.
    #[error("fields[{field}].values: expected {expected} values (as fields[0]), found {found}")]
    FieldLength {
        field: usize,
        expected: u64,
        found: u64,
    },
    #[error("bricks[{brick}].level: level {level} out of range ({levels} levels)")]
    BrickLevelOutOfRange {
        brick: usize,
        level: u32,
        levels: usize,
    },
    #[error("bricks[{brick}].dims: expected >= 1 cells per axis, found {dims:?}")]
    BrickEmptyDims { brick: usize, dims: [u32; 3] },
    /// The brick's cell count does not fit in a `u64`.
    #[error("bricks[{brick}].dims: {dims:?} is more cells than a file can hold")]
    BrickTooManyCells { brick: usize, dims: [u32; 3] },
    #[error("bricks[{brick}].cell_width: expected > 0, found {width}")]
    BrickCellWidth { brick: usize, width: f64 },
    #[error("bricks[{brick}].inv_cell_width: expected 1 / {width} = {}, found {found}", 1.0 / .width)]
    BrickInvCellWidth {
        brick: usize,
        width: f64,
        found: f64,
    },
    /// The brick's cell width is not its level's.
    #[error("bricks[{brick}].cell_width: {width:?} differs from its level {level}'s cell width {level_width:?}")]
    BrickWidthNotLevels {
        brick: usize,
        width: f64,
        level: u32,
        level_width: f64,
    },
    #[error("bricks[{brick}].origin: not finite")]
    BrickOriginNotFinite { brick: usize },
    /// The brick's values `first..first + len` are not all in the value arrays.
    #[error(
        "bricks[{brick}]: values {first}..{first}+{len} out of range ({values} values per field)"
    )]
    BrickOutOfRange {
        brick: usize,
        first: u64,
        len: u64,
        values: u64,
    },
    /// The region's slice of `region_bricks` is not all in it.
    #[error("regions[{region}]: bricks {start}..{start}+{len} out of range ({entries} region_bricks entries)")]
    RegionBricksOutOfRange {
        region: usize,
        start: u64,
        len: u64,
        entries: u64,
    },
    /// `region_bricks[entry]` names no brick; `in_region` is `(region, index in its list)`
    /// when a region's list holds the entry.
    #[error("{}: brick {id} out of range ({bricks} bricks)", entry_name(*.entry, *.in_region))]
    BrickIdOutOfRange {
        entry: usize,
        in_region: Option<(usize, usize)>,
        id: u32,
        bricks: usize,
    },
    #[error("region_ranges: expected {expected} entries ({regions} regions x {fields} fields), found {found}")]
    RegionRangesLength {
        expected: u64,
        regions: usize,
        fields: usize,
        found: usize,
    },
    #[error("kd_axes: expected {expected} entries (one per node), found {found}")]
    KdAxesLength { expected: usize, found: usize },
    /// An inner root must be node 0 (nodes are stored parent first).
    #[error("kd_root: expected node 0 or a leaf, found node {root}")]
    KdRootNotFirst { root: u32 },
    #[error("kd_axes[{node}]: expected 0, 1 or 2, found {axis}")]
    KdAxis { node: u32, axis: u8 },
    #[error("kd_nodes[{node}].split: NaN")]
    KdSplitNan { node: u32 },
    /// A split outside the file's bounds on its axis would give a region a box reaching
    /// past the data (a ray then stepped through 1e30 units of cells: found by the
    /// `qbk_open` fuzz target).
    #[error("kd_nodes[{node}].split: {split} on axis {axis} is outside the bounds {min}..{max}")]
    KdSplitOutsideBounds {
        node: u32,
        split: f64,
        axis: u8,
        min: f64,
        max: f64,
    },
    #[error("kd_nodes[{node}]: child {child} out of range ({nodes} nodes)")]
    KdChildOutOfRange { node: u32, child: u32, nodes: usize },
    /// A node reached twice from the root (a node with two parents) or a child stored
    /// before its parent (which is how a cycle shows: nodes are stored parent first).
    #[error(
        "kd_nodes[{node}]: child {child} is reached twice or stored before its parent (not a tree stored parent first)"
    )]
    KdNotATree { node: u32, child: u32 },
    /// A leaf reference names a region that does not exist; `node` is the parent
    /// (`None`: the root).
    #[error("{}: region {region} out of range ({regions} regions)", parent_name(*.node))]
    KdRegionOutOfRange {
        node: Option<u32>,
        region: u32,
        regions: usize,
    },
    /// A region in two leaves would have two boxes (a region's box is its leaf's cell).
    #[error("{}: region {region} is in a second leaf", parent_name(*.node))]
    KdRegionTwice { node: Option<u32>, region: u32 },
    #[error("regions[{region}]: in no KD-tree leaf")]
    RegionNotInTree { region: usize },
}

fn parent_name(node: Option<u32>) -> String {
    node.map_or_else(|| "kd_root".to_owned(), |i| format!("kd_nodes[{i}]"))
}

fn entry_name(entry: usize, in_region: Option<(usize, usize)>) -> String {
    match in_region {
        Some((i, j)) => format!("regions[{i}].bricks[{j}]"),
        None => format!("region_bricks[{entry}]"),
    }
}

/// Checks the invariants of a structurally valid archive: [`check_top`], every brick
/// ([`check_brick`]), every region's list ([`check_region`], one flat pass over the
/// lists' entries) and the KD-tree ([`check_kd`]). Cost is linear in the number of
/// bricks, regions, region brick entries and KD nodes; the value arrays are not read.
pub fn check(file: &ArchivedBrickFile) -> Result<(), ValidationError> {
    check_top(file)?;
    for b in 0..file.bricks.len() {
        check_brick(file, b)?;
    }
    let n_entries = file.region_bricks.len() as u64;
    for (i, region) in file.regions.iter().enumerate() {
        let start = u64::from(region.bricks_start.to_native());
        let len = u64::from(region.bricks_len.to_native());
        if start + len > n_entries {
            return Err(ValidationError::RegionBricksOutOfRange {
                region: i,
                start,
                len,
                entries: n_entries,
            });
        }
    }
    // Every entry of every list names a brick: one flat pass over the entries (a list is
    // a slice of them, checked above), not one per region.
    let n_bricks = file.bricks.len();
    if let Some(at) = file
        .region_bricks
        .iter()
        .position(|id| id.to_native() as usize >= n_bricks)
    {
        let id = file.region_bricks[at].to_native();
        let in_region = file.regions.iter().enumerate().find_map(|(i, r)| {
            let start = r.bricks_start.to_native() as usize;
            let len = r.bricks_len.to_native() as usize;
            (start..start + len).contains(&at).then(|| (i, at - start))
        });
        return Err(ValidationError::BrickIdOutOfRange {
            entry: at,
            in_region,
            id,
            bricks: n_bricks,
        });
    }
    check_kd(file)
}

/// The invariants that do not grow with the data: the bounds, the levels, the fields'
/// lengths and the lengths of the tables indexed per region and per KD node. What a
/// reader that checks each brick, region and the tree where it reads them
/// ([`crate::Structure::OnUse`]) runs at open.
pub fn check_top(file: &ArchivedBrickFile) -> Result<(), ValidationError> {
    let n_regions = file.regions.len();
    let n_fields = file.fields.len();

    // Bounds: every region's box is cut from them.
    for a in 0..3 {
        let (lo, hi) = (
            file.bounds.min[a].to_native(),
            file.bounds.max[a].to_native(),
        );
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(ValidationError::BadBox {
                axis: a,
                min: lo,
                max: hi,
            });
        }
    }

    // Levels.
    for (i, level) in file.levels.iter().enumerate() {
        let w = level.cell_width.to_native();
        if !(w.is_finite() && w > 0.0) {
            return Err(ValidationError::LevelCellWidth { level: i, width: w });
        }
    }

    // Fields: one value per leaf cell in every field.
    let n_values = value_count(file);
    for (i, field) in file.fields.iter().enumerate() {
        if field.values.len() as u64 != n_values {
            return Err(ValidationError::FieldLength {
                field: i,
                expected: n_values,
                found: field.values.len() as u64,
            });
        }
    }

    let expected_ranges = n_regions as u64 * n_fields as u64;
    if file.region_ranges.len() as u64 != expected_ranges {
        return Err(ValidationError::RegionRangesLength {
            expected: expected_ranges,
            regions: n_regions,
            fields: n_fields,
            found: file.region_ranges.len(),
        });
    }
    if file.kd_axes.len() != file.kd_nodes.len() {
        return Err(ValidationError::KdAxesLength {
            expected: file.kd_nodes.len(),
            found: file.kd_axes.len(),
        });
    }
    Ok(())
}

/// Values per field (every field holds as many as the first, see [`check_top`]).
fn value_count(file: &ArchivedBrickFile) -> u64 {
    file.fields.first().map_or(0, |f| f.values.len() as u64)
}

/// Brick `i`'s invariants (an index past the bricks is [`ValidationError::BrickIdOutOfRange`]):
/// its level exists and has its cell width, its cells are at least one per axis and
/// their values all lie in the value arrays. Needs [`check_top`].
pub fn check_brick(file: &ArchivedBrickFile, i: usize) -> Result<(), ValidationError> {
    let n_levels = file.levels.len();
    let n_fields = file.fields.len();
    let n_values = value_count(file);
    let Some(brick) = file.bricks.get(i) else {
        return Err(ValidationError::BrickIdOutOfRange {
            entry: i,
            in_region: None,
            id: i as u32,
            bricks: file.bricks.len(),
        });
    };
    let level = brick.level.to_native();
    if level as usize >= n_levels {
        return Err(ValidationError::BrickLevelOutOfRange {
            brick: i,
            level,
            levels: n_levels,
        });
    }
    let dims = brick.dims.map(|d| d.to_native());
    if dims.contains(&0) {
        return Err(ValidationError::BrickEmptyDims { brick: i, dims });
    }
    let w = brick.cell_width.to_native();
    if !(w.is_finite() && w > 0.0) {
        return Err(ValidationError::BrickCellWidth { brick: i, width: w });
    }
    let inv = brick.inv_cell_width.to_native();
    if inv != 1.0 / w {
        return Err(ValidationError::BrickInvCellWidth {
            brick: i,
            width: w,
            found: inv,
        });
    }
    // The viewer steps through a region in units of its finest *level's* width and
    // reconstructs with the *bricks'* widths: a level far finer than its bricks made
    // every ray take millions of samples per region (found by the `qbk_open` fuzz
    // target). The baker merges widths equal to 1e-6, so 1e-3 is loose enough.
    let lw = file.levels[level as usize].cell_width.to_native();
    if (w - lw).abs() > 1e-3 * lw {
        return Err(ValidationError::BrickWidthNotLevels {
            brick: i,
            width: w,
            level,
            level_width: lw,
        });
    }
    if brick.origin.iter().any(|c| !c.to_native().is_finite()) {
        return Err(ValidationError::BrickOriginNotFinite { brick: i });
    }
    // Three u32 dims can hold up to 2^96 cells. Unchecked, the product wraps in
    // release builds (found by the `qbk_open` fuzz target): a brick of 2^22 x 2^21 x
    // 2^21 cells then counts as 0 cells, passes the range check below, and the viewer
    // indexes far past the value arrays.
    let Some(cells) = dims
        .iter()
        .try_fold(1u64, |n, &d| n.checked_mul(u64::from(d)))
    else {
        return Err(ValidationError::BrickTooManyCells { brick: i, dims });
    };
    if n_fields > 0 {
        let first = brick.first_value.to_native();
        let end = first.checked_add(cells);
        if end.is_none_or(|e| e > n_values) {
            return Err(ValidationError::BrickOutOfRange {
                brick: i,
                first,
                len: cells,
                values: n_values,
            });
        }
    }
    Ok(())
}

/// Region `r`'s list of bricks lies in `region_bricks`, and every brick it names exists
/// and passes [`check_brick`]: what reading the region's bricks needs. Needs
/// [`check_top`]; `r` past the regions is [`ValidationError::KdRegionOutOfRange`].
pub fn check_region(file: &ArchivedBrickFile, r: usize) -> Result<(), ValidationError> {
    let Some(region) = file.regions.get(r) else {
        return Err(ValidationError::KdRegionOutOfRange {
            node: None,
            region: r as u32,
            regions: file.regions.len(),
        });
    };
    let n_entries = file.region_bricks.len() as u64;
    let start = u64::from(region.bricks_start.to_native());
    let len = u64::from(region.bricks_len.to_native());
    if start + len > n_entries {
        return Err(ValidationError::RegionBricksOutOfRange {
            region: r,
            start,
            len,
            entries: n_entries,
        });
    }
    let n_bricks = file.bricks.len();
    for (j, id) in file.region_bricks[start as usize..(start + len) as usize]
        .iter()
        .enumerate()
    {
        let id = id.to_native();
        if id as usize >= n_bricks {
            return Err(ValidationError::BrickIdOutOfRange {
                entry: start as usize + j,
                in_region: Some((r, j)),
                id,
                bricks: n_bricks,
            });
        }
        check_brick(file, id as usize)?;
    }
    Ok(())
}

/// The KD nodes reachable from the root form a tree (no node has two parents, no
/// cycles), every index is in range, and every region sits in exactly one leaf (its box
/// is that leaf's cell). Linear in the nodes and regions; reads no brick.
pub fn check_kd(file: &ArchivedBrickFile) -> Result<(), ValidationError> {
    let nodes = file.kd_nodes.as_slice();
    let axes = file.kd_axes.as_slice();
    let n_regions = file.regions.len();
    if axes.len() != nodes.len() {
        return Err(ValidationError::KdAxesLength {
            expected: nodes.len(),
            found: axes.len(),
        });
    }
    let mut region_in_leaf = vec![false; n_regions];
    // A leaf reference (`parent`: the inner node naming it, `None` for the root).
    let mut leaf = |parent: Option<u32>, child: u32| -> Result<(), ValidationError> {
        if child == EMPTY {
            return Ok(());
        }
        let region = child & !LEAF;
        match region_in_leaf.get_mut(region as usize) {
            Some(seen) if *seen => Err(ValidationError::KdRegionTwice {
                node: parent,
                region,
            }),
            Some(seen) => {
                *seen = true;
                Ok(())
            }
            None => Err(ValidationError::KdRegionOutOfRange {
                node: parent,
                region,
                regions: n_regions,
            }),
        }
    };
    let root = file.kd_root.to_native();
    // Sized by counts that bytecheck has proven to be backed by bytes of the file.
    let mut reached = vec![false; nodes.len()];
    if root & LEAF != 0 {
        leaf(None, root)?;
    } else if root != 0 || nodes.is_empty() {
        return Err(ValidationError::KdRootNotFirst { root });
    } else {
        reached[0] = true;
    }
    // One pass in storage order. Writers store a parent before its children (depth
    // first), so requiring `child > parent` rules out cycles, and a node reached from two
    // parents is caught when the second one names it: what the root reaches is a tree.
    // A node the root does not reach is never walked and is skipped, as a walk would.
    for (n, node) in nodes.iter().enumerate() {
        if !reached[n] {
            continue;
        }
        let i = n as u32;
        if axes[n] > 2 {
            return Err(ValidationError::KdAxis {
                node: i,
                axis: axes[n],
            });
        }
        let split = node.split.to_native();
        if split.is_nan() {
            return Err(ValidationError::KdSplitNan { node: i });
        }
        let a = usize::from(axes[n]);
        let (lo, hi) = (
            file.bounds.min[a].to_native(),
            file.bounds.max[a].to_native(),
        );
        if !(split >= lo && split <= hi) {
            return Err(ValidationError::KdSplitOutsideBounds {
                node: i,
                split,
                axis: axes[n],
                min: lo,
                max: hi,
            });
        }
        for child in [node.left.to_native(), node.right.to_native()] {
            if child & LEAF != 0 {
                leaf(Some(i), child)?;
                continue;
            }
            let c = child as usize;
            if c >= nodes.len() {
                return Err(ValidationError::KdChildOutOfRange {
                    node: i,
                    child,
                    nodes: nodes.len(),
                });
            }
            if c <= n || reached[c] {
                return Err(ValidationError::KdNotATree { node: i, child });
            }
            reached[c] = true;
        }
    }
    if let Some(r) = region_in_leaf.iter().position(|&s| !s) {
        return Err(ValidationError::RegionNotInTree { region: r });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::schema::{ArchivedBrick, ArchivedKdNode, ArchivedRegion, ArchivedValueRange};

    /// The record sizes the schema's layout notes rely on.
    #[test]
    fn archived_record_sizes() {
        assert_eq!(std::mem::size_of::<ArchivedBrick>(), 64);
        assert_eq!(std::mem::size_of::<ArchivedRegion>(), 8);
        assert_eq!(std::mem::size_of::<ArchivedKdNode>(), 16);
        assert_eq!(std::mem::size_of::<ArchivedValueRange>(), 8);
    }
}
