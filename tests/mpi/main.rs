//! Frame sequences over the ranks of an MPI run: `mpirun -np N qbricks-bake bake 'in_####'`
//! and `mpirun -np N qbricks-view render 'out_####'` share the frames out, every output is
//! written once and equals a run in one process, a broken frame is named and fails the run,
//! one file baked or one frame rendered over ranks equals one process's,
//! a command that runs in one process is refused, and no run hangs (each has a deadline).
//!
//! Needs `mpirun` (Open MPI) and the binaries built with the `mpi` feature:
//! `cargo build --release -p qbricks-preprocess -p qbricks-viewer --bins --features
//! qbricks-preprocess/mpi,qbricks-viewer/mpi`, then `cargo test --release --features mpi
//! --test mpi` (`.ci/run` does both).

#![allow(clippy::unwrap_used)]

#[path = "../common/mod.rs"]
mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{bin, root};

/// Longest an `mpirun` may take before the test calls it hung.
const DEADLINE: Duration = Duration::from_secs(120);

/// Runs `args` in `dir` under `mpirun -np ranks` (`ranks` 0: without mpirun), within the
/// deadline; a run past it is killed and fails the test.
fn run(dir: &Path, ranks: usize, args: &[&str]) -> Output {
    run_with(dir, ranks, args, &[])
}

