//! Files written by `qbricks_preprocess::vdb::write` (and `synth`) load in real OpenVDB.
//!
//! Reads them back with Debian's `pyopenvdb` (every active value, every value of every
//! leaf, tiles, transforms, metadata) and `vdb_print -l` (including the double-precision
//! grid types pyopenvdb does not register). Skipped with a message when the tools are
//! absent (`apt-get install python3-openvdb libopenvdb-tools`).

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use lab::synth::{scene_grids, speed_grid, write_scene, SynthOptions};
use qbricks_preprocess::grid::{AnyGrid, Grid, Leaf, Tile, Transform, LEAF_VOXELS};
use qbricks_preprocess::vdb::write::{
    write_vdb, write_vdb_with, Compression, MetaValue, WriteOptions,
};
use serde_json::Value;

const PYTHON: &str = "/usr/bin/python3";

const COMPRESSIONS: [Compression; 3] =
    [Compression::None, Compression::ActiveMask, Compression::Zip];

fn have_pyopenvdb() -> bool {
    let ok = crate::common::have_pyopenvdb();
    if !ok {
        eprintln!("SKIPPED: pyopenvdb not available (apt-get install python3-openvdb)");
    }
    ok
}

fn have_vdb_print() -> bool {
    let ok = Command::new("vdb_print").arg("-version").output().is_ok();
    if !ok {
        eprintln!("SKIPPED: vdb_print not available (apt-get install libopenvdb-tools)");
    }
    ok
}

/// Dumps every grid of a file as JSON: name, class, voxel size, translation, metadata,
/// active voxel count, all active items (voxels and tiles) and, for the leaf origins given
/// in argv[2] (a JSON object name → list of origins), every voxel's value and state.
const DUMP: &str = r#"
import json, sys
import pyopenvdb as vdb
grids, file_meta = vdb.readAll(sys.argv[1])
probe = json.load(open(sys.argv[2]))
out = {"file_metadata": {k: (list(v) if isinstance(v, tuple) else v) for k, v in file_meta.items()}, "grids": []}
for g in grids:
    items = [[list(x["min"]), list(x["max"]), x["value"]] for x in g.iterOnValues()]
    acc = g.getConstAccessor()
    leaves = []
    for o in probe.get(g.name, []):
        vals = []
        for n in range(512):
            ijk = (o[0] + (n >> 6), o[1] + ((n >> 3) & 7), o[2] + (n & 7))
            v, a = acc.probeValue(ijk)
            vals.append([v, a])
        leaves.append(vals)
    meta = {k: (list(v) if isinstance(v, tuple) else v) for k, v in g.metadata.items()}
    out["grids"].append({
        "name": g.name, "type": type(g).__name__,
        "voxel_size": list(g.transform.voxelSize()),
        "translation": list(g.transform.indexToWorld((0, 0, 0))),
        "background": g.background,
        "active": g.activeVoxelCount(), "items": items, "leaves": leaves, "metadata": meta})
print(json.dumps(out))
"#;

fn dump(path: &Path, probe: &BTreeMap<String, Vec<[i32; 3]>>) -> Value {
    let probe_path = path.with_extension("probe.json");
    std::fs::write(&probe_path, serde_json::to_vec(probe).expect("probe json")).expect("write");
    let out = Command::new(PYTHON)
        .arg("-c")
        .arg(DUMP)
        .arg(path)
        .arg(&probe_path)
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "pyopenvdb failed on {}: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("dump json")
}

fn f(v: &Value) -> f64 {
    v.as_f64().expect("number")
}

fn ivec(v: &Value) -> [i32; 3] {
    let a = v.as_array().expect("array");
    [0, 1, 2].map(|i| a[i].as_i64().expect("int") as i32)
}

/// Scalar or vector value as single-precision components (serde_json's default float
/// parsing can be one f64 ulp off; narrowing to the stored f32 makes the check exact).
fn comps(v: &Value) -> Vec<f32> {
    match v {
        Value::Array(a) => a.iter().map(|x| f(x) as f32).collect(),
        other => vec![f(other) as f32],
    }
}

