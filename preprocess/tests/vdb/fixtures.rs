//! The reader against files written by real OpenVDB (tests/fixtures, made by
//! make_fixtures.py): every active voxel, tile and (for the mask-compression fixtures)
//! inactive leaf value must equal what OpenVDB itself read from the same file.

use crate::common::vdb::*;
use crate::common::{fixtures, qbricks_bake};
use qbricks_preprocess::vdb::{MetaValue, ValueType, VdbFile};
use serde_json::Value;

fn expected() -> serde_json::Map<String, Value> {
    let text = std::fs::read_to_string(fixtures().join("expected.json")).expect("expected.json");
    match serde_json::from_str(&text).expect("valid JSON") {
        Value::Object(m) => m,
        _ => panic!("expected.json is not an object"),
    }
}

fn check_file(name: &str, exp: &Value) {
    let file = VdbFile::open(fixtures().join(name)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        u64::from(file.file_version),
        exp["file_version"].as_u64().unwrap(),
        "{name}"
    );
    let exp_grids = exp["grids"].as_array().unwrap();
    assert_eq!(file.grids().len(), exp_grids.len(), "{name}: grid count");
    for (i, eg) in exp_grids.iter().enumerate() {
        let d = &file.grids()[i];
        let ctx = format!("{name}: grid {i} {:?}", d.name);
        assert_eq!(d.name, eg["name"].as_str().unwrap(), "{ctx}");
        assert_eq!(
            d.value_type.name(),
            eg["value_type"].as_str().unwrap(),
            "{ctx}"
        );
        assert_eq!(d.half_float, eg["half_float"].as_bool().unwrap(), "{ctx}");
        let g = flatten(&file.read_grid(i).unwrap_or_else(|e| panic!("{e}")));
        assert_eq!(
            g.voxel_size.to_vec(),
            json_comps(&eg["voxel_size"]),
            "{ctx}: voxel size"
        );
        assert_eq!(
            g.translation.to_vec(),
            json_comps(&eg["translation"]),
            "{ctx}: translation"
        );
        assert!(
            same(&g.background, &json_comps(&eg["background"])),
            "{ctx}: background"
        );

        let mut voxels: Vec<([i32; 3], Vec<f64>)> = eg["voxels"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| (json_ijk(v), json_comps(&v[3])))
            .collect();
        voxels.sort_by_key(|v| v.0);
        assert_eq!(g.voxels.len(), voxels.len(), "{ctx}: active voxel count");
        for (got, want) in g.voxels.iter().zip(&voxels) {
            assert_eq!(got.0, want.0, "{ctx}: voxel position");
            assert!(
                same(&got.1, &want.1),
                "{ctx}: voxel {:?}: {:?} != {:?}",
                got.0,
                got.1,
                want.1
            );
        }

        let tiles = json_tiles(&eg["tiles"]);
        assert_eq!(g.tiles.len(), tiles.len(), "{ctx}: tile count");
        for (got, want) in g.tiles.iter().zip(&tiles) {
            assert_eq!((got.0, got.1), (want.0, want.1), "{ctx}: tile");
            assert!(same(&got.2, &want.2), "{ctx}: tile {:?} value", got.0);
        }
        let total: u64 =
            g.voxels.len() as u64 + g.tiles.iter().map(|t| u64::from(t.1).pow(3)).sum::<u64>();
        assert_eq!(
            total,
            eg["active_voxels"].as_u64().unwrap(),
            "{ctx}: active voxels"
        );

        if let Some(inactive) = eg.get("inactive") {
            let mut want: Vec<([i32; 3], Vec<f64>)> = inactive
                .as_array()
                .unwrap()
                .iter()
                .map(|v| (json_ijk(v), json_comps(&v[3])))
                .collect();
            want.sort_by_key(|v| v.0);
            assert_eq!(g.inactive.len(), want.len(), "{ctx}: inactive count");
            for (got, w) in g.inactive.iter().zip(&want) {
                assert_eq!(got.0, w.0, "{ctx}");
                assert!(
                    same(&got.1, &w.1),
                    "{ctx}: inactive {:?}: {:?} != {:?}",
                    got.0,
                    got.1,
                    w.1
                );
            }
        }
    }
}

#[test]
fn every_fixture_matches_openvdb() {
    let exp = expected();
    assert!(exp.len() >= 10, "fixtures missing");
    for (name, e) in &exp {
        check_file(name, e);
    }
}

