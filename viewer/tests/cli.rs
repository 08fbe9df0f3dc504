//! The `qbricks-view` binary itself. Declaring this integration test also makes
//! `cargo test --workspace` build the binary that the end-to-end tests in `tests/` run.

use std::process::Command;

fn qbricks_view() -> Command {
    Command::new(env!("CARGO_BIN_EXE_qbricks-view"))
}

#[test]
fn help_lists_every_subcommand() {
    let out = qbricks_view()
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
fn missing_file_is_one_line_naming_the_file_with_exit_2() {
    let out = qbricks_view()
        .args(["info", "/nonexistent/dir/scene.qbk"])
        .output()
        .expect("run qbricks-view");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("/nonexistent/dir/scene.qbk"), "{err}");
}
