//! The `qbricks-bake` commands from the command line: `--help`, `bake --json` against the
//! file it wrote, exit code 2 with a one-line message naming the file on bad input, and
//! the moved `synth` and `accuracy` (now `qbricks-lab`'s) saying where they went. (The hostile cases shared with
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
    for sub in ["inspect", "bake"] {
        assert!(text.contains(sub), "--help lacks {sub}:\n{text}");
    }
}

#[test]
fn bake_json_summary_matches_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("tiny.vdb");
    std::fs::copy(common::root().join("data/wake_small.vdb"), &vdb).expect("copy sample");

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
    assert_eq!(f.provenance.grids.len(), 3);
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
    std::fs::copy(common::root().join("data/wake_small.vdb"), &vdb).expect("copy sample");
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
fn moved_commands_exit_2_naming_qbricks_lab() {
    for sub in ["synth", "accuracy"] {
        let out = run(&[sub, "wake", "--n0", "16", "-o", "x.vdb"]);
        assert_eq!(out.status.code(), Some(2), "{sub}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{sub}: {err}");
        assert!(
            err.contains(&format!("moved: run `qbricks-lab {sub}")),
            "{sub}: {err}"
        );
    }
}
