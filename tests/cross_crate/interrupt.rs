//! Ctrl-C (SIGINT) or SIGTERM in the middle of writing an output leaves no temporary file.
//!
//! Each program writes its output to a FIFO that nobody reads: the output goes to a hidden
//! temporary file first (in `TMPDIR`, here the case's directory, since a FIFO's own
//! directory is no place for it) and is copied into the FIFO only once complete, so the
//! process stops with its temporary file on disk, blocked opening the FIFO — a
//! deterministic "mid-write" moment. The test waits for the temporary file, sends the signal, and checks
//! that the process died of that signal and the temporary file is gone.
#![cfg(unix)]

use crate::common;
use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .expect("read dir")
        .filter_map(|e| {
            let name = e.ok()?.file_name().to_string_lossy().into_owned();
            (name.starts_with(".out") && name.ends_with(".tmp")).then_some(name)
        })
        .collect()
}

/// Runs `program args` (with `out.fifo` as its output) in a fresh directory, sends `signal`
/// once its temporary file exists, and checks the outcome.
fn interrupt(program: &str, args: &[&str], signal: (&str, i32)) {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::copy(
        common::root().join("data/wake_small.vdb"),
        dir.path().join("w.vdb"),
    )
    .expect("copy vdb");
    std::fs::copy(
        common::root().join("data/wake_small.qbk"),
        dir.path().join("w.qbk"),
    )
    .expect("copy qbk");
    let fifo = dir.path().join("out.fifo");
    let st = Command::new("mkfifo").arg(&fifo).status().expect("mkfifo");
    assert!(st.success(), "mkfifo failed");

    let mut child = Command::new(common::bin(program))
        .args(args)
        .current_dir(dir.path())
        .env("TMPDIR", dir.path())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let start = Instant::now();
    let shown = format!("{program} {}", args.join(" "));
    while temp_files(dir.path()).is_empty() {
        if let Some(status) = child.try_wait().expect("wait") {
            panic!("{shown}: ended ({status}) before its temporary file was seen");
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "{shown}: no temporary file after 60 s"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let st = Command::new("kill")
        .args([format!("-{}", signal.0), child.id().to_string()])
        .status()
        .expect("kill");
    assert!(st.success(), "kill failed");
    let status = child.wait().expect("wait");
    assert_eq!(
        status.signal(),
        Some(signal.1),
        "{shown}: expected death by SIG{}, got {status}",
        signal.0
    );
    assert_eq!(
        temp_files(dir.path()),
        Vec::<String>::new(),
        "{shown}: temporary files left after SIG{}",
        signal.0
    );
}

#[test]
fn sigint_during_bake_removes_the_temporary_file() {
    interrupt(
        "qbricks-bake",
        &["bake", "w.vdb", "-o", "out.fifo", "--quiet"],
        ("INT", 2),
    );
}

#[test]
fn sigterm_during_synth_removes_the_temporary_file() {
    interrupt(
        "qbricks-lab",
        &[
            "synth", "wake", "--n0", "16", "--levels", "2", "-o", "out.fifo",
        ],
        ("TERM", 15),
    );
}

#[test]
fn sigint_during_render_removes_the_temporary_file() {
    interrupt(
        "qbricks-view",
        &[
            "render", "w.qbk", "-o", "out.fifo", "--width", "16", "--height", "12",
        ],
        ("INT", 2),
    );
}

/// With a reader on the FIFO, the output goes through it whole (and the FIFO stays a FIFO).
#[test]
fn fifo_output_is_written_into() {
    use std::io::Read;
    use std::os::unix::fs::FileTypeExt;
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("wake_small.vdb");
    std::fs::copy(common::root().join("data/wake_small.vdb"), &vdb).expect("copy vdb");
    let fifo = dir.path().join("out.fifo");
    let st = Command::new("mkfifo").arg(&fifo).status().expect("mkfifo");
    assert!(st.success(), "mkfifo failed");
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            std::fs::File::open(&fifo)
                .expect("open fifo")
                .read_to_end(&mut bytes)
                .expect("read fifo");
            bytes
        })
    };
    let out = Command::new(common::bin("qbricks-bake"))
        .args(["bake", "wake_small.vdb", "-o", "out.fifo", "--quiet"])
        .current_dir(dir.path())
        .output()
        .expect("bake");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bytes = reader.join().expect("reader");
    let want = std::fs::read(common::root().join("data/wake_small.qbk")).expect("sample");
    assert!(
        bytes == want,
        "the FIFO carried {} bytes, not the sample's {}",
        bytes.len(),
        want.len()
    );
    assert!(std::fs::metadata(&fifo)
        .expect("fifo")
        .file_type()
        .is_fifo());
    assert_eq!(temp_files(dir.path()), Vec::<String>::new());
}
