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
//! Errors name the element, e.g. `regions[12].bricks[3]: brick 9001 out of range (512 bricks)`.

use crate::schema::{ArchivedBrickFile, ArchivedKdNode};

/// Checks the invariants of a structurally valid archive. Cost is linear in the number
/// of bricks, regions, region brick entries and KD nodes; the value arrays are not read.
pub fn check(file: &ArchivedBrickFile) -> Result<(), String> {
    let n_levels = file.levels.len();
    let n_bricks = file.bricks.len();
    let n_regions = file.regions.len();
    let n_fields = file.fields.len();

    // Bounds.
    check_box(|| "bounds".to_owned(), &file.bounds.min, &file.bounds.max)?;

    // Levels.
    for (i, level) in file.levels.iter().enumerate() {
        let w = level.cell_width.to_native();
        if !(w.is_finite() && w > 0.0) {
            return Err(format!("levels[{i}].cell_width: expected > 0, found {w}"));
        }
    }

    // Fields: one value per leaf cell in every field.
    let n_values = file.fields.first().map_or(0, |f| f.values.len() as u64);
    for (i, field) in file.fields.iter().enumerate() {
        if field.values.len() as u64 != n_values {
            return Err(format!(
                "fields[{i}].values: expected {n_values} values (as fields[0]), found {}",
                field.values.len()
            ));
        }
    }

    // Bricks.
    for (i, brick) in file.bricks.iter().enumerate() {
        let level = brick.level.to_native();
        if level as usize >= n_levels {
            return Err(format!(
                "bricks[{i}].level: level {level} out of range ({n_levels} levels)"
            ));
        }
        let dims = brick.dims.map(|d| d.to_native());
        if dims.contains(&0) {
            return Err(format!(
                "bricks[{i}].dims: expected >= 1 cells per axis, found {dims:?}"
            ));
        }
        let w = brick.cell_width.to_native();
        if !(w.is_finite() && w > 0.0) {
            return Err(format!("bricks[{i}].cell_width: expected > 0, found {w}"));
        }
        let inv = brick.inv_cell_width.to_native();
        if inv != 1.0 / w {
            return Err(format!(
                "bricks[{i}].inv_cell_width: expected 1 / {w} = {}, found {inv}",
                1.0 / w
            ));
        }
        // The viewer steps through a region in units of its finest *level's* width and
        // reconstructs with the *bricks'* widths: a level far finer than its bricks made
        // every ray take millions of samples per region (found by the `qbk_open` fuzz
        // target). The baker merges widths equal to 1e-6, so 1e-3 is loose enough.
        let lw = file.levels[level as usize].cell_width.to_native();
        if (w - lw).abs() > 1e-3 * lw {
            return Err(format!(
                "bricks[{i}].cell_width: {w:?} differs from its level {level}'s cell width {lw:?}"
            ));
        }
        if brick.origin.iter().any(|c| !c.to_native().is_finite()) {
            return Err(format!("bricks[{i}].origin: not finite"));
        }
        // Three u32 dims can hold up to 2^96 cells. Unchecked, the product wraps in
        // release builds (found by the `qbk_open` fuzz target): a brick of 2^22 x 2^21 x
        // 2^21 cells then counts as 0 cells, passes the range check below, and the viewer
        // indexes far past the value arrays.
        let Some(cells) = dims
            .iter()
            .try_fold(1u64, |n, &d| n.checked_mul(u64::from(d)))
        else {
            return Err(format!(
                "bricks[{i}].dims: {dims:?} is more cells than a file can hold"
            ));
        };
        if n_fields > 0 {
            let first = brick.first_value.to_native();
            let end = first.checked_add(cells);
            if end.is_none_or(|e| e > n_values) {
                return Err(format!(
                    "bricks[{i}]: values {first}..{first}+{cells} out of range ({n_values} values per field)"
                ));
            }
        }
    }

    // Regions and their brick lists.
    let n_entries = file.region_bricks.len() as u64;
    for (i, region) in file.regions.iter().enumerate() {
        check_box(
            || format!("regions[{i}].bounds"),
            &region.bounds.min,
            &region.bounds.max,
        )?;
        let start = u64::from(region.bricks_start.to_native());
        let len = u64::from(region.bricks_len.to_native());
        if start + len > n_entries {
            return Err(format!(
                "regions[{i}]: bricks {start}..{start}+{len} out of range ({n_entries} region_bricks entries)"
            ));
        }
        if len > 0 {
            let finest = region.finest_level.to_native();
            if finest as usize >= n_levels {
                return Err(format!(
                    "regions[{i}].finest_level: level {finest} out of range ({n_levels} levels)"
                ));
            }
        }
    }
    // Every entry of every list names a brick: one flat pass over the entries (a list is
    // a slice of them, checked above), not one per region.
    if let Some(at) = file
        .region_bricks
        .iter()
        .position(|id| id.to_native() as usize >= n_bricks)
    {
        let id = file.region_bricks[at].to_native();
        let (i, j) = file
            .regions
            .iter()
            .enumerate()
            .find_map(|(i, r)| {
                let start = r.bricks_start.to_native() as usize;
                let len = r.bricks_len.to_native() as usize;
                (start..start + len).contains(&at).then(|| (i, at - start))
            })
            .unwrap_or((usize::MAX, at));
        if i != usize::MAX {
            return Err(format!(
                "regions[{i}].bricks[{j}]: brick {id} out of range ({n_bricks} bricks)"
            ));
        }
        return Err(format!(
            "region_bricks[{at}]: brick {id} out of range ({n_bricks} bricks)"
        ));
    }
    // The region's step width is its finest level's: it must be the finest level of its
    // bricks, as the schema says (a finer one makes rays crawl, a coarser one misses
    // detail). Checked after the entries, so that every id indexes a brick.
    for (i, region) in file.regions.iter().enumerate() {
        let start = region.bricks_start.to_native() as usize;
        let len = region.bricks_len.to_native() as usize;
        let finest = file.region_bricks[start..start + len]
            .iter()
            .map(|id| file.bricks[id.to_native() as usize].level.to_native())
            .min();
        if let Some(finest) = finest {
            let stored = region.finest_level.to_native();
            if stored != finest {
                return Err(format!(
                    "regions[{i}].finest_level: {stored}, but its finest brick is on level {finest}"
                ));
            }
        }
    }
    let expected_ranges = n_regions as u64 * n_fields as u64;
    if file.region_ranges.len() as u64 != expected_ranges {
        return Err(format!(
            "region_ranges: expected {expected_ranges} entries ({n_regions} regions x {n_fields} fields), found {}",
            file.region_ranges.len()
        ));
    }

    check_kd(file)
}

