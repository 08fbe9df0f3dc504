//! Comparing grids with what OpenVDB read: grids flattened to values, `expected.json` parsed.

use qbricks_preprocess::grid::AnyGrid;

/// Components of a value as f64.
pub trait Comps {
    fn comps(&self) -> Vec<f64>;
}
impl Comps for f32 {
    fn comps(&self) -> Vec<f64> {
        vec![f64::from(*self)]
    }
}
impl Comps for f64 {
    fn comps(&self) -> Vec<f64> {
        vec![*self]
    }
}
impl Comps for [f32; 3] {
    fn comps(&self) -> Vec<f64> {
        self.iter().map(|&c| f64::from(c)).collect()
    }
}
impl Comps for [f64; 3] {
    fn comps(&self) -> Vec<f64> {
        self.to_vec()
    }
}

/// A grid flattened for comparison: name, type, voxels, tiles, inactive leaf values.
#[derive(Debug, Default)]
pub struct Flat {
    pub name: String,
    pub value_type: &'static str,
    pub voxel_size: [f64; 3],
    pub translation: [f64; 3],
    pub background: Vec<f64>,
    /// (ijk, value) of active leaf voxels, sorted.
    pub voxels: Vec<([i32; 3], Vec<f64>)>,
    /// (origin, size, value) of active tiles, sorted.
    pub tiles: Vec<([i32; 3], u32, Vec<f64>)>,
    /// (ijk, value) of inactive leaf voxels, sorted.
    pub inactive: Vec<([i32; 3], Vec<f64>)>,
}

fn flat_of<V: Copy + Comps>(
    g: &qbricks_preprocess::grid::Grid<V>,
    value_type: &'static str,
) -> Flat {
    let mut f = Flat {
        name: g.name.clone(),
        value_type,
        voxel_size: g.transform.voxel_size,
        translation: g.transform.translation,
        background: g.background.comps(),
        ..Flat::default()
    };
    for leaf in &g.leaves {
        for n in 0..512 {
            let ijk = [
                leaf.origin[0] + (n >> 6) as i32,
                leaf.origin[1] + ((n >> 3) & 7) as i32,
                leaf.origin[2] + (n & 7) as i32,
            ];
            let v = leaf.values[n].comps();
            if leaf.is_active(n) {
                f.voxels.push((ijk, v));
            } else {
                f.inactive.push((ijk, v));
            }
        }
    }
    for t in &g.tiles {
        f.tiles.push((t.origin, t.size, t.value.comps()));
    }
    let key = |a: &[i32; 3]| *a;
    f.voxels.sort_by_key(|v| key(&v.0));
    f.inactive.sort_by_key(|v| key(&v.0));
    f.tiles.sort_by_key(|t| (t.0, t.1));
    f
}

pub fn flatten(g: &AnyGrid) -> Flat {
    match g {
        AnyGrid::Float(g) => flat_of(g, "float"),
        AnyGrid::Double(g) => flat_of(g, "double"),
        AnyGrid::Vec3s(g) => flat_of(g, "vec3s"),
        AnyGrid::Vec3d(g) => flat_of(g, "vec3d"),
    }
}

/// A JSON value (number or list of numbers) as components.
pub fn json_comps(v: &serde_json::Value) -> Vec<f64> {
    match v {
        serde_json::Value::Array(a) => a.iter().flat_map(json_comps).collect(),
        serde_json::Value::Number(n) => vec![n.as_f64().expect("number")],
        serde_json::Value::String(s) => vec![s.parse().expect("nan/inf string")],
        other => panic!("not a value: {other}"),
    }
}

/// A JSON list of `[i, j, k, size, value]` tiles as (origin, size, components), sorted by
/// origin and size.
pub fn json_tiles(v: &serde_json::Value) -> Vec<([i32; 3], u32, Vec<f64>)> {
    let mut tiles: Vec<([i32; 3], u32, Vec<f64>)> = v
        .as_array()
        .expect("tiles: a JSON list")
        .iter()
        .map(|t| {
            (
                json_ijk(t),
                t[3].as_u64().expect("tile size") as u32,
                json_comps(&t[4]),
            )
        })
        .collect();
    tiles.sort_by_key(|t| (t.0, t.1));
    tiles
}

pub fn json_ijk(v: &serde_json::Value) -> [i32; 3] {
    let a = v.as_array().expect("array");
    [0, 1, 2].map(|k| a[k].as_i64().expect("int") as i32)
}

/// Compares values bit for bit (NaN equal to NaN).
pub fn same(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
}
