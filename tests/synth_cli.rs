//! `qbricks-bake synth` as a command: output, summary, and exit code 2 with a one-line
//! message on bad input.

use std::process::{Command, Output};

mod util;

/// The `qbricks-bake` binary that `cargo test --workspace` built.
fn qbricks_bake() -> std::path::PathBuf {
    util::bin("qbricks-bake")
}

fn run(args: &[&str]) -> Output {
    Command::new(qbricks_bake())
        .args(args)
        .output()
        .expect("run qbricks-bake")
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
fn bad_input_exits_2_with_one_line() {
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
