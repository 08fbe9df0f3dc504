//! `qbricks-view info`: what a `.qbk` file holds, as JSON or as text.
//!
//! The JSON keys `format_version`, `bytes`, `cells`, `bricks`, `regions`, `kd_nodes`,
//! `levels` (`level`, `cell_width`, `cells`, `bricks`), `bounds_min`, `bounds_max`,
//! `fields` (`name`, `min`, `max`) and `source` are a stable interface (scripts and tests
//! read them); the other keys are extras for people.

use std::fmt::Write as _;

use format::kd::{KdTree, Node};
use format::sequence::FieldRange;
use format::{query, BrickFileView};
use serde::Serialize;

/// Summary of one level. `cells` and `bricks` are counted from the bricks in the file.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LevelInfo {
    pub level: u32,
    pub cell_width: f64,
    pub cells: u64,
    pub bricks: u64,
}

/// Summary of one field: its name and the file's range over all finite leaf cells (the
/// same [`FieldRange`] the volume and the view state use; JSON `null` if not a number),
/// and the size of its histogram. Flattened, so the JSON keys stay `name`, `min`, `max`,
/// `histogram_bins`.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct FieldInfo {
    #[serde(flatten)]
    pub range: FieldRange,
    pub(crate) histogram_bins: u64,
}

/// One source grid of the provenance.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct GridInfo {
    pub name: String,
    pub voxel_size: [f64; 3],
    pub level: u32,
}

/// Everything `info` reports.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Info {
    pub format_version: u32,
    /// Size of the whole file.
    pub bytes: u64,
    /// Leaf cells (per field).
    pub cells: u64,
    pub bricks: u64,
    pub regions: u64,
    pub kd_nodes: u64,
    pub levels: Vec<LevelInfo>,
    pub bounds_min: [f64; 3],
    pub bounds_max: [f64; 3],
    pub fields: Vec<FieldInfo>,
    /// File name of the source VDB.
    pub source: String,
    // Extras.
    pub path: String,
    pub checksum_verified: bool,
    /// Depth of the KD-tree (a single leaf has depth 1; 0 without nodes).
    pub(crate) kd_depth: u64,
    pub(crate) kd_leaves: u64,
    /// Total entries of all regions' brick lists (bricks counted once per region).
    pub(crate) region_brick_refs: u64,
    pub grids: Vec<GridInfo>,
    /// The bake options as JSON (a string when they are not valid JSON).
    pub bake_options: serde_json::Value,
    pub tool_version: String,
    /// What modelling only what the scene needs costs and saves: the bytes of the fields'
    /// leaf values (4 per cell and field) against everything else — bricks, regions,
    /// KD-tree, value ranges, histograms, header, provenance.
    pub value_bytes: u64,
    pub structure_bytes: u64,
    /// `structure_bytes / bytes`.
    pub structure_share: f64,
    /// File bytes per leaf cell (all fields together).
    pub bytes_per_cell: f64,
    /// Cells one uniform grid at the finest cell width over the bounds would need.
    pub uniform_finest_cells: f64,
}

