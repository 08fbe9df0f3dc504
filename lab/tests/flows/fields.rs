//! Extra fields (`--fields q,speed,density,…`): scalar grids of the file resampled onto the
//! velocity's leaf cells; and the field-list and overflow cases of issue 12 (duplicate
//! fields, several scalar `--grid`s, velocities whose Q or speed overflow f32).

use std::path::Path;
use std::process::Output;

use crate::common::qbricks_bake;
use lab::synth::{sample_grid, scene_layout, GridLayout};
use qbricks_preprocess::bake::{bake, BakeError, BakeOptions};
use qbricks_preprocess::fields::FieldKind;
use qbricks_preprocess::grid::{AnyGrid, Grid, Leaf, Transform};
use qbricks_preprocess::vdb::write::{write_vdb, Compression};

/// A scalar grid over the index box `lo..hi` with values `f(world centre)`.
fn scalar(
    name: &str,
    t: Transform,
    lo: [i32; 3],
    hi: [i32; 3],
    f: impl Fn([f64; 3]) -> f64,
) -> Grid<f32> {
    let mut leaves = Vec::new();
    let start = lo.map(|v| v.div_euclid(8) * 8);
    let mut o = start;
    while o[0] < hi[0] {
        o[1] = start[1];
        while o[1] < hi[1] {
            o[2] = start[2];
            while o[2] < hi[2] {
                let mut leaf = Leaf {
                    origin: o,
                    active: [0; 8],
                    values: Box::new([0.0; 512]),
                };
                for n in 0..512 {
                    let ijk = [
                        o[0] + (n >> 6) as i32,
                        o[1] + ((n >> 3) & 7) as i32,
                        o[2] + (n & 7) as i32,
                    ];
                    if (0..3).all(|a| ijk[a] >= lo[a] && ijk[a] < hi[a]) {
                        leaf.active[n >> 6] |= 1 << (n & 63);
                        leaf.values[n] = f(t.index_to_world(ijk.map(f64::from))) as f32;
                    }
                }
                leaves.push(leaf);
                o[2] += 8;
            }
            o[1] += 8;
        }
        o[0] += 8;
    }
    Grid {
        name: name.into(),
        transform: t,
        background: 0.0,
        leaves,
        tiles: vec![],
    }
}

fn linear(p: [f64; 3]) -> f64 {
    1.0 + p[0] + 2.0 * p[1] - 0.5 * p[2]
}

fn velocity() -> (GridLayout, Grid<[f32; 3]>) {
    let layout = scene_layout("lamb-oseen", 16, 1).unwrap().remove(0);
    let flow = lab::analytic::scene("lamb-oseen").unwrap();
    let g = sample_grid(flow.as_ref(), &layout);
    (layout, g)
}

fn field<'a>(f: &'a format::BrickFile, name: &str) -> &'a format::Field {
    f.fields.iter().find(|x| x.name == name).unwrap()
}

/// Leaf-cell centres in value order.
fn centres(f: &format::BrickFile) -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    for b in &f.bricks {
        let d = b.dims.map(|d| d as usize);
        for z in 0..d[2] {
            for y in 0..d[1] {
                for x in 0..d[0] {
                    let c = [x, y, z];
                    out.push([0, 1, 2].map(|a| b.origin[a] + c[a] as f64 * b.cell_width));
                }
            }
        }
    }
    out
}

#[test]
fn scalar_grids_are_baked_on_the_velocity_cells() {
    let (layout, vel) = velocity();
    let t = vel.transform;
    let lo = layout.lo.map(|v| v as i32);
    let hi = layout.hi.map(|v| v as i32);
    // density on the velocity's lattice; temperature on a coarser, shifted lattice covering
    // more than the velocity (so trilinear sampling has all 8 voxels everywhere).
    let density = scalar("density", t, lo, hi, |p| (3.0 * p[0]).sin() + p[1] * p[2]);
    let tt = Transform {
        voxel_size: [0.3; 3],
        translation: [0.05, -0.02, 0.11],
    };
    let temperature = scalar("temperature", tt, [-5; 3], [6; 3], linear);
    let grids = vec![
        AnyGrid::Vec3s(vel.clone()),
        AnyGrid::Float(density.clone()),
        AnyGrid::Float(temperature),
    ];
    let opts = BakeOptions {
        fields: Some(vec![
            FieldKind::Q,
            FieldKind::Scalar("density".into()),
            FieldKind::Speed,
            FieldKind::Scalar("temperature".into()),
        ]),
        ..BakeOptions::default()
    };
    let (file, summary) = bake(grids, &opts).unwrap();
    let names: Vec<&str> = file.fields.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["q", "density", "speed", "temperature"]);
    assert_eq!(summary.fields.len(), 4);
    let cs = centres(&file);
    // Same lattice: the voxel's own value, bit for bit.
    for (c, v) in cs.iter().zip(&field(&file, "density").values) {
        let want = ((3.0 * c[0]).sin() + c[1] * c[2]) as f32;
        assert!(
            (v - want).abs() <= 1e-6 * want.abs().max(1.0),
            "{c:?}: {v} vs {want}"
        );
    }
    // Other lattice: trilinear reproduces a linear function (up to f32 rounding).
    for (c, v) in cs.iter().zip(&field(&file, "temperature").values) {
        let want = linear(*c);
        assert!((f64::from(*v) - want).abs() < 1e-5, "{c:?}: {v} vs {want}");
    }
    // Q and speed do not change by adding fields.
    let plain = bake(vec![AnyGrid::Vec3s(vel)], &BakeOptions::default())
        .unwrap()
        .0;
    assert_eq!(field(&file, "q").values, field(&plain, "q").values);
    assert_eq!(field(&file, "speed").values, field(&plain, "speed").values);
}