/// f64 equality up to the last bits lost by serde_json's float parsing.
fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-14 * a.abs().max(b.abs())
}

/// The grid named `name` in a dump (readers need not keep file order).
fn by_name<'a>(grids: &'a [Value], name: &str) -> &'a Value {
    grids
        .iter()
        .find(|g| g["name"] == name)
        .unwrap_or_else(|| panic!("grid {name} not read back"))
}

trait Comps {
    fn comps(&self) -> Vec<f32>;
}
impl Comps for f32 {
    fn comps(&self) -> Vec<f32> {
        vec![*self]
    }
}
impl Comps for [f32; 3] {
    fn comps(&self) -> Vec<f32> {
        self.to_vec()
    }
}

/// Checks one grid read back by pyopenvdb against what was written: transform, background,
/// every active item (voxel or tile) and every value of the probed leaves.
fn check_grid<V: Copy + Comps>(got: &Value, want: &Grid<V>, probe: &[[i32; 3]]) {
    let name = &want.name;
    assert_eq!(got["name"], Value::from(name.as_str()));
    for a in 0..3 {
        assert_eq!(
            f(&got["voxel_size"][a]),
            want.transform.voxel_size[a],
            "{name}"
        );
        assert_eq!(
            f(&got["translation"][a]),
            want.transform.translation[a],
            "{name}"
        );
    }
    assert_eq!(
        comps(&got["background"]),
        want.background.comps(),
        "{name} background"
    );
    assert_eq!(
        got["active"].as_u64(),
        Some(want.active_voxel_count()),
        "{name}"
    );
    // Active items: (min, max) → value.
    let mut expected: BTreeMap<([i32; 3], [i32; 3]), Vec<f32>> = BTreeMap::new();
    for leaf in &want.leaves {
        for (ijk, v) in leaf.active_voxels() {
            expected.insert((ijk, ijk), v.comps());
        }
    }
    for t in &want.tiles {
        let max = t.origin.map(|c| c + t.size as i32 - 1);
        expected.insert((t.origin, max), t.value.comps());
    }
    let items = got["items"].as_array().expect("items");
    assert_eq!(items.len(), expected.len(), "{name}: active items");
    for item in items {
        let key = (ivec(&item[0]), ivec(&item[1]));
        let want_v = expected
            .get(&key)
            .unwrap_or_else(|| panic!("{name}: unexpected {key:?}"));
        assert_eq!(&comps(&item[2]), want_v, "{name} at {key:?}");
    }
    // Every voxel of the probed leaves, inactive ones included.
    let leaves = got["leaves"].as_array().expect("leaves");
    assert_eq!(leaves.len(), probe.len());
    for (origin, vals) in probe.iter().zip(leaves) {
        let leaf = want
            .leaves
            .iter()
            .find(|l| l.origin == *origin)
            .expect("probed leaf");
        for n in 0..LEAF_VOXELS {
            let pair = &vals[n];
            assert_eq!(
                comps(&pair[0]),
                leaf.values[n].comps(),
                "{name} leaf {origin:?} voxel {n}"
            );
            assert_eq!(
                pair[1].as_bool(),
                Some(leaf.is_active(n)),
                "{name} leaf {origin:?} voxel {n}"
            );
        }
    }
}

fn transform(h: f64, t: [f64; 3]) -> Transform {
    Transform {
        voxel_size: [h; 3],
        translation: t,
    }
}

