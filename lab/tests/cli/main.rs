//! The `qbricks-lab` commands from the command line, one test binary: `--help` here,
//! `synth` and `accuracy` (`synth_accuracy`), `bench` (`bench`). The hostile cases shared
//! with the other programs are the table in the root `tests/cross_crate/cli_cases.rs`.

extern crate preprocess as qbricks_preprocess;

#[path = "../common/mod.rs"]
mod common;

mod bench;
mod synth_accuracy;

#[test]
fn help_lists_every_subcommand() {
    let out = common::qbricks_lab()
        .arg("--help")
        .output()
        .expect("run qbricks-lab");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for sub in ["synth", "accuracy", "bench"] {
        assert!(text.contains(sub), "--help lacks {sub}:\n{text}");
    }
}