/// [`run`] with environment variables `env` set for every rank.
fn run_with(dir: &Path, ranks: usize, args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut cmd = match ranks {
        0 => Command::new(args[0]),
        n => {
            let mut c = Command::new("mpirun");
            c.args(["-np", &n.to_string(), "--oversubscribe"]);
            for (k, _) in env {
                c.args(["-x", k]);
            }
            c.args(&args[..1]);
            c
        }
    };
    cmd.envs(env.iter().copied());
    cmd.args(&args[1..])
        .current_dir(dir)
        // Open MPI refuses to run as root without these (CI containers run as root).
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut child = cmd.spawn().expect("mpirun (apt-get install openmpi-bin)");
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if start.elapsed() > DEADLINE {
            let _ = child.kill();
            panic!("{args:?} over {ranks} ranks hung: killed after {DEADLINE:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn exe(name: &str) -> String {
    bin(name).display().to_string()
}

/// A sequence of `n` frames in `dir/cache`: links to the bundled sample.
fn frames(dir: &Path, n: usize) {
    std::fs::create_dir_all(dir.join("cache")).unwrap();
    for i in 1..=n {
        std::os::unix::fs::symlink(
            root().join("data/wake_small.vdb"),
            dir.join(format!("cache/f_{i:04}.vdb")),
        )
        .unwrap();
    }
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    v.sort();
    v
}

/// The manifest's frames, with paths made relative to nothing (only the numbers, cells
/// and ranges): what must not depend on how many ranks baked them.
fn manifest_frames(path: &Path) -> serde_json::Value {
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    for f in m["frames"].as_array_mut().unwrap() {
        f.as_object_mut().unwrap().remove("output");
    }
    serde_json::json!([m["frames"], m["fields"], m["failed"], m["missing"]])
}

#[test]
fn bake_sequence_over_ranks_equals_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    frames(d, 5);
    let bake = exe("qbricks-bake");
    let one = run(
        d,
        0,
        &[&bake, "bake", "cache/f_####.vdb", "-o", "one/f_####.qbk"],
    );
    assert!(one.status.success(), "{}", text(&one.stderr));
    for ranks in [2, 3] {
        let out = format!("r{ranks}/f_####.qbk");
        let o = run(
            d,
            ranks,
            &[
                &bake,
                "bake",
                "cache/f_####.vdb",
                "-o",
                &out,
                "--progress",
                "--json",
            ],
        );
        let err = text(&o.stderr);
        assert!(o.status.success(), "{err}");
        // Every rank took frames (a binary without MPI would be N single runs).
        for r in 0..ranks {
            assert!(
                err.contains(&format!("rank {r} of {ranks}: ")),
                "rank {r} of {ranks} not heard from (built without the mpi feature?): {err}"
            );
        }
        // One report, from rank 0.
        let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(report["frames"], 5);
        let dir_n = d.join(format!("r{ranks}"));
        let written = files_in(&dir_n);
        assert_eq!(written.len(), 6, "{written:?}");
        for i in 1..=5 {
            let name = format!("f_{i:04}.qbk");
            assert_eq!(
                std::fs::read(dir_n.join(&name)).unwrap(),
                std::fs::read(d.join("one").join(&name)).unwrap(),
                "{name} over {ranks} ranks"
            );
        }
        assert_eq!(
            manifest_frames(&dir_n.join("f_sequence.json")),
            manifest_frames(&d.join("one/f_sequence.json"))
        );
    }
}

#[test]
fn render_sequence_over_ranks_equals_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    frames(d, 4);
    let (bake, view) = (exe("qbricks-bake"), exe("qbricks-view"));
    let o = run(
        d,
        0,
        &[&bake, "bake", "cache/f_####.vdb", "-o", "q/f_####.qbk"],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let args = |out: &'static str| -> Vec<String> {
        [
            &view,
            "render",
            "q/f_####.qbk",
            "-o",
            out,
            "--width",
            "64",
            "--height",
            "48",
            "--json",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let strs = |v: &[String]| v.to_vec();
    let one_args = strs(&args("one/f_####.png"));
    let one = run(
        d,
        0,
        &one_args.iter().map(String::as_str).collect::<Vec<_>>(),
    );
    assert!(one.status.success(), "{}", text(&one.stderr));
    let frames_of = |stdout: &[u8]| -> Vec<u64> {
        text(stdout)
            .lines()
            .map(|l| {
                serde_json::from_str::<serde_json::Value>(l).unwrap()["frame"]
                    .as_u64()
                    .unwrap()
            })
            .collect()
    };
    for (ranks, out) in [(2, "r2/f_####.png"), (3, "r3/f_####.png")] {
        let a = strs(&args(out));
        let o = run(d, ranks, &a.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(o.status.success(), "{}", text(&o.stderr));
        // Rank 0 reports every frame once, in order.
        assert_eq!(frames_of(&o.stdout), vec![1, 2, 3, 4]);
        let dir_n = d.join(out.split('/').next().unwrap());
        assert_eq!(files_in(&dir_n).len(), 4);
        for i in 1..=4 {
            let name = format!("f_{i:04}.png");
            assert_eq!(
                std::fs::read(dir_n.join(&name)).unwrap(),
                std::fs::read(d.join("one").join(&name)).unwrap(),
                "{name} over {ranks} ranks"
            );
        }
    }
    assert_eq!(frames_of(&one.stdout), vec![1, 2, 3, 4]);
}

#[test]
fn a_broken_frame_is_named_and_fails_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    frames(d, 3);
    std::fs::write(d.join("cache/f_0004.vdb"), b"not a vdb").unwrap();
    let (bake, view) = (exe("qbricks-bake"), exe("qbricks-view"));
    let o = run(
        d,
        2,
        &[&bake, "bake", "cache/f_####.vdb", "-o", "q/f_####.qbk"],
    );
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("cache/f_0004.vdb: file header"), "{err}");
    assert!(
        err.contains("1 of 4 frames failed: cache/f_0004.vdb"),
        "{err}"
    );
    assert_eq!(
        files_in(&d.join("q")).len(),
        4,
        "three frames and the manifest"
    );
    // The viewer skips the failed frame the manifest lists; a frame truncated since is
    // named by the rank that rendered it.
    let q2 = d.join("q/f_0002.qbk");
    let bytes = std::fs::read(&q2).unwrap();
    std::fs::write(&q2, &bytes[..bytes.len() / 2]).unwrap();
    let o = run(
        d,
        2,
        &[
            &view,
            "render",
            "q/f_####.qbk",
            "-o",
            "png/f_####.png",
            "--width",
            "32",
            "--height",
            "24",
        ],
    );
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("q/f_0002.qbk: file length does not match its header"),
        "{err}"
    );
    assert!(err.contains("1 of 3 frames failed: q/f_0002.qbk"), "{err}");
    let pngs: Vec<String> = files_in(&d.join("png"))
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(pngs, ["f_0001.png", "f_0003.png"]);
}