/// `what` names the box in the error; built only on error (this runs once per region).
fn check_box(
    what: impl Fn() -> String,
    min: &[rkyv::Archived<f64>; 3],
    max: &[rkyv::Archived<f64>; 3],
) -> Result<(), String> {
    for a in 0..3 {
        let (lo, hi) = (min[a].to_native(), max[a].to_native());
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return Err(format!(
                "{}: expected min <= max on axis {a}, found {lo} > {hi}",
                what()
            ));
        }
    }
    Ok(())
}

/// The KD nodes reachable from node 0 form a tree (no node has two parents, no cycles),
/// every index is in range, every region sits in at least one leaf, and the per-node
/// ranges and fullness flags can be trusted for skipping: a node's range holds its
/// children's (a leaf's its region's) and a node is full only if its children are (a leaf
/// only if it holds a region). Wider ranges than needed are allowed (they skip less).
fn check_kd(file: &ArchivedBrickFile) -> Result<(), String> {
    let nodes = &file.kd_nodes;
    let n_regions = file.regions.len();
    let nf = file.fields.len();
    let range = |n: usize, f: usize| {
        let r = &file.kd_ranges[n * nf + f];
        (r.min.to_native(), r.max.to_native())
    };
    // `outer` holds `inner` (NaN holds nothing and is held by nothing).
    let holds = |outer: (f32, f32), inner: (f32, f32)| outer.0 <= inner.0 && outer.1 >= inner.1;
    if nodes.is_empty() && n_regions > 0 {
        return Err(format!(
            "kd_nodes: empty, but there are {n_regions} regions"
        ));
    }
    let expected = nodes.len() as u64 * nf as u64;
    if file.kd_ranges.len() as u64 != expected {
        return Err(format!(
            "kd_ranges: expected {expected} entries ({} nodes x {nf} fields), found {}",
            nodes.len(),
            file.kd_ranges.len()
        ));
    }
    if file.kd_full.len() != nodes.len() {
        return Err(format!(
            "kd_full: expected {} entries (one per node), found {}",
            nodes.len(),
            file.kd_full.len()
        ));
    }
    if nodes.is_empty() {
        return Ok(());
    }
    // Sized by counts that bytecheck has proven to be backed by bytes of the file.
    let mut seen = vec![false; nodes.len()];
    let mut region_in_leaf = vec![false; n_regions];
    let mut stack = vec![0u32];
    seen[0] = true;
    while let Some(i) = stack.pop() {
        let Some(node) = nodes.get(i as usize) else {
            continue;
        };
        match node {
            ArchivedKdNode::Inner {
                axis,
                split,
                left,
                right,
            } => {
                if *axis > 2 {
                    return Err(format!(
                        "kd_nodes[{i}].axis: expected 0, 1 or 2, found {axis}"
                    ));
                }
                if split.to_native().is_nan() {
                    return Err(format!("kd_nodes[{i}].split: NaN"));
                }
                for child in [left.to_native(), right.to_native()] {
                    let Some(flag) = seen.get_mut(child as usize) else {
                        return Err(format!(
                            "kd_nodes[{i}]: child {child} out of range ({} nodes)",
                            nodes.len()
                        ));
                    };
                    let (n, c) = (i as usize, child as usize);
                    if (0..nf).any(|f| !holds(range(n, f), range(c, f))) {
                        return Err(format!(
                            "kd_ranges of node {i}: do not hold those of its child {child}"
                        ));
                    }
                    if file.kd_full[n] && !file.kd_full[c] {
                        return Err(format!(
                            "kd_full of node {i}: set, but its child {child} is not full"
                        ));
                    }
                    if *flag {
                        return Err(format!(
                            "kd_nodes[{i}]: child {child} is reached twice (not a tree)"
                        ));
                    }
                    *flag = true;
                    stack.push(child);
                }
            }
            ArchivedKdNode::Leaf { region } => match region.as_ref() {
                Some(r) => {
                    let r = r.to_native();
                    match region_in_leaf.get_mut(r as usize) {
                        Some(flag) => *flag = true,
                        None => {
                            return Err(format!(
                                "kd_nodes[{i}]: region {r} out of range ({n_regions} regions)"
                            ))
                        }
                    }
                    for f in 0..nf {
                        let reg = &file.region_ranges[r as usize * nf + f];
                        let reg = (reg.min.to_native(), reg.max.to_native());
                        if !holds(range(i as usize, f), reg) {
                            return Err(format!(
                                "kd_ranges of leaf {i}: field {f} does not hold region {r}'s range"
                            ));
                        }
                    }
                }
                None => {
                    if file.kd_full[i as usize] {
                        return Err(format!("kd_full of node {i}: set on an empty leaf"));
                    }
                }
            },
        }
    }
    if let Some(r) = region_in_leaf.iter().position(|&s| !s) {
        return Err(format!("regions[{r}]: in no KD-tree leaf"));
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
        assert_eq!(std::mem::size_of::<ArchivedRegion>(), 64);
        assert_eq!(std::mem::size_of::<ArchivedKdNode>(), 24);
        assert_eq!(std::mem::size_of::<ArchivedValueRange>(), 8);
    }
}