/// A float grid that exercises every node-compression case, tiles at all three levels,
/// negative coordinates and a non-zero background.
fn tricky_float_grid() -> Grid<f32> {
    let bg = 0.5f32;
    let mut leaves = Vec::new();
    // Per-node metadata cases 0..=6 by what the inactive voxels hold.
    for case in 0..7 {
        let mut active = [0u64; 8];
        let mut values = Box::new([bg; LEAF_VOXELS]);
        for n in 0..LEAF_VOXELS {
            if n % 3 == 0 {
                active[n >> 6] |= 1 << (n & 63);
                values[n] = n as f32 * 0.25 - 40.0;
            } else {
                values[n] = match case {
                    0 => bg,
                    1 => -bg,
                    2 => 3.0,
                    3 => {
                        if n % 2 == 0 {
                            bg
                        } else {
                            -bg
                        }
                    }
                    4 => {
                        if n % 2 == 0 {
                            bg
                        } else {
                            7.0
                        }
                    }
                    5 => {
                        if n % 2 == 0 {
                            8.0
                        } else {
                            9.0
                        }
                    }
                    _ => n as f32,
                };
            }
        }
        leaves.push(Leaf {
            origin: [-64 + 8 * case, -8, 16],
            active,
            values,
        });
    }
    // A fully active leaf and an all-inactive one.
    leaves.push(Leaf {
        origin: [0, 0, 0],
        active: [u64::MAX; 8],
        values: Box::new(std::array::from_fn(|n| n as f32)),
    });
    leaves.push(Leaf {
        origin: [8, 0, 0],
        active: [0; 8],
        values: Box::new([bg; LEAF_VOXELS]),
    });
    let tiles = vec![
        Tile {
            origin: [16, 0, 0],
            size: 8,
            value: 1.5,
        },
        Tile {
            origin: [-128, 128, 0],
            size: 128,
            value: 2.5,
        },
        Tile {
            origin: [-8192, 0, 4096],
            size: 4096,
            value: 3.5,
        },
    ];
    Grid {
        name: "tricky".into(),
        transform: transform(0.25, [-1.0, 2.0, 0.125]),
        background: bg,
        leaves,
        tiles,
    }
}

#[test]
fn synth_and_tricky_grids_read_back_in_pyopenvdb() {
    if !have_pyopenvdb() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let velocity = scene_grids("wake", 16, 2).expect("grids");
    let speed: Vec<Grid<f32>> = velocity.iter().map(speed_grid).collect();
    let tricky = tricky_float_grid();
    let mut probe: BTreeMap<String, Vec<[i32; 3]>> = BTreeMap::new();
    probe.insert(
        "tricky".into(),
        tricky.leaves.iter().map(|l| l.origin).collect(),
    );
    // Partial leaves at box edges (first and last leaf of each grid).
    for g in &velocity {
        let first = g.leaves[0].origin;
        let last = g.leaves[g.leaves.len() - 1].origin;
        probe.insert(g.name.clone(), vec![first, last]);
    }
    let mut grids: Vec<AnyGrid> = velocity.iter().cloned().map(AnyGrid::Vec3s).collect();
    grids.extend(speed.iter().cloned().map(AnyGrid::Float));
    grids.push(AnyGrid::Float(tricky.clone()));
    for compression in COMPRESSIONS {
        let path = dir.path().join(format!("mixed_{compression:?}.vdb"));
        let mut options = WriteOptions::new(compression);
        options.grid_metadata = vec![BTreeMap::from([
            ("origin".to_string(), MetaValue::Vec3d([-0.75, -1.5, 2.0])),
            ("flag".to_string(), MetaValue::Bool(true)),
            ("count".to_string(), MetaValue::Int64(1 << 40)),
        ])];
        write_vdb_with(&path, &grids, &options).expect("write");
        let got = dump(&path, &probe);
        let g = got["grids"].as_array().expect("grids");
        assert_eq!(g.len(), grids.len());
        for v in &velocity {
            let got = by_name(g, &v.name);
            assert_eq!(got["type"], "Vec3SGrid");
            check_grid(got, v, &probe[&v.name]);
            let meta = &got["metadata"];
            assert_eq!(meta["class"], "unknown");
            assert_eq!(meta["is_saved_as_half_float"], false);
            assert_eq!(meta["value_type"], "vec3s");
            assert_eq!(meta["file_compression"], compression.describe());
            assert!(close(f(&meta["dx"]), v.transform.voxel_size[0]));
        }
        let meta0 = &by_name(g, &velocity[0].name)["metadata"];
        assert_eq!(comps(&meta0["origin"]), vec![-0.75, -1.5, 2.0]);
        assert_eq!(meta0["flag"], true);
        assert_eq!(meta0["count"].as_i64(), Some(1 << 40));
        for s in &speed {
            let got = by_name(g, &s.name);
            assert_eq!(got["type"], "FloatGrid");
            check_grid(got, s, &[]);
        }
        let last = by_name(g, "tricky");
        check_grid(last, &tricky, &probe["tricky"]);
        assert_eq!(last["metadata"]["value_type"], "float");
    }
}