/// One file baked over 2 and 3 ranks (each deriving its share of the fields, rank 0
/// writing the file) is the file one process bakes, byte for byte, with one report from
/// rank 0 that counts the ranks; a broken input fails the run with exit 2 naming the file,
/// writes nothing and does not hang.
#[test]
fn one_file_baked_over_ranks_equals_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bake = exe("qbricks-bake");
    let sample = root().join("data/wake_small.vdb").display().to_string();
    let one = run(d, 0, &[&bake, "bake", &sample, "-o", "one.qbk", "--quiet"]);
    assert!(one.status.success(), "{}", text(&one.stderr));
    let want = std::fs::read(d.join("one.qbk")).unwrap();
    for ranks in [2, 3] {
        let out = format!("r{ranks}.qbk");
        let o = run(d, ranks, &[&bake, "bake", &sample, "-o", &out, "--json"]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        assert!(
            std::fs::read(d.join(&out)).unwrap() == want,
            "{ranks} ranks: not the file one process bakes"
        );
        let report: serde_json::Value = serde_json::from_slice(&o.stdout)
            .unwrap_or_else(|e| panic!("one JSON report ({e}): {}", text(&o.stdout)));
        assert_eq!(
            report["ranks"], ranks,
            "built without the mpi feature? {report}"
        );
    }
    // Every message in pieces of a few kB (as messages past MPI's 2 GiB go): the same file.
    let o = run_with(
        d,
        3,
        &[&bake, "bake", &sample, "-o", "pieces.qbk", "--quiet"],
        &[("QBRICKS_MPI_PIECE", "3000")],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(std::fs::read(d.join("pieces.qbk")).unwrap() == want);
    std::fs::write(d.join("broken.vdb"), b"not a vdb").unwrap();
    let o = run(d, 2, &[&bake, "bake", "broken.vdb", "-o", "broken.qbk"]);
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("broken.vdb: file header"), "{err}");
    assert!(!d.join("broken.qbk").exists());
}

/// One frame over 2 and 3 ranks (each rank searching its share of the file's KD-tree,
/// rank 0 compositing) gives the PNG one process gives, byte for byte, with and without the
/// sphere and its shadows; each rank reads fewer than 75 % of the bricks.
#[test]
fn one_frame_over_ranks_equals_one_process_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sample = root().join("data/wake_small.qbk").display().to_string();
    let sphere = root().join("data/sphere.obj").display().to_string();
    let view = exe("qbricks-view");
    let size = ["--width", "160", "--height", "120"];
    for (case, extra) in [
        ("plain", vec![]),
        ("sphere and shadows", vec!["--mesh", &sphere, "--shadows"]),
    ] {
        let mut one: Vec<&str> = vec![&view, "render", &sample, "-o", "one.png"];
        one.extend(size);
        one.extend(extra.iter().copied());
        let o = run(d, 0, &one);
        assert!(o.status.success(), "{case}: {}", text(&o.stderr));
        let want = std::fs::read(d.join("one.png")).unwrap();
        for n in [2, 3] {
            let out = format!("np{n}.png");
            let mut args: Vec<&str> = vec![&view, "render", &sample, "-o", &out, "--json"];
            args.extend(size);
            args.extend(extra.iter().copied());
            let o = run(d, n, &args);
            assert!(o.status.success(), "{case}, {n} ranks: {}", text(&o.stderr));
            assert!(
                std::fs::read(d.join(&out)).unwrap() == want,
                "{case}: the PNG of {n} ranks differs from one process's"
            );
            let report: serde_json::Value = serde_json::from_slice(&o.stdout)
                .unwrap_or_else(|e| panic!("{case}: one JSON report ({e}): {}", text(&o.stdout)));
            let bricks = report["bricks"].as_u64().unwrap();
            let ranks = report["ranks"].as_array().unwrap();
            assert_eq!(ranks.len(), n, "{report}");
            for (i, r) in ranks.iter().enumerate() {
                assert_eq!(r["rank"].as_u64(), Some(i as u64));
                let touched = r["bricks_touched"].as_u64().unwrap();
                assert!(r["ms"].as_f64().unwrap() > 0.0 && r["composite_ms"].as_f64().is_some());
                if n == 2 {
                    assert!(
                        (touched as f64) < 0.75 * bricks as f64,
                        "{case}: rank {i} read {touched} of {bricks} bricks"
                    );
                }
            }
            // Both ranks search: the cut balances what the view's surface costs.
            assert!(
                ranks
                    .iter()
                    .all(|r| r["stats"]["samples"].as_u64().unwrap() > 0),
                "{case}: {report}"
            );
        }
        // Every message (crossings, shadow rays and their answers) in pieces of a few
        // hundred bytes, as messages past MPI's 2 GiB go: the same PNG.
        let mut args: Vec<&str> = vec![&view, "render", &sample, "-o", "pieces.png"];
        args.extend(size);
        args.extend(extra.iter().copied());
        let o = run_with(d, 3, &args, &[("QBRICKS_MPI_PIECE", "700")]);
        assert!(o.status.success(), "{case}, pieces: {}", text(&o.stderr));
        assert!(
            std::fs::read(d.join("pieces.png")).unwrap() == want,
            "{case}: the PNG sent in pieces differs"
        );
    }
}

