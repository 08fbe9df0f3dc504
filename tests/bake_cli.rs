//! `qbricks-bake bake` end to end: synth a tiny VDB, bake it, open the result.

mod util;

use std::process::Command;

use format::BrickFileView;

/// The binary is built by `cargo test --workspace`; a lone `cargo test --test bake_cli`
/// needs `cargo build [--release] -p qbricks-preprocess` first.
fn qbricks_bake() -> Command {
    Command::new(util::bin("qbricks-bake"))
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

    // Refuses to overwrite its input; unknown grid: one line, exit code 2.
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
