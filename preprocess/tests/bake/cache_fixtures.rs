//! OpenVDB-written simulation-cache layouts (`preprocess/tests/fixtures/make_fixtures.py`): a
//! Mantaflow-like staggered velocity grid with half floats and blosc, and velocity split
//! into three float grids (`vel.x`, `vel.y`, `vel.z`) as Houdini exports it.

use std::path::PathBuf;

use crate::common::{fixtures, qbricks_bake};
use format::BrickFileView;
use qbricks_preprocess::bake::{bake, BakeOptions};
use qbricks_preprocess::grid::{AnyGrid, Grid};
use qbricks_preprocess::vdb::VdbFile;
use serde_json::Value;

fn fixture(name: &str) -> PathBuf {
    fixtures().join(name)
}

fn inspect(name: &str) -> Value {
    let out = qbricks_bake()
        .args(["inspect", "--json"])
        .arg(fixture(name))
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn inspect_shows_the_cache_layouts() {
    let v = inspect("cache_staggered_blosc.vdb");
    // OpenVDB writes grids in name order: density, velocity.
    let g = &v["grids"];
    assert_eq!(g[1]["name"], "velocity");
    let g = [&g[1], &g[0]];
    assert_eq!(g[0]["class"], "staggered");
    assert_eq!(g[0]["half_float"], true);
    assert!(g[0]["compression"]
        .as_array()
        .unwrap()
        .contains(&"blosc".into()));
    assert_eq!(g[1]["name"], "density");
    assert_eq!(g[1]["class"], "fog volume");
    let out = qbricks_bake()
        .arg("inspect")
        .arg(fixture("cache_staggered_blosc.vdb"))
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("class        staggered") && text.contains("class        fog volume"),
        "{text}"
    );

    let v = inspect("split_zip.vdb");
    let names: Vec<&str> = v["grids"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| g["name"].as_str().unwrap())
        .collect();
    let mut sorted = names.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, ["temperature", "vel.x", "vel.y", "vel.z"]);
    for g in v["grids"].as_array().unwrap() {
        assert_eq!(g["class"], "unknown");
    }
}

fn q_and_density(path: &std::path::Path) -> (Vec<f32>, Vec<f32>) {
    let view = BrickFileView::open(path).unwrap();
    let f = view.file();
    let get = |n: &str| {
        f.fields
            .iter()
            .find(|x| x.name == n)
            .unwrap()
            .values
            .iter()
            .map(|v| v.to_native())
            .collect::<Vec<f32>>()
    };
    (get("q"), get("density"))
}

#[test]
fn the_staggered_cache_bakes_as_a_mac_grid_with_density() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c.qbk");
    let o = qbricks_bake()
        .arg("bake")
        .arg(fixture("cache_staggered_blosc.vdb"))
        .arg("-o")
        .arg(&out)
        .args(["--quiet", "--fields", "q,speed,density"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{o:?}");
    let (q, density) = q_and_density(&out);
    // The library with the grid marked staggered gives the same Q; centred differs.
    let file = VdbFile::open(fixture("cache_staggered_blosc.vdb")).unwrap();
    let mut grids = file.read_all().unwrap();
    // velocity first, then density (the file has them in name order).
    grids.reverse();
    let field = |f: &format::BrickFile, n: &str| {
        f.fields
            .iter()
            .find(|x| x.name == n)
            .unwrap()
            .values
            .clone()
    };
    let mac = BakeOptions {
        staggered: vec!["velocity".into()],
        ..BakeOptions::default()
    };
    let lib = bake(vec![grids[0].clone()], &mac).unwrap().0;
    assert_eq!(q, field(&lib, "q"));
    let centred = bake(vec![grids[0].clone()], &BakeOptions::default())
        .unwrap()
        .0;
    assert_ne!(q, field(&centred, "q"));
    // Density on the velocity's lattice: the voxel values as OpenVDB stored them (half).
    let AnyGrid::Float(d) = &grids[1] else {
        panic!("density is a float grid")
    };
    let mut stored: Vec<f32> = d
        .leaves
        .iter()
        .flat_map(|l| l.active_voxels().map(|(_, v)| v))
        .collect();
    let mut baked = density.clone();
    stored.sort_by(f32::total_cmp);
    baked.sort_by(f32::total_cmp);
    assert_eq!(baked, stored);
}

#[test]
fn split_components_from_openvdb_bake_as_one_velocity() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.qbk");
    let o = qbricks_bake()
        .arg("bake")
        .arg(fixture("split_zip.vdb"))
        .arg("-o")
        .arg(&out)
        .args(["--quiet", "--fields", "q,velocity"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{o:?}");
    let view = BrickFileView::open(&out).unwrap();
    let f = view.file();
    assert_eq!(f.provenance.grids.len(), 1);
    assert_eq!(f.provenance.grids[0].name, "vel");
    // Same as baking a vec3 grid assembled here from the three (tile included).
    let file = VdbFile::open(fixture("split_zip.vdb")).unwrap();
    let parts: Vec<Grid<f32>> = ["vel.x", "vel.y", "vel.z"]
        .iter()
        .map(|n| file.grids().iter().position(|g| g.name == *n).unwrap())
        .map(|i| match file.read_grid(i).unwrap() {
            AnyGrid::Float(g) => g,
            _ => panic!("float components"),
        })
        .collect();
    let merged =
        qbricks_preprocess::inputs::merge_components("vel", [&parts[0], &parts[1], &parts[2]])
            .unwrap();
    assert_eq!(merged.active_voxel_count(), 16 * 12 * 7 + 512);
    let opts = BakeOptions {
        fields: Some(vec![
            qbricks_preprocess::fields::FieldKind::Q,
            qbricks_preprocess::fields::FieldKind::Velocity,
        ]),
        ..BakeOptions::default()
    };
    let lib = bake(vec![AnyGrid::Vec3d(merged)], &opts).unwrap().0;
    for (a, b) in f.fields.iter().zip(&lib.fields) {
        assert_eq!(a.name.as_str(), b.name);
        let got: Vec<f32> = a.values.iter().map(|v| v.to_native()).collect();
        assert_eq!(got, b.values, "{}", b.name);
    }
}
