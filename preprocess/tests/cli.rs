//! The `qbricks-bake` commands from the command line: `--help`, `bake --json` against the
//! file it wrote, `synth` output and summary, `accuracy --json --plot`, and exit code 2
//! with a one-line message naming the file on bad input. (The hostile cases shared with
//! `qbricks-view` are the table in the root `tests/cross_crate/cli_cases.rs`.)

mod common;

use std::process::Output;

use common::qbricks_bake;
use format::BrickFileView;

fn run(args: &[&str]) -> Output {
    qbricks_bake()
        .args(args)
        .output()
        .expect("run qbricks-bake")
}

#[test]
fn help_lists_every_subcommand() {
    let out = run(&["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for sub in ["inspect", "synth", "bake"] {
        assert!(text.contains(sub), "--help lacks {sub}:\n{text}");
    }
}

#[test]
fn bake_json_summary_matches_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("tiny.vdb");
    let st = qbricks_bake()
        .args(["synth", "wake", "--n0", "16", "--levels", "2", "-o"])
        .arg(&vdb)
        .output()
        .expect("run synth");
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );

    let out = qbricks_bake()
        .arg("bake")
        .arg(&vdb)
        .args([
            "--json",
            "--fields",
            "q,speed,velocity",
            "--stencil",
            "cross-level",
        ])
        .output()
        .expect("run bake");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    let mut keys: Vec<&str> = v
        .as_object()
        .expect("object")
        .keys()
        .map(|k| k.as_str())
        .collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "bricks",
            "dropped_cells",
            "fields",
            "input_cells",
            "kd_nodes",
            "leaf_cells",
            "nonfinite",
            "nonfinite_derived",
            "output",
            "regions",
            "seconds"
        ]
    );
    let qbk = dir.path().join("tiny.qbk");
    assert_eq!(v["output"].as_str(), Some(qbk.to_str().expect("utf8")));
    let view = BrickFileView::open(&qbk).expect("open baked file");
    let f = view.file();
    assert_eq!(v["bricks"].as_u64(), Some(f.bricks.len() as u64));
    assert_eq!(v["regions"].as_u64(), Some(f.regions.len() as u64));
    assert_eq!(v["kd_nodes"].as_u64(), Some(f.kd_nodes.len() as u64));
    let leaf = v["leaf_cells"].as_u64().expect("leaf_cells");
    assert_eq!(leaf, f.fields[0].values.len() as u64);
    assert_eq!(
        v["input_cells"].as_u64(),
        Some(leaf + v["dropped_cells"].as_u64().expect("dropped"))
    );
    let names: Vec<&str> = v["fields"]
        .as_array()
        .expect("fields")
        .iter()
        .map(|f| f["name"].as_str().expect("name"))
        .collect();
    assert_eq!(
        names,
        ["q", "speed", "velocity_x", "velocity_y", "velocity_z"]
    );
    assert_eq!(f.provenance.source.as_str(), "tiny.vdb");
    assert_eq!(f.provenance.grids.len(), 2);
}

/// A missing input (`inspect`, `bake`), an output over the input and an unknown grid: one
/// line naming the file, exit code 2.
#[test]
fn bake_and_inspect_errors_are_one_line_naming_the_file_with_exit_2() {
    for sub in ["inspect", "bake"] {
        let out = run(&[sub, "/nonexistent/dir/flow.vdb"]);
        assert_eq!(out.status.code(), Some(2), "{sub}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{sub}: {err}");
        assert!(err.contains("/nonexistent/dir/flow.vdb"), "{sub}: {err}");
    }

    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("tiny.vdb");
    let st = qbricks_bake()
        .args(["synth", "wake", "--n0", "16", "--levels", "2", "-o"])
        .arg(&vdb)
        .output()
        .expect("run synth");
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    for args in [
        vec!["-o", vdb.to_str().expect("utf8")],
        vec!["--grid", "nope"],
    ] {
        let out = qbricks_bake()
            .arg("bake")
            .arg(&vdb)
            .args(&args)
            .output()
            .expect("run bake");
        assert_eq!(out.status.code(), Some(2));
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains("tiny.vdb"), "{err}");
    }
}