/// Dvr over 2 and 3 ranks: every channel of the PNG within one 8-bit level of one
/// process's (each rank ends its rays' runs on its own opacity, not the whole ray's).
#[test]
fn dvr_over_ranks_is_within_one_level_of_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sample = root().join("data/wake_small.qbk").display().to_string();
    let sphere = root().join("data/sphere.obj").display().to_string();
    let view = exe("qbricks-view");
    let flags = [
        "--mode", "dvr", "--mesh", &sphere, "--width", "160", "--height", "120",
    ];
    let mut one: Vec<&str> = vec![&view, "render", &sample, "-o", "one.png"];
    one.extend(flags);
    let o = run(d, 0, &one);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let want = image::open(d.join("one.png")).unwrap().to_rgb8();
    for n in [2, 3] {
        let out = format!("np{n}.png");
        let mut args: Vec<&str> = vec![&view, "render", &sample, "-o", &out];
        args.extend(flags);
        let o = run(d, n, &args);
        assert!(o.status.success(), "{n} ranks: {}", text(&o.stderr));
        let got = image::open(d.join(&out)).unwrap().to_rgb8();
        assert_eq!(got.dimensions(), want.dimensions());
        let worst = got
            .as_raw()
            .iter()
            .zip(want.as_raw())
            .map(|(a, b)| (i32::from(*a) - i32::from(*b)).abs())
            .max()
            .unwrap();
        assert!(
            worst <= 1,
            "{n} ranks: a channel {worst} levels from one process's"
        );
    }
}

/// What one frame over ranks cannot render alike is refused by rank 0 with the reason,
/// and nothing is written; without mpirun the same binary renders it.
#[test]
fn views_one_frame_over_ranks_cannot_render_are_refused_and_run_alone() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sample = root().join("data/wake_small.qbk").display().to_string();
    let view = exe("qbricks-view");
    for (flags, says) in [
        (vec!["--mode", "dvr", "--shadows"], "dvr with shadows"),
        (
            vec!["--pixel", "3,3"],
            "--pixel (one ray, explained) runs in one process",
        ),
    ] {
        let mut args: Vec<&str> = vec![&view, "render", &sample, "-o", "one.png"];
        args.extend(flags.iter().copied());
        let o = run(d, 2, &args);
        let err = text(&o.stderr);
        assert!(!o.status.success(), "{flags:?}");
        assert!(err.contains(says), "{flags:?}: {err}");
        // Said once, by rank 0.
        assert_eq!(err.matches(says).count(), 1, "{err}");
        assert!(!d.join("one.png").exists());
    }
    // A file that is not there: every rank stops, the run fails, nothing hangs.
    let o = run(d, 2, &[&view, "render", "missing.qbk", "-o", "one.png"]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("missing.qbk"),
        "{}",
        text(&o.stderr)
    );
    // Without mpirun the same binary renders dvr as always.
    let o = run(
        d,
        0,
        &[
            &view, "render", &sample, "-o", "one.png", "--width", "32", "--height", "24", "--mode",
            "dvr",
        ],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(d.join("one.png").exists());
}