#[test]
fn fixtures_cover_codecs_types_half_and_tiles() {
    // Guard against a regenerated fixture set silently losing coverage.
    let mut codecs = std::collections::BTreeSet::new();
    let mut types = std::collections::BTreeSet::new();
    let mut maps = std::collections::BTreeSet::new();
    let (mut half, mut root_tile, mut internal_tile, mut instance, mut negative) =
        (false, false, false, false, false);
    for name in expected().keys() {
        let file = VdbFile::open(fixtures().join(name)).unwrap();
        for (i, d) in file.grids().iter().enumerate() {
            codecs.insert(d.compression & 0x5);
            types.insert(d.value_type.name().to_string());
            maps.insert(d.map_type.clone());
            half |= d.half_float;
            instance |= d.instance_of.is_some();
            let g = flatten(&file.read_grid(i).unwrap());
            root_tile |= g.tiles.iter().any(|t| t.1 == 4096);
            internal_tile |= g.tiles.iter().any(|t| t.1 == 128 || t.1 == 8);
            negative |= g.voxels.iter().any(|v| v.0.iter().any(|&c| c < 0));
        }
    }
    assert_eq!(codecs.len(), 3, "none, zip and blosc");
    assert_eq!(types.len(), 4, "{types:?}");
    // OpenVDB turns a TranslationMap into a UniformScaleTranslateMap when it builds the
    // transform, so real files hold the other four (TranslationMap has a unit test).
    assert_eq!(maps.len(), 4, "scale/translate maps: {maps:?}");
    assert!(half && root_tile && internal_tile && instance && negative);
    // One file written to a stream (no grid offsets): the stream reader path.
    let stream = std::fs::read(fixtures().join("float_stream.vdb")).unwrap();
    assert_eq!(stream[20], 0, "float_stream.vdb has grid offsets");
}

#[test]
fn metadata_duplicate_names_and_instances_read_as_openvdb_wrote_them() {
    let file = VdbFile::open(fixtures().join("multi_zip.vdb")).unwrap();
    let names: Vec<&str> = file.grids().iter().map(|g| g.name.as_str()).collect();
    assert_eq!(
        names.iter().filter(|n| **n == "vel").count(),
        2,
        "{names:?}"
    );
    let coarse = file
        .grids()
        .iter()
        .find(|g| g.name == "vel" && g.metadata.get("dx") == Some(&MetaValue::Double(0.5)))
        .expect("coarse vel grid with dx metadata");
    assert_eq!(
        coarse.metadata.get("origin"),
        Some(&MetaValue::Vec3d([-1.0, -2.0, 0.25]))
    );
    assert_eq!(coarse.metadata.get("level"), Some(&MetaValue::Int32(0)));
    assert_eq!(coarse.metadata.get("refined"), Some(&MetaValue::Bool(true)));
    assert_eq!(
        coarse.metadata.get("source"),
        Some(&MetaValue::String("make_fixtures.py".into()))
    );
    assert_eq!(coarse.value_type, ValueType::Vec3s);
    let copy = file
        .grids()
        .iter()
        .position(|g| g.name == "density_copy")
        .unwrap();
    let parent = file.grids()[copy]
        .instance_of
        .expect("density_copy is an instance");
    assert_eq!(file.grids()[parent].name, "density");
    let a = flatten(&file.read_grid(copy).unwrap());
    let b = flatten(&file.read_grid(parent).unwrap());
    assert_eq!(a.voxels, b.voxels);
    assert_ne!(
        a.translation, b.translation,
        "an instance keeps its own transform"
    );
}

#[test]
fn newer_file_versions_read_the_same() {
    // Versions 223 to 225 differ only in features these grid types don't use; a 224 file
    // relabelled as 225 or 223 must read identically.
    let bytes = std::fs::read(fixtures().join("multi_blosc.vdb")).unwrap();
    let base = VdbFile::from_bytes("multi_blosc.vdb", bytes.clone())
        .unwrap()
        .read_all()
        .unwrap();
    for v in [223u32, 225] {
        let mut b = bytes.clone();
        b[8..12].copy_from_slice(&v.to_le_bytes());
        let f = VdbFile::from_bytes("relabelled.vdb", b).unwrap();
        assert_eq!(f.file_version, v);
        assert_eq!(f.read_all().unwrap(), base);
    }
}

/// Mean over active voxels (tiles weighted by their voxel count), per component.
fn expected_mean(eg: &Value) -> Vec<f64> {
    let mut sum = Vec::new();
    let mut n = 0f64;
    let mut add = |v: Vec<f64>, w: f64| {
        sum.resize(v.len(), 0.0);
        for (s, c) in sum.iter_mut().zip(v) {
            *s += c * w;
        }
        n += w;
    };
    for v in eg["voxels"].as_array().unwrap() {
        add(json_comps(&v[3]), 1.0);
    }
    for t in eg["tiles"].as_array().unwrap() {
        add(json_comps(&t[4]), (t[3].as_f64().unwrap()).powi(3));
    }
    sum.iter().map(|s| s / n).collect()
}

