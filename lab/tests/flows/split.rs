//! Velocity given as three scalar component grids (`X.x`/`X.y`/`X.z`, `X_x`…, `Xx`…):
//! baked exactly like the vec3 grid they split; mismatched components and ambiguous
//! candidates are one-line exit-2 errors naming the grids.

use std::path::Path;
use std::process::Output;

use crate::common::qbricks_bake;
use format::BrickFileView;
use lab::synth::scene_grids;
use qbricks_preprocess::grid::{AnyGrid, Grid, Leaf};
use qbricks_preprocess::vdb::write::{write_vdb, Compression};

/// The `lamb-oseen` velocity at n0 = 16 and its three components named `base{sep}{c}`.
fn components(base: &str, sep: &str) -> (Grid<[f32; 3]>, Vec<Grid<f32>>) {
    let vel = scene_grids("lamb-oseen", 16, 1).unwrap().remove(0);
    let parts = (0..3)
        .map(|c| Grid {
            name: format!("{base}{sep}{}", ["x", "y", "z"][c]),
            transform: vel.transform,
            background: 0.0,
            leaves: vel
                .leaves
                .iter()
                .map(|l| Leaf {
                    origin: l.origin,
                    active: l.active,
                    values: Box::new(l.values.map(|v| v[c])),
                })
                .collect(),
            tiles: vec![],
        })
        .collect();
    (vel, parts)
}

fn write(path: &Path, grids: Vec<AnyGrid>) {
    write_vdb(path, &grids, Compression::Zip).unwrap();
}

fn bake(args: &[&str], input: &Path, output: &Path) -> Output {
    qbricks_bake()
        .arg("bake")
        .arg(input)
        .arg("-o")
        .arg(output)
        .arg("--quiet")
        .args(args)
        .output()
        .unwrap()
}

fn fields(path: &Path) -> Vec<(String, Vec<f32>)> {
    let view = BrickFileView::open(path).unwrap();
    view.file()
        .fields
        .iter()
        .map(|f| {
            (
                f.name.to_string(),
                f.values.iter().map(|v| v.to_native()).collect(),
            )
        })
        .collect()
}

fn one_line_error(out: &Output) -> String {
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr).trim_end().to_string();
    assert_eq!(err.lines().count(), 1, "{err}");
    err
}

#[test]
fn every_naming_style_bakes_like_the_vec3_grid() {
    let dir = tempfile::tempdir().unwrap();
    let (vel, _) = components("vel", ".");
    let whole = dir.path().join("whole.vdb");
    write(&whole, vec![AnyGrid::Vec3s(vel)]);
    let out = bake(
        &["--fields", "q,speed,velocity"],
        &whole,
        &dir.path().join("whole.qbk"),
    );
    assert!(out.status.success(), "{out:?}");
    let want = fields(&dir.path().join("whole.qbk"));
    for (base, sep) in [("vel", "."), ("v", "_"), ("flow", "")] {
        let (_, parts) = components(base, sep);
        let path = dir.path().join(format!("{base}.vdb"));
        // A scalar grid that is not a component rides along.
        let (_, mut extra) = components("density", ".");
        extra.truncate(1);
        write(
            &path,
            parts.into_iter().chain(extra).map(AnyGrid::Float).collect(),
        );
        let qbk = dir.path().join(format!("{base}.qbk"));
        let out = bake(&["--fields", "q,speed,velocity"], &path, &qbk);
        assert!(out.status.success(), "{base}: {out:?}");
        assert_eq!(fields(&qbk), want, "{base}{sep}x");
        let view = BrickFileView::open(&qbk).unwrap();
        assert_eq!(view.file().provenance.grids[0].name, base);
    }
}

#[test]
fn several_candidates_need_velocity() {
    let dir = tempfile::tempdir().unwrap();
    let (vel, parts) = components("u", ".");
    let path = dir.path().join("two.vdb");
    let mut grids: Vec<AnyGrid> = parts.into_iter().map(AnyGrid::Float).collect();
    grids.push(AnyGrid::Vec3s(vel));
    write(&path, grids);
    let qbk = dir.path().join("two.qbk");
    let err = one_line_error(&bake(&[], &path, &qbk));
    assert!(
        err.contains("several velocity candidates (\"vel\", \"u\"): choose one with --velocity"),
        "{err}"
    );
    assert!(!qbk.exists());
    for pick in ["u", "vel"] {
        let out = bake(&["--velocity", pick], &path, &qbk);
        assert!(out.status.success(), "{pick}: {out:?}");
        let view = BrickFileView::open(&qbk).unwrap();
        assert_eq!(view.file().provenance.grids[0].name, pick);
    }
    let err = one_line_error(&bake(&["--velocity", "w"], &path, &qbk));
    assert!(
        err.contains("no velocity named \"w\" (candidates: \"vel\", \"u\")"),
        "{err}"
    );
    let err = one_line_error(&bake(&["--velocity", "u", "--grid", "vel"], &path, &qbk));
    assert!(
        err.contains("--grid and --velocity cannot be combined"),
        "{err}"
    );
}

#[test]
fn mismatched_components_are_refused_naming_the_grids() {
    let dir = tempfile::tempdir().unwrap();
    let names = "\"vel.x\", \"vel.y\", \"vel.z\"";
    // Different transform on one component.
    let (_, mut parts) = components("vel", ".");
    parts[1].transform.voxel_size = parts[1].transform.voxel_size.map(|v| 2.0 * v);
    let path = dir.path().join("transform.vdb");
    write(&path, parts.into_iter().map(AnyGrid::Float).collect());
    let err = one_line_error(&bake(&[], &path, &dir.path().join("t.qbk")));
    assert!(
        err.starts_with(&format!(
            "qbricks-bake: {}: component grids {names}: different transforms",
            path.display()
        )),
        "{err}"
    );
    assert!(err.contains("\"vel.y\" has voxel size"), "{err}");
    // One voxel less in one component.
    let (_, mut parts) = components("vel", ".");
    parts[2].leaves[3].active[0] &= !1;
    let path = dir.path().join("active.vdb");
    write(&path, parts.into_iter().map(AnyGrid::Float).collect());
    let err = one_line_error(&bake(&[], &path, &dir.path().join("a.qbk")));
    assert!(
        err.contains(&format!("component grids {names}: active sets differ")),
        "{err}"
    );
    // Same counts, different voxels.
    let (_, mut parts) = components("vel", ".");
    parts[0].leaves[5].active[0] &= !1;
    let mut lone = parts[0].leaves[5].clone();
    lone.origin = [64, 64, 64];
    lone.active = [0; 8];
    lone.active[0] = 1;
    parts[0].leaves.push(lone);
    let origin = parts[0].leaves[5].origin;
    let path = dir.path().join("moved.vdb");
    write(&path, parts.into_iter().map(AnyGrid::Float).collect());
    let err = one_line_error(&bake(&[], &path, &dir.path().join("m.qbk")));
    assert!(
        err.contains("active sets differ in the 8³ block at voxel") && err.contains("vel.x"),
        "{err} (changed block {origin:?})"
    );
}
