//! The `qbricks-view` commands from the command line, one test binary: `--help` here,
//! `render` and `probe` (`render_probe`), `info` (`info`), `bench` (`bench`). The hostile
//! cases shared with `qbricks-bake` are the table in the root
//! `tests/cross_crate/cli_cases.rs`.

#[path = "../common/mod.rs"]
mod common;

mod bench;
mod info;
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