#[test]
fn inspect_json_matches_openvdb() {
    let exp = expected();
    for name in [
        "multi_zip.vdb",
        "double_blosc.vdb",
        "half_zip.vdb",
        "float_none.vdb",
    ] {
        let out = qbricks_bake()
            .args(["inspect", "--json"])
            .arg(fixtures().join(name))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let got: Value = serde_json::from_slice(&out.stdout).unwrap();
        let e = &exp[name];
        assert_eq!(got["file_version"], e["file_version"]);
        assert_eq!(got["library_version"], e["library_version"]);
        let grids = got["grids"].as_array().unwrap();
        let want_grids = e["grids"].as_array().unwrap();
        // `zip` below stops at the shorter list: a missing or extra grid must fail here.
        assert_eq!(grids.len(), want_grids.len(), "{name}: grid count");
        for (g, eg) in grids.iter().zip(want_grids) {
            let ctx = format!("{name} {}", eg["name"]);
            for key in ["name", "value_type", "half_float", "active_voxels"] {
                assert_eq!(g[key], eg[key], "{ctx}: {key}");
            }
            assert_eq!(json_comps(&g["voxel_size"]), json_comps(&eg["voxel_size"]));
            assert_eq!(
                json_comps(&g["translation"]),
                json_comps(&eg["translation"])
            );
            assert!(
                g["compression"].is_array() && g["metadata"].is_object(),
                "{ctx}"
            );
            let mean = json_comps(&g["mean"]);
            let want = expected_mean(eg);
            assert_eq!(mean.len(), want.len(), "{ctx}: mean components");
            for (m, w) in mean.iter().zip(&want) {
                assert!(
                    (m - w).abs() <= 1e-9 * w.abs().max(1.0),
                    "{ctx}: mean {m} vs {w}"
                );
            }
            // Bounds and extremes from the voxel and tile lists.
            let mut lo = [i32::MAX; 3];
            let mut hi = [i32::MIN; 3];
            let mut vals = Vec::new();
            for v in eg["voxels"].as_array().unwrap() {
                let p = json_ijk(v);
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
                vals.push(json_comps(&v[3]));
            }
            for t in eg["tiles"].as_array().unwrap() {
                let p = json_ijk(t);
                let s = t[3].as_i64().unwrap() as i32;
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k] + s - 1);
                }
                vals.push(json_comps(&t[4]));
            }
            assert_eq!(json_ijk(&g["bbox_min"]), lo, "{ctx}");
            assert_eq!(json_ijk(&g["bbox_max"]), hi, "{ctx}");
            if eg["value_type"] == "float" || eg["value_type"] == "double" {
                let min = vals.iter().map(|v| v[0]).fold(f64::INFINITY, f64::min);
                let max = vals.iter().map(|v| v[0]).fold(f64::NEG_INFINITY, f64::max);
                assert_eq!(g["min"].as_f64().unwrap(), min, "{ctx}");
                assert_eq!(g["max"].as_f64().unwrap(), max, "{ctx}");
            } else {
                let m = vals
                    .iter()
                    .map(|v| v.iter().map(|c| c * c).sum::<f64>().sqrt())
                    .fold(0.0, f64::max);
                assert!(
                    (g["max_magnitude"].as_f64().unwrap() - m).abs() <= 1e-12 * m,
                    "{ctx}"
                );
            }
        }
    }
    // Metadata of a known grid.
    let out = qbricks_bake()
        .args(["inspect", "--json"])
        .arg(fixtures().join("double_zip.vdb"))
        .output()
        .unwrap();
    let got: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(got["grids"][0]["metadata"]["dx"], serde_json::json!(0.125));
    assert_eq!(
        got["grids"][1]["metadata"]["origin"],
        serde_json::json!([-3.0, 0.0, 4.0])
    );
}

#[test]
fn inspect_table_names_every_grid() {
    let out = qbricks_bake()
        .arg("inspect")
        .arg(fixtures().join("multi_blosc.vdb"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    for name in ["\"vel\"", "\"density\"", "\"density_copy\"", "blosc"] {
        assert!(text.contains(name), "{name} missing from:\n{text}");
    }
}

#[test]
fn vdb_rs_agrees_on_a_float_fixture() {
    // vdb-rs (an independent Rust reader; it reads scalar grids) as a second oracle.
    let path = fixtures().join("float_blosc.vdb");
    let ours = flatten(&VdbFile::open(&path).unwrap().read_grid(0).unwrap());
    let f = std::fs::File::open(&path).unwrap();
    let mut reader = vdb_rs::VdbReader::new(std::io::BufReader::new(f)).unwrap();
    let grid = reader.read_grid::<f32>("temperature").unwrap();
    let mut voxels = Vec::new();
    let mut tiles = Vec::new();
    for (p, v, level) in grid.iter() {
        let ijk = [p.x as i32, p.y as i32, p.z as i32];
        match level {
            vdb_rs::VdbLevel::Voxel => voxels.push((ijk, vec![f64::from(v)])),
            vdb_rs::VdbLevel::Node3 => tiles.push((ijk, 8u32, vec![f64::from(v)])),
            vdb_rs::VdbLevel::Node4 => tiles.push((ijk, 128u32, vec![f64::from(v)])),
        }
    }
    voxels.sort_by_key(|v| v.0);
    tiles.sort_by_key(|t| (t.0, t.1));
    assert!(
        voxels.len() >= 16,
        "vdb-rs read {} voxels, {} tiles",
        voxels.len(),
        tiles.len()
    );
    assert_eq!(ours.voxels, voxels);
    assert_eq!(ours.tiles, tiles);
}