/// Gathers the summary of an opened (hence validated) file.
pub fn info(view: &BrickFileView) -> Info {
    let file = view.file();
    let mut levels: Vec<LevelInfo> = file
        .levels
        .iter()
        .enumerate()
        .map(|(i, l)| LevelInfo {
            level: i as u32,
            cell_width: l.cell_width.to_native(),
            cells: 0,
            bricks: 0,
        })
        .collect();
    let mut cells = 0u64;
    for brick in file.bricks.iter() {
        // Saturating: a file without fields has no values to bound its bricks' cell
        // counts, so their sum may exceed u64 (the counts are only reported).
        let n = query::brick_cells(brick);
        cells = cells.saturating_add(n);
        if let Some(l) = levels.get_mut(brick.level.to_native() as usize) {
            l.cells = l.cells.saturating_add(n);
            l.bricks += 1;
        }
    }
    let (kd_depth, kd_leaves) = kd_shape(view);
    let bounds = query::bounds(file);
    let prov = &file.provenance;
    let bytes = view.byte_len();
    let value_bytes: u64 = file.fields.iter().map(|f| 4 * f.values.len() as u64).sum();
    let structure_bytes = bytes.saturating_sub(value_bytes);
    let uniform_finest_cells = match levels.first() {
        Some(l) if l.cell_width > 0.0 => (0..3)
            .map(|a| {
                ((bounds.max[a] - bounds.min[a]) / l.cell_width)
                    .ceil()
                    .max(0.0)
            })
            .product(),
        _ => 0.0,
    };
    Info {
        format_version: view.header().format_version,
        bytes: view.byte_len(),
        cells,
        bricks: file.bricks.len() as u64,
        regions: file.regions.len() as u64,
        kd_nodes: file.kd_nodes.len() as u64,
        levels,
        bounds_min: bounds.min,
        bounds_max: bounds.max,
        fields: file
            .fields
            .iter()
            .map(|f| FieldInfo {
                range: FieldRange {
                    name: f.name.to_string(),
                    min: f.min.to_native(),
                    max: f.max.to_native(),
                },
                histogram_bins: f.histogram.len() as u64,
            })
            .collect(),
        source: prov.source.to_string(),
        path: view.path().display().to_string(),
        checksum_verified: view.checksum_verified(),
        kd_depth,
        kd_leaves,
        region_brick_refs: file.region_bricks.len() as u64,
        grids: prov
            .grids
            .iter()
            .map(|g| GridInfo {
                name: g.name.to_string(),
                voxel_size: g.voxel_size.map(|v| v.to_native()),
                level: g.level.to_native(),
            })
            .collect(),
        bake_options: serde_json::from_str(prov.bake_options.as_str())
            .unwrap_or_else(|_| serde_json::Value::String(prov.bake_options.to_string())),
        tool_version: prov.tool_version.to_string(),
        value_bytes,
        structure_bytes,
        structure_share: structure_bytes as f64 / bytes.max(1) as f64,
        bytes_per_cell: bytes as f64 / cells.max(1) as f64,
        uniform_finest_cells,
    }
}

/// Depth and leaf count of the KD-tree (validated at open to be a tree); leaves are
/// counted with the empty ones, depth in levels of nodes with the leaves (a lone leaf
/// is depth 1).
fn kd_shape(view: &BrickFileView) -> (u64, u64) {
    let tree = format::kd::file_tree(view.file());
    let (mut depth, mut leaves) = (0u64, 0u64);
    let mut stack = vec![(tree.root, 1u64)];
    // The budget guards against cycles even though validation rules them out.
    let mut budget = tree.nodes.len().saturating_mul(2).saturating_add(1);
    while let Some((i, d)) = stack.pop() {
        if budget == 0 {
            break;
        }
        budget -= 1;
        depth = depth.max(d);
        match tree.node(i) {
            Some(Node::Inner { left, right, .. }) => {
                stack.push((left, d + 1));
                stack.push((right, d + 1));
            }
            Some(Node::Leaf(_)) => leaves += 1,
            None => {}
        }
    }
    (depth, leaves)
}