#[test]
fn synth_writes_a_file_and_reports_each_grid() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("w.vdb");
    let o = run(&[
        "synth",
        "wake",
        "-o",
        out.to_str().expect("utf-8 path"),
        "--n0",
        "16",
        "--levels",
        "2",
        "--float",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    for name in ["vel_l0", "vel_l1", "speed_l0", "speed_l1"] {
        assert!(text.contains(name), "{text}");
    }
    let size = std::fs::metadata(&out).expect("output").len();
    assert!(text.contains(&format!("{size} bytes")), "{text}");
}

#[test]
fn synth_bad_input_exits_2_with_one_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("x.vdb");
    let out = out.to_str().expect("utf-8 path");
    let missing_dir = dir.path().join("no/such/dir/x.vdb");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["synth", "vortex-street", "-o", out], "unknown scene"),
        (vec!["synth", "wake", "-o", out, "--n0", "1"], "n0"),
        (vec!["synth", "wake", "-o", out, "--levels", "0"], "levels"),
        (
            vec!["synth", "wake", "-o", out, "--n0", "4096", "--levels", "10"],
            "MiB of grid memory",
        ),
        (
            vec![
                "synth",
                "abc",
                "-o",
                missing_dir.to_str().expect("utf-8"),
                "--n0",
                "8",
            ],
            "no/such/dir",
        ),
    ];
    for (args, needle) in cases {
        let o = run(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    assert!(!std::path::Path::new(out).exists());
}

#[test]
fn accuracy_prints_every_key_and_plots_a_png() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plot = dir.path().join("acc.png");
    let out = qbricks_bake()
        .args([
            "accuracy", "wake", "--n0", "8", "16", "--points", "200", "--json",
        ])
        .arg("--plot")
        .arg(&plot)
        .output()
        .expect("run qbricks-bake accuracy");
    assert!(
        out.status.success(),
        "accuracy failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON");
    assert_eq!(v["scene"], "wake");
    let res = v["resolutions"].as_array().expect("resolutions");
    assert_eq!(res.len(), 2);
    let stats = ["points", "max", "rms", "max_rel", "rms_rel"];
    for r in res {
        for key in ["stored_q", "stored_speed", "reconstructed_q", "boundary_q"] {
            for s in stats {
                assert!(r[key][s].is_number(), "{key}.{s} missing: {r}");
            }
        }
        for key in ["position", "normal_deg"] {
            for st in stats {
                assert!(r["surface"][key][st].is_number(), "surface.{key}.{st}: {r}");
            }
        }
        for key in ["iso", "rays", "hits"] {
            assert!(r["surface"][key].is_number(), "surface.{key}: {r}");
        }
        // Three nested grids; at n0 8 a level can be covered entirely by the finer one,
        // so two or three levels keep cells. Points near the level boundaries exist.
        let levels = r["levels"].as_array().expect("levels").len();
        assert!((2..=3).contains(&levels), "{levels} levels");
        assert!(r["boundary_q"]["points"].as_u64() > Some(0));
    }
    let orders = v["orders"].as_array().expect("orders");
    assert_eq!(orders.len(), 1);
    for key in ["stored_q_rms", "stored_q_max", "reconstructed_q_rms"] {
        assert!(orders[0][key].is_number(), "{key}: {}", orders[0]);
    }
    // Null when a resolution has no surface hits (the n0-8 wake may have none).
    for key in ["surface_position_rms", "normal_angle_rms"] {
        assert!(orders[0].get(key).is_some(), "{key}: {}", orders[0]);
    }
    let png = std::fs::read(&plot).expect("plot written");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "plot is not a PNG");
    image::load_from_memory(&png).expect("plot decodes");

    let bad = qbricks_bake()
        .args(["accuracy", "nope", "--n0", "8"])
        .output()
        .expect("run accuracy");
    assert_eq!(bad.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&bad.stderr)
            .trim_end()
            .lines()
            .count(),
        1
    );
}
