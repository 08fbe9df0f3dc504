//! Vorticity magnitude and λ2 (`--fields vorticity,lambda2`) come from Q's gradient stencil,
//! with its cross-level treatment, so they converge at Q's (second) order against the
//! closed forms of Lamb–Oseen, Burgers and ABC, on one grid and across level boundaries
//! (the `-nested` scenes); and `qbricks-bake --fields q,lambda2,vorticity,helicity` writes
//! them with the ranges the flow has.
//!
//! Measure: `cargo test --release -p qbricks-lab --test flows measures:: -- --nocapture`

use crate::common::bake::{cells, field};
use crate::common::qbricks_bake;
use lab::analytic::{self, Exact};
use lab::synth::{scene_grids, write_scene, SynthOptions};
use qbricks_preprocess::bake::{bake, BakeOptions};
use qbricks_preprocess::derive::Stencil;
use qbricks_preprocess::fields::FieldKind;
use qbricks_preprocess::grid::AnyGrid;
use qbricks_preprocess::vdb::write::Compression;

/// The measures compared, by file field name, with their exact values.
type Pick = fn(&Exact) -> f64;
const MEASURES: [(&str, Pick); 3] = [
    ("q", |e| e.q),
    ("vorticity", |e| e.vorticity),
    ("lambda2", |e| e.lambda2),
];

/// RMS error of each of [`MEASURES`] over all leaf cells of `scene` baked at `n0`.
fn rms_errors(scene: &str, n0: u32, levels: u32, stencil: Stencil) -> [f64; 3] {
    let grids: Vec<AnyGrid> = scene_grids(scene, n0, levels)
        .expect("synth")
        .into_iter()
        .map(AnyGrid::Vec3s)
        .collect();
    let opts = BakeOptions {
        stencil,
        fields: Some(vec![FieldKind::Q, FieldKind::Vorticity, FieldKind::Lambda2]),
        ..BakeOptions::default()
    };
    let file = bake(grids, &opts).expect("bake").0;
    assert_eq!(file.levels.len() as u32, levels);
    let flow = analytic::scene(scene).expect("scene");
    MEASURES.map(|(name, exact)| {
        let cs = cells(&file, field(&file, name));
        let sum: f64 = cs
            .iter()
            .map(|c| (f64::from(c.value) - exact(&flow.exact(c.centre))).powi(2))
            .sum();
        (sum / cs.len() as f64).sqrt()
    })
}

/// Observed orders of [`MEASURES`] from n0 16 to 32, printed.
fn orders(scene: &str, levels: u32, stencil: Stencil) -> [f64; 3] {
    let (a, b) = (
        rms_errors(scene, 16, levels, stencil),
        rms_errors(scene, 32, levels, stencil),
    );
    let o = [0, 1, 2].map(|k| (a[k] / b[k]).log2());
    println!(
        "{scene:18} {stencil:?}: rms q {:.2e} → {:.2e} (order {:.2}), vorticity {:.2e} → {:.2e} ({:.2}), lambda2 {:.2e} → {:.2e} ({:.2})",
        a[0], b[0], o[0], a[1], b[1], o[1], a[2], b[2], o[2]
    );
    o
}

fn assert_like_q(scene: &str, o: [f64; 3]) {
    assert!(o[0] > 1.6, "{scene}: Q order {}", o[0]);
    for (k, name) in [(1, "vorticity"), (2, "lambda2")] {
        // At least Q's order (within the scatter of two resolutions).
        assert!(
            o[k] > 1.6 && o[k] > o[0] - 0.3,
            "{scene}: {name} order {} vs Q {}",
            o[k],
            o[0]
        );
    }
}

#[test]
fn vorticity_and_lambda2_converge_like_q_on_one_grid() {
    for scene in ["lamb-oseen", "burgers", "abc"] {
        assert_like_q(scene, orders(scene, 1, Stencil::Central));
    }
}

#[test]
fn vorticity_and_lambda2_converge_like_q_across_level_boundaries() {
    for scene in ["lamb-oseen-nested", "burgers-nested", "abc-nested"] {
        for stencil in [Stencil::Central, Stencil::CrossLevel] {
            assert_like_q(scene, orders(scene, 2, stencil));
        }
    }
}

#[test]
fn cli_bakes_the_vortex_measures_with_the_ranges_of_the_flow() {
    let dir = tempfile::tempdir().unwrap();
    let vdb = dir.path().join("burgers.vdb");
    let synth = SynthOptions {
        scene: "burgers".into(),
        n0: 32,
        levels: 1,
        compression: Compression::Zip,
        speed_grids: false,
        staggered: false,
        frame: 1,
        boxes: None,
    };
    write_scene(&vdb, &synth).unwrap();
    let qbk = dir.path().join("burgers.qbk");
    let bake = |fields: &str| {
        qbricks_bake()
            .arg("bake")
            .arg(&vdb)
            .arg("-o")
            .arg(&qbk)
            .args(["--quiet", "--json", "--fields", fields])
            .output()
            .unwrap()
    };
    let out = bake("q,lambda2,vorticity,helicity");
    assert!(out.status.success(), "{out:?}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let fields: Vec<(&str, f64, f64)> = v["fields"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f["name"].as_str().unwrap(),
                f["min"].as_f64().unwrap(),
                f["max"].as_f64().unwrap(),
            )
        })
        .collect();
    let names: Vec<&str> = fields.iter().map(|f| f.0).collect();
    assert_eq!(names, ["q", "lambda2", "vorticity", "helicity"]);
    assert_eq!(v["nonfinite_derived"], 0);
    // Each range as the flow has it over the leaf-cell centres ((i + ½) h, h = 2/32), up
    // to the stencil's error (a few per cent with 4 cells per core radius). Burgers
    // (ω₀ = 0.7, α = 0.2) has Q ≈ ω₀² − ¾α² = 0.46, λ2 ≈ α²/4 − ω₀² = −0.48 and |ω| ≈ 2ω₀
    // = 1.4 on its axis; the cells nearest the axis are h/√2 off it.
    let flow = analytic::scene("burgers").unwrap();
    let h = 2.0 / 32.0;
    let mut exact = [[f64::INFINITY, f64::NEG_INFINITY]; 4];
    for i in -16..16 {
        for j in -16..16 {
            for k in -16..16 {
                let p = [i, j, k].map(|c| (f64::from(c) + 0.5) * h);
                let e = flow.exact(p);
                for (r, v) in exact
                    .iter_mut()
                    .zip([e.q, e.lambda2, e.vorticity, e.helicity])
                {
                    *r = [r[0].min(v), r[1].max(v)];
                }
            }
        }
    }
    println!("baked {fields:?}\nexact {exact:?}");
    let near = |v: f64, want: f64| (v - want).abs() <= 0.1 * want.abs() + 1e-3;
    for ((name, lo, hi), want) in fields.iter().zip(exact) {
        assert!(
            near(*lo, want[0]) && near(*hi, want[1]),
            "{name}: baked {lo}..{hi}, exact {want:?}"
        );
    }
    assert!(exact[1][0] < -0.4 && exact[2][1] > 1.2, "{exact:?}");
    // The axial flow runs along ω above z = 0 and against it below.
    let (lo, hi) = (fields[3].1, fields[3].2);
    assert!(
        (-1.0..-0.9).contains(&lo) && hi <= 1.0 && hi > 0.9,
        "{lo} {hi}"
    );

    // An unknown name is still taken for a scalar grid the file lacks.
    let out = bake("q,lambda3");
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains("--fields: no scalar grid named \"lambda3\" (the file has no scalar grids)"),
        "{e}"
    );
}
