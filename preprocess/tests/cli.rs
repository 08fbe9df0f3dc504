//! The `qbricks-bake` binary itself. Declaring this integration test also makes
//! `cargo test --workspace` build the binary that the end-to-end tests in `tests/` run.

use std::process::Command;

fn qbricks_bake() -> Command {
    Command::new(env!("CARGO_BIN_EXE_qbricks-bake"))
}

#[test]
fn help_lists_every_subcommand() {
    let out = qbricks_bake()
        .arg("--help")
        .output()
        .expect("run qbricks-bake");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for sub in ["inspect", "synth", "bake"] {
        assert!(text.contains(sub), "--help lacks {sub}:\n{text}");
    }
}

#[test]
fn missing_input_is_one_line_naming_the_file_with_exit_2() {
    for sub in ["inspect", "bake"] {
        let out = qbricks_bake()
            .args([sub, "/nonexistent/dir/flow.vdb"])
            .output()
            .expect("run qbricks-bake");
        assert_eq!(out.status.code(), Some(2), "{sub}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{sub}: {err}");
        assert!(err.contains("/nonexistent/dir/flow.vdb"), "{sub}: {err}");
    }
}