#[test]
fn write_scene_output_reads_back_in_pyopenvdb() {
    if !have_pyopenvdb() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    for scene in ["wake-single", "lamb-oseen", "burgers", "abc"] {
        let path = dir.path().join(format!("{scene}.vdb"));
        let opts = SynthOptions {
            scene: scene.into(),
            n0: 12,
            levels: 3,
            compression: Compression::Zip,
            speed_grids: false,
            staggered: false,
            frame: 1,
            boxes: None,
        };
        write_scene(&path, &opts).expect("write");
        let want = scene_grids(scene, 12, 3).expect("grids");
        let got = dump(&path, &BTreeMap::new());
        assert_eq!(got["file_metadata"]["scene"], Value::from(scene));
        let g = got["grids"].as_array().expect("grids");
        assert_eq!(g.len(), 1);
        check_grid(&g[0], &want[0], &[]);
        assert_eq!(g[0]["metadata"]["scene"], Value::from(scene));
    }
}

/// `vdb_print -l` output: per grid, (name, type, active voxel count), sorted by name
/// (vdb_print does not keep file order).
fn vdb_print(path: &Path) -> Vec<(String, String, u64)> {
    let out = Command::new("vdb_print")
        .arg("-l")
        .arg(path)
        .output()
        .expect("run vdb_print");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "vdb_print failed on {}: {}{}",
        path.display(),
        text,
        String::from_utf8_lossy(&out.stderr)
    );
    let mut grids = Vec::new();
    let mut name = String::new();
    let mut ty = String::new();
    for line in text.lines() {
        let line = line.trim();
        if let Some(n) = line.strip_prefix("Name: ") {
            name = n.to_string();
        } else if let Some(t) = line.strip_prefix("Type: ") {
            ty = t.to_string();
        } else if let Some(c) = line.strip_prefix("Number of active voxels:") {
            let count = c.trim().replace(',', "").parse().expect("count");
            grids.push((name.clone(), ty.clone(), count));
        }
    }
    grids.sort();
    grids
}