fn write(path: &Path, grids: Vec<AnyGrid>) {
    write_vdb(path, &grids, Compression::Zip).unwrap();
}

fn bake_cli(input: &Path, args: &[&str]) -> Output {
    qbricks_bake()
        .arg("bake")
        .arg(input)
        .args(["--quiet", "-o"])
        .arg(input.with_extension("qbk"))
        .args(args)
        .output()
        .unwrap()
}

fn error_line(out: &Output) -> String {
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let e = String::from_utf8_lossy(&out.stderr).trim_end().to_string();
    assert_eq!(e.lines().count(), 1, "{e}");
    e
}

#[test]
fn cli_fields_list_sets_the_order_and_refuses_duplicates_and_unknown_grids() {
    let dir = tempfile::tempdir().unwrap();
    let (layout, vel) = velocity();
    let lo = layout.lo.map(|v| v as i32);
    let hi = layout.hi.map(|v| v as i32);
    let a = scalar("a", vel.transform, lo, hi, linear);
    let b = scalar("b", vel.transform, lo, hi, |p| p[0]);
    let path = dir.path().join("f.vdb");
    write(
        &path,
        vec![AnyGrid::Vec3s(vel), AnyGrid::Float(a), AnyGrid::Float(b)],
    );
    let qbk = path.with_extension("qbk");

    let out = bake_cli(&path, &["--fields", "q,b,speed", "--json"]);
    assert!(out.status.success(), "{out:?}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let names: Vec<&str> = v["fields"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["q", "b", "speed"]);
    assert_eq!(v["nonfinite_derived"], 0);

    // Issue 12: the same field twice is refused (also through velocity_x), nothing written.
    std::fs::remove_file(&qbk).unwrap();
    for list in ["q,q,speed", "q,a,a", "velocity,speed,velocity"] {
        let e = error_line(&bake_cli(&path, &["--fields", list]));
        assert!(e.contains("is requested twice"), "{list}: {e}");
        assert!(!qbk.exists());
    }
    let e = error_line(&bake_cli(&path, &["--fields", "q,nope"]));
    assert!(
        e.contains("--fields: no scalar grid named \"nope\" (scalar grids: \"a\", \"b\")"),
        "{e}"
    );
    // Issue 12: two different scalar grids by --grid are not merged into one field "a".
    let e = error_line(&bake_cli(&path, &["--grid", "a", "--grid", "b"]));
    assert!(
        e.contains("--grid names several scalar grids (\"a\", \"b\")"),
        "{e}"
    );
    // One scalar grid alone still bakes as its own field.
    assert!(bake_cli(&path, &["--grid", "a"]).status.success());
}

/// Velocities near 1e38 are finite but give Q (and speed) beyond f32.
fn huge() -> Vec<AnyGrid> {
    let (_, mut vel) = velocity();
    for l in &mut vel.leaves {
        for (n, v) in l.values.iter_mut().enumerate() {
            let s = if (n ^ (n >> 3) ^ (n >> 6)) & 1 == 0 {
                1.0
            } else {
                -1.0
            };
            *v = [s * 3e38, -s * 3e38, s * 1e38];
        }
    }
    vec![AnyGrid::Vec3s(vel)]
}

#[test]
fn overflowing_q_and_speed_are_counted_warned_and_refused_when_strict() {
    let (file, summary) = bake(huge(), &BakeOptions::default()).unwrap();
    assert_eq!(summary.nonfinite, 0, "the input is finite");
    assert!(summary.nonfinite_derived > 0);
    assert!(
        summary
            .warnings
            .iter()
            .any(|w| w.contains("field \"q\"") && w.contains("not finite as 32-bit floats")),
        "{:?}",
        summary.warnings
    );
    // Every stored range is a true range of the stored values.
    for f in &file.fields {
        assert!(
            f.min.is_finite() && f.max.is_finite() && f.min <= f.max,
            "{}",
            f.name
        );
        assert!(
            f.values
                .iter()
                .all(|v| v.is_finite() && *v >= f.min && *v <= f.max),
            "{}",
            f.name
        );
        assert!(
            f.max > 1e38 || f.min < -1e38,
            "{}: {} {}",
            f.name,
            f.min,
            f.max
        );
    }
    for r in &file.region_ranges {
        assert!(r.min.is_finite() && r.max.is_finite() && r.min <= r.max);
    }
    let strict = BakeOptions {
        strict: true,
        ..BakeOptions::default()
    };
    let e = bake(huge(), &strict).unwrap_err();
    assert!(matches!(e, BakeError::NonFiniteDerived { .. }), "{e}");
    assert!(e.to_string().contains("refused because of --strict"), "{e}");
}
