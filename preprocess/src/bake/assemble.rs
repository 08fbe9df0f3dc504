//! Assembly stage: the [`BrickFile`] a bake writes (fields with their ranges and
//! histograms, levels, bricks with snapped supports, regions, KD-tree, provenance), and
//! the bound on its size ([`format::MAX_ARCHIVE_BYTES`]), checked before it is built.

use format::{Aabb, Brick, BrickFile, Field, Level, Provenance, SourceGrid, ValueRange};

use crate::fields::{range_and_histogram, HISTOGRAM_BINS};

use super::derived::FieldValues;
use super::{BakeError, BakeOptions, Bricks, FieldSummary, Kd};

/// Bytes of the archive of a bake, from the sizes of its arrays (each element as the
/// schema archives it) and 1 MiB for the rest (names, provenance, alignment).
pub(super) fn archive_bytes(bricks: &Bricks, fields: &FieldValues, kd: &Kd) -> u64 {
    let n = |len: usize, bytes: u64| (len as u64).saturating_mul(bytes);
    let nf = fields.names.len();
    let values = n(fields.cells(), 4).saturating_mul(nf as u64);
    let histograms = n(nf, 8 * HISTOGRAM_BINS as u64);
    let region_bricks = n(kd.regions.bricks.len(), 4);
    values
        .saturating_add(histograms)
        .saturating_add(n(bricks.boxes.len(), 64))
        .saturating_add(n(kd.regions.len(), 8))
        .saturating_add(region_bricks)
        .saturating_add(n(kd.ranges.len(), 8))
        .saturating_add(n(kd.tree.1.len(), 16 + 1))
        .saturating_add(1 << 20)
}

/// Refuses an archive of `bytes` larger than a `.qbk` may be.
pub(super) fn check_archive(leaf_cells: u64, fields: u64, bytes: u64) -> Result<(), BakeError> {
    if bytes > format::MAX_ARCHIVE_BYTES {
        return Err(BakeError::TooLargeForFormat {
            leaf_cells,
            fields,
            bytes,
        });
    }
    Ok(())
}

/// Assembly stage: the [`BrickFile`] (fields with their ranges and histograms, levels,
/// bricks, regions, KD-tree, provenance) ready to be written, its fields' values left
/// where `fields` keeps them, and the field ranges for the summary. The regions and
/// KD-tree are moved into the file when they are in memory; kept in scratch files, they
/// stay there and are returned beside it (the writer streams them).
pub(super) fn assemble(
    opts: &BakeOptions,
    source_grids: Vec<SourceGrid>,
    level_widths: &[f64],
    bricks: &Bricks,
    fields: &FieldValues,
    kd: Kd,
    bounds: Option<Aabb>,
) -> (BrickFile, Vec<FieldSummary>, Option<Kd>) {
    let mut file_fields = Vec::with_capacity(fields.names.len());
    let mut field_summaries = Vec::with_capacity(fields.names.len());
    for (f, (name, vals)) in fields.names.iter().zip(fields.slices()).enumerate() {
        let release = |r: std::ops::Range<usize>| fields.release(f, r);
        let window = opts.spill.window_values(4);
        let (min, max, histogram) = range_and_histogram(vals, window, &release);
        let name = name.clone();
        field_summaries.push(FieldSummary {
            name: name.clone(),
            min,
            max,
        });
        file_fields.push(Field {
            name,
            min,
            max,
            histogram,
            // The values stay where the bake keeps them (see `Baked`).
            values: Vec::new(),
        });
    }
    let mut file_levels: Vec<Level> = level_widths
        .iter()
        .map(|&w| Level {
            cell_width: w,
            cells: 0,
            bricks: 0,
        })
        .collect();
    for b in &bricks.boxes {
        let l = &mut file_levels[b.level as usize];
        l.cells += b.cells();
        l.bricks += 1;
    }
    let file_bricks: Vec<Brick> = bricks
        .boxes
        .iter()
        .zip(&bricks.origins)
        .zip(&bricks.first)
        .zip(&bricks.widths)
        .map(|(((b, o), f), &w)| Brick {
            level: b.level,
            origin: *o,
            cell_width: w,
            inv_cell_width: 1.0 / w,
            dims: b.dims,
            first_value: *f,
        })
        .collect();
    let bounds = bounds.unwrap_or(Aabb {
        min: [0.0; 3],
        max: [0.0; 3],
    });
    let mut file = BrickFile {
        provenance: Provenance {
            source: opts.source.clone(),
            grids: source_grids,
            bake_options: serde_json::to_string(opts).unwrap_or_default(),
            tool_version: env!("CARGO_PKG_VERSION").to_string(),
        },
        bounds,
        levels: file_levels,
        fields: file_fields,
        bricks: file_bricks,
        regions: Vec::new(),
        region_bricks: Vec::new(),
        region_ranges: Vec::new(),
        kd_root: kd.tree.0,
        kd_nodes: Vec::new(),
        kd_axes: Vec::new(),
    };
    if kd.on_disk() {
        return (file, field_summaries, Some(kd));
    }
    structure_into(&mut file, kd);
    (file, field_summaries, None)
}

/// Puts the regions and KD-tree of `kd` into `file` (read from disk if they are there).
pub(super) fn structure_into(file: &mut BrickFile, kd: Kd) {
    let Kd {
        tree: (root, nodes, axes),
        regions,
        ranges,
    } = kd;
    file.regions = regions.runs.into_vec();
    file.region_bricks = regions.bricks.into_vec();
    file.region_ranges = ranges
        .iter()
        .map(|&[min, max]| ValueRange { min, max })
        .collect();
    file.kd_root = root;
    file.kd_nodes = nodes.into_vec();
    file.kd_axes = axes.into_vec();
}