#[test]
fn vdb_print_lists_every_grid_type_we_write() {
    if !have_vdb_print() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let tricky = tricky_float_grid();
    let widen = |l: &Leaf<f32>| Leaf {
        origin: l.origin,
        active: l.active,
        values: Box::new(std::array::from_fn(|n| f64::from(l.values[n]))),
    };
    let double = Grid {
        name: "double".into(),
        transform: tricky.transform,
        background: 0.5f64,
        leaves: tricky.leaves.iter().map(widen).collect(),
        tiles: tricky
            .tiles
            .iter()
            .map(|t| Tile {
                origin: t.origin,
                size: t.size,
                value: f64::from(t.value),
            })
            .collect(),
    };
    let vec3d = Grid {
        name: "vec3d".into(),
        transform: transform(0.1, [0.0; 3]),
        background: [0.0f64; 3],
        leaves: vec![Leaf {
            origin: [-8, -8, -8],
            active: [0x5555_5555_5555_5555; 8],
            values: Box::new(std::array::from_fn(|n| [n as f64, -(n as f64), 0.5])),
        }],
        tiles: vec![Tile {
            origin: [128, 0, 0],
            size: 128,
            value: [1.0, 2.0, 3.0],
        }],
    };
    let grids = vec![
        AnyGrid::Float(tricky.clone()),
        AnyGrid::Double(double.clone()),
        AnyGrid::Vec3d(vec3d.clone()),
    ];
    for compression in COMPRESSIONS {
        let path = dir.path().join(format!("types_{compression:?}.vdb"));
        write_vdb(&path, &grids, compression).expect("write");
        let listed = vdb_print(&path);
        let mut want = vec![
            (
                "tricky".to_string(),
                "Tree_float_5_4_3".to_string(),
                tricky.active_voxel_count(),
            ),
            (
                "double".to_string(),
                "Tree_double_5_4_3".to_string(),
                double.active_voxel_count(),
            ),
            (
                "vec3d".to_string(),
                "Tree_vec3d_5_4_3".to_string(),
                vec3d.active_voxel_count(),
            ),
        ];
        want.sort();
        assert_eq!(listed, want, "{compression:?}");
    }
    // A synth file with speed grids, as the CLI writes it.
    let path = dir.path().join("wake.vdb");
    let opts = SynthOptions {
        scene: "wake".into(),
        n0: 16,
        levels: 3,
        compression: Compression::Zip,
        speed_grids: true,
        staggered: false,
        frame: 1,
        boxes: None,
    };
    let (summary, _) = write_scene(&path, &opts).expect("write");
    let listed = vdb_print(&path);
    let mut want: Vec<(String, String, u64)> = summary
        .iter()
        .map(|s| {
            let ty = match s.value_type {
                "vec3s" => "Tree_vec3s_5_4_3",
                _ => "Tree_float_5_4_3",
            };
            (s.name.clone(), ty.to_string(), s.active_voxels)
        })
        .collect();
    want.sort();
    assert_eq!(want.len(), 6);
    assert_eq!(listed, want);
}

#[test]
fn writer_is_deterministic_and_atomic() {
    let dir = tempfile::tempdir().expect("tempdir");
    let opts = SynthOptions {
        scene: "wake".into(),
        n0: 16,
        levels: 2,
        compression: Compression::Zip,
        speed_grids: true,
        staggered: false,
        frame: 1,
        boxes: None,
    };
    let a = dir.path().join("a.vdb");
    let b = dir.path().join("b.vdb");
    let (_, size) = write_scene(&a, &opts).expect("a");
    write_scene(&b, &opts).expect("b");
    let bytes_a = std::fs::read(&a).expect("read a");
    assert_eq!(bytes_a.len() as u64, size);
    assert_eq!(bytes_a, std::fs::read(&b).expect("read b"));
    // Only the two outputs in the directory: no temporary file left behind.
    assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 2);
    // A write that fails in the atomic path itself — everything written and synced, then
    // the rename refused because the target is a non-empty directory — leaves the target
    // as it was and no temporary file behind.
    let target = dir.path().join("c.vdb");
    std::fs::create_dir(&target).expect("mkdir");
    std::fs::write(target.join("keep"), b"kept").expect("write");
    let e = write_scene(&target, &opts).expect_err("rename over a directory");
    assert!(e.to_string().contains("c.vdb"), "{e}");
    assert_eq!(std::fs::read(target.join("keep")).expect("kept"), b"kept");
    assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 3);
    std::fs::remove_dir_all(&target).expect("rm");
    // A write refused before any file is created (a zero voxel size) leaves the existing
    // file untouched too.
    let bad = Grid {
        name: "bad".into(),
        transform: transform(0.0, [0.0; 3]),
        background: 0.0f32,
        leaves: Vec::new(),
        tiles: Vec::new(),
    };
    assert!(write_vdb(&a, &[AnyGrid::Float(bad)], Compression::Zip).is_err());
    assert_eq!(std::fs::read(&a).expect("read a"), bytes_a);
    assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 2);
}