/// Human-readable rendering of [`Info`].
pub fn to_text(info: &Info) -> String {
    let mut s = String::new();
    let mib = info.bytes as f64 / (1024.0 * 1024.0);
    // Writing to a String cannot fail.
    let _ = writeln!(s, "{}", info.path);
    let _ = writeln!(
        s,
        "  format version {}, {} bytes ({mib:.1} MiB), checksum {}",
        info.format_version,
        info.bytes,
        if info.checksum_verified {
            "verified"
        } else {
            "not verified"
        }
    );
    let _ = writeln!(
        s,
        "  source {} (baked by qbricks-bake {})",
        info.source, info.tool_version
    );
    for g in &info.grids {
        let _ = writeln!(
            s,
            "    grid {:?}: voxel size {:?}, level {}",
            g.name, g.voxel_size, g.level
        );
    }
    let _ = writeln!(s, "  bake options {}", info.bake_options);
    let _ = writeln!(
        s,
        "  bounds [{}, {}, {}] .. [{}, {}, {}]",
        info.bounds_min[0],
        info.bounds_min[1],
        info.bounds_min[2],
        info.bounds_max[0],
        info.bounds_max[1],
        info.bounds_max[2]
    );
    let _ = writeln!(
        s,
        "  {} cells in {} bricks; {} regions ({} brick refs); KD-tree {} nodes, {} leaves, depth {}",
        info.cells,
        info.bricks,
        info.regions,
        info.region_brick_refs,
        info.kd_nodes,
        info.kd_leaves,
        info.kd_depth
    );
    let _ = writeln!(
        s,
        "  {:.1} bytes per leaf cell; values {} bytes, structure {} bytes ({:.1} % of the file, {:.1} % of the values); a uniform grid at the finest width would need {:.0} cells ({:.1}× the leaf cells)",
        info.bytes_per_cell,
        info.value_bytes,
        info.structure_bytes,
        100.0 * info.structure_share,
        100.0 * info.structure_bytes as f64 / info.value_bytes.max(1) as f64,
        info.uniform_finest_cells,
        info.uniform_finest_cells / info.cells.max(1) as f64
    );
    let _ = writeln!(s, "  levels:");
    for l in &info.levels {
        let _ = writeln!(
            s,
            "    {}: cell width {}, {} cells, {} bricks",
            l.level, l.cell_width, l.cells, l.bricks
        );
    }
    let _ = writeln!(s, "  fields:");
    for f in &info.fields {
        let _ = writeln!(
            s,
            "    {}: min {}, max {} ({} histogram bins)",
            f.range.name, f.range.min, f.range.max, f.histogram_bins
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use format::kd::BuildNode;
    use format::{Aabb, Brick, BrickFile, Field, Level, Provenance, Region, ValueRange};

    fn sample() -> BrickFile {
        let (kd_root, kd_nodes, kd_axes) = format::kd::pack(&[
            BuildNode::Inner {
                axis: 0,
                split: 0.5,
                left: 1,
                right: 2,
            },
            BuildNode::Leaf { region: Some(0) },
            BuildNode::Leaf { region: Some(1) },
        ]);
        BrickFile {
            provenance: Provenance {
                source: "wake.vdb".into(),
                grids: vec![],
                bake_options: "{\"step\":0.5}".into(),
                tool_version: "0.1.0".into(),
            },
            bounds: Aabb {
                min: [-1.0, -1.0, -1.0],
                max: [2.0, 1.0, 1.0],
            },
            levels: vec![
                Level {
                    cell_width: 0.5,
                    cells: 8,
                    bricks: 1,
                },
                Level {
                    cell_width: 1.0,
                    cells: 1,
                    bricks: 1,
                },
            ],
            fields: vec![Field {
                name: "q".into(),
                min: -2.0,
                max: 3.0,
                histogram: vec![1, 2],
                values: vec![0.0; 9],
            }],
            bricks: vec![
                Brick {
                    level: 0,
                    origin: [0.0; 3],
                    cell_width: 0.5,
                    inv_cell_width: 1.0 / 0.5,
                    dims: [2, 2, 2],
                    first_value: 0,
                },
                Brick {
                    level: 1,
                    origin: [1.0; 3],
                    cell_width: 1.0,
                    inv_cell_width: 1.0,
                    dims: [1, 1, 1],
                    first_value: 8,
                },
            ],
            regions: vec![
                Region {
                    bricks_start: 0,
                    bricks_len: 1,
                },
                Region {
                    bricks_start: 1,
                    bricks_len: 2,
                },
            ],
            region_bricks: vec![0, 0, 1],
            region_ranges: vec![ValueRange { min: 0.0, max: 0.0 }; 2],
            kd_root,
            kd_nodes,
            kd_axes,
        }
    }

    #[test]
    fn counts_come_from_the_file() {
        let bytes = format::writer::to_bytes(&sample()).expect("bytes");
        let view = BrickFileView::from_bytes(std::path::Path::new("s.qbk"), &bytes).expect("open");
        let i = info(&view);
        assert_eq!(i.bytes, bytes.len() as u64);
        assert_eq!((i.cells, i.bricks, i.regions, i.kd_nodes), (9, 2, 2, 1));
        assert_eq!((i.kd_depth, i.kd_leaves, i.region_brick_refs), (2, 2, 3));
        assert_eq!(i.levels[0].cells, 8);
        assert_eq!(i.levels[1].bricks, 1);
        assert_eq!(i.bake_options["step"], 0.5);
        // One field of 9 leaf values; bounds 3×2×2 at finest width 0.5 → 6·4·4 cells.
        assert_eq!(i.value_bytes, 36);
        assert_eq!(i.structure_bytes, bytes.len() as u64 - 36);
        assert_eq!(i.uniform_finest_cells, 96.0);
        assert!((i.bytes_per_cell - bytes.len() as f64 / 9.0).abs() < 1e-12);
        let text = to_text(&i);
        assert!(text.contains("9 cells in 2 bricks"), "{text}");
        assert!(text.contains("q: min -2, max 3"), "{text}");
    }
}
