//! Per-grid summary of a VDB file: what `qbricks-bake inspect` prints.

use serde::Serialize;

use super::{MetaValue, VdbError, VdbFile};
use crate::grid::{AnyGrid, Grid};

/// The whole report (`--json` output).
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub file_version: u32,
    pub library_version: String,
    pub grids: Vec<GridReport>,
}

/// One grid's summary. Statistics are over active voxels, tiles counted as the voxels they
/// cover; `bbox_*` are inclusive index-space bounds (`null` for an empty grid).
#[derive(Debug, Clone, Serialize)]
pub struct GridReport {
    pub name: String,
    pub value_type: String,
    /// Grid class (`unknown`, `level set`, `fog volume`, `staggered`).
    pub class: String,
    pub voxel_size: [f64; 3],
    pub translation: [f64; 3],
    pub compression: Vec<&'static str>,
    pub half_float: bool,
    pub active_voxels: u64,
    pub bbox_min: Option<[i32; 3]>,
    pub bbox_max: Option<[i32; 3]>,
    /// One entry for scalars, three for vectors; `null` entries for an empty grid.
    pub mean: Vec<Option<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<Option<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<Option<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_magnitude: Option<Option<f64>>,
    pub metadata: serde_json::Map<String, serde_json::Value>,
}

/// Reads every grid of `file` and summarises it.
pub fn report(file: &VdbFile) -> Result<Report, VdbError> {
    let mut grids = Vec::with_capacity(file.grids().len());
    for (i, d) in file.grids().iter().enumerate() {
        let grid = file.read_grid(i)?;
        let stats = match &grid {
            AnyGrid::Float(g) => stats(g, |v| [f64::from(*v), 0.0, 0.0], 1),
            AnyGrid::Double(g) => stats(g, |v| [*v, 0.0, 0.0], 1),
            AnyGrid::Vec3s(g) => stats(g, |v| v.map(f64::from), 3),
            AnyGrid::Vec3d(g) => stats(g, |v| *v, 3),
        };
        let transform = grid.transform();
        let vector = d.value_type.is_vector();
        let some = stats.count > 0;
        let mean = (0..if vector { 3 } else { 1 })
            .map(|c| some.then(|| stats.sum[c] / stats.count as f64))
            .collect();
        grids.push(GridReport {
            name: d.name.clone(),
            value_type: d.value_type.name().to_string(),
            class: d.class().to_string(),
            voxel_size: transform.voxel_size,
            translation: transform.translation,
            compression: d.compression_flags().names(),
            half_float: d.half_float,
            active_voxels: stats.count,
            bbox_min: some.then_some(stats.lo),
            bbox_max: some.then_some(stats.hi),
            mean,
            min: (!vector).then(|| some.then_some(stats.min)),
            max: (!vector).then(|| some.then_some(stats.max)),
            max_magnitude: vector.then(|| some.then_some(stats.max_mag)),
            metadata: d
                .metadata
                .iter()
                .filter_map(|(k, v)| meta_json(v).map(|j| (k.clone(), j)))
                .collect(),
        });
    }
    Ok(Report {
        file_version: file.file_version,
        library_version: format!("{}.{}", file.library_version.0, file.library_version.1),
        grids,
    })
}

fn meta_json(v: &MetaValue) -> Option<serde_json::Value> {
    use serde_json::json;
    Some(match v {
        MetaValue::Bool(b) => json!(b),
        MetaValue::Int32(i) => json!(i),
        MetaValue::Int64(i) => json!(i),
        MetaValue::Float(f) => json!(f64::from(*f)),
        MetaValue::Double(f) => json!(f),
        MetaValue::String(s) => json!(s),
        MetaValue::Vec3i(v) => json!(v),
        MetaValue::Vec3s(v) => json!(v.map(f64::from)),
        MetaValue::Vec3d(v) => json!(v),
        MetaValue::Other(_) => return None,
    })
}

struct Stats {
    count: u64,
    sum: [f64; 3],
    min: f64,
    max: f64,
    max_mag: f64,
    lo: [i32; 3],
    hi: [i32; 3],
}

fn add_value(s: &mut Stats, c: &[f64; 3], weight: u64, n_comps: usize) {
    s.count += weight;
    for (sum, c) in s.sum.iter_mut().zip(c) {
        *sum += c * weight as f64;
    }
    if n_comps == 1 {
        s.min = s.min.min(c[0]);
        s.max = s.max.max(c[0]);
    } else {
        s.max_mag = s
            .max_mag
            .max((c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt());
    }
}

fn stats<V: Copy>(g: &Grid<V>, comps: impl Fn(&V) -> [f64; 3], n_comps: usize) -> Stats {
    let mut s = Stats {
        count: 0,
        sum: [0.0; 3],
        min: f64::INFINITY,
        max: f64::NEG_INFINITY,
        max_mag: 0.0,
        lo: [i32::MAX; 3],
        hi: [i32::MIN; 3],
    };
    for leaf in &g.leaves {
        // Bounds from the mask (word x holds bits y*8+z), values one by one.
        let any: u64 = leaf.active.iter().fold(0, |a, w| a | w);
        if any == 0 {
            continue;
        }
        let xs: Vec<i32> = (0..8)
            .filter(|&x| leaf.active[x] != 0)
            .map(|x| x as i32)
            .collect();
        let ys: Vec<i32> = (0..8i32)
            .filter(|&y| (any >> (8 * y)) & 0xff != 0)
            .collect();
        let zbits = (0..8).fold(0u64, |a, y| a | ((any >> (8 * y)) & 0xff));
        let zs: Vec<i32> = (0..8i32).filter(|&z| (zbits >> z) & 1 != 0).collect();
        let (o, first, last) = (leaf.origin, |v: &[i32]| v[0], |v: &[i32]| v[v.len() - 1]);
        for (k, axis) in [&xs, &ys, &zs].iter().enumerate() {
            s.lo[k] = s.lo[k].min(o[k] + first(axis));
            s.hi[k] = s.hi[k].max(o[k] + last(axis));
        }
        for (w, &word) in leaf.active.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                let n = w * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                add_value(&mut s, &comps(&leaf.values[n]), 1, n_comps);
            }
        }
    }
    for t in &g.tiles {
        let hi = t.origin.map(|o| o.saturating_add(t.size as i32 - 1));
        for (k, &h) in hi.iter().enumerate() {
            s.lo[k] = s.lo[k].min(t.origin[k]);
            s.hi[k] = s.hi[k].max(h);
        }
        add_value(&mut s, &comps(&t.value), u64::from(t.size).pow(3), n_comps);
    }
    s
}
