//! The `qbricks-view` commands from the command line, one test binary: `--help` here,
//! `render` and `probe` (`render_probe`), `probe --plane` (`probe_plane`), `info` (`info`);
//! `bench` moved to `qbricks-lab`. The hostile
//! cases shared with `qbricks-bake` are the table in the root
//! `tests/cross_crate/cli_cases.rs`.

#[path = "../common/mod.rs"]
mod common;

mod info;
mod probe_plane;
mod render_probe;

#[test]
fn help_lists_every_subcommand() {
    let out = common::qbricks_view()
        .arg("--help")
        .output()
        .expect("run qbricks-view");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for sub in ["info", "render", "probe"] {
        assert!(text.contains(sub), "--help lacks {sub}:\n{text}");
    }
}

#[test]
fn bench_moved_to_qbricks_lab_exits_2() {
    let out = common::qbricks_view()
        .args(["bench", "data/wake_small.qbk", "--json"])
        .output()
        .expect("run qbricks-view");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("moved: run `qbricks-lab bench"), "{err}");
}
