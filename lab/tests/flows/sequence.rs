//! Frame sequences: `bake 'in_####.vdb' -o 'out_%04d.qbk'` bakes every frame that exists
//! (a missing and a corrupt frame in the middle), names the failure, exits 2, writes the
//! same bytes as single-file bakes, and a manifest with global field ranges.

use std::path::Path;

use crate::common::{qbricks_bake, qbricks_lab};
use format::BrickFileView;
use serde_json::Value;

fn run(args: &[&str], dir: &Path) -> std::process::Output {
    qbricks_bake().current_dir(dir).args(args).output().unwrap()
}

fn synth(dir: &Path, scene: &str, out: &str) {
    let o = qbricks_lab()
        .current_dir(dir)
        .args(["synth", scene, "--n0", "16", "-o", out])
        .output()
        .unwrap();
    assert!(o.status.success(), "{o:?}");
}

#[test]
fn sequence_with_a_gap_and_a_corrupt_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::create_dir(dir.join("cache")).unwrap();
    // Frames 1, 2 (corrupt), 4; frame 3 is missing.
    synth(dir, "lamb-oseen", "cache/fluid_data_0001.vdb");
    synth(dir, "burgers", "cache/fluid_data_0002.vdb");
    synth(dir, "burgers", "cache/fluid_data_0004.vdb");
    let bad = dir.join("cache/fluid_data_0002.vdb");
    let bytes = std::fs::read(&bad).unwrap();
    std::fs::write(&bad, &bytes[..bytes.len() / 2]).unwrap();
    // Not frames of the pattern.
    std::fs::write(dir.join("cache/fluid_data_01.vdb"), b"x").unwrap();
    std::fs::write(dir.join("cache/fluid_data_0005.vdb.bak"), b"x").unwrap();

    for (pattern, jobs) in [("out/frame_%04d.qbk", "2"), ("out1/frame_####.qbk", "1")] {
        let o = run(
            &[
                "bake",
                "cache/fluid_data_####.vdb",
                "-o",
                pattern,
                "--json",
                "--jobs",
                jobs,
            ],
            dir,
        );
        assert_eq!(o.status.code(), Some(2), "{o:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        let lines: Vec<&str> = err.lines().collect();
        assert!(
            lines
                .iter()
                .any(|l| l.starts_with("qbricks-bake: cache/fluid_data_0002.vdb: ")),
            "{err}"
        );
        assert!(
            lines
                .last()
                .unwrap()
                .contains("1 of 3 frames failed: cache/fluid_data_0002.vdb"),
            "{err}"
        );
        assert!(
            err.contains("1 frame(s) missing between 1 and 4: 3"),
            "{err}"
        );
        let summary: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(summary["frames"], 2);
        assert_eq!(summary["failed"], serde_json::json!([2]));
    }
    // Same bytes as single-file bakes, whatever the number of frames at once.
    for f in ["0001", "0004"] {
        let single = format!("single_{f}.qbk");
        let o = run(
            &[
                "bake",
                &format!("cache/fluid_data_{f}.vdb"),
                "-o",
                &single,
                "--quiet",
            ],
            dir,
        );
        assert!(o.status.success(), "{o:?}");
        let want = std::fs::read(dir.join(&single)).unwrap();
        assert_eq!(
            std::fs::read(dir.join(format!("out/frame_{f}.qbk"))).unwrap(),
            want
        );
        assert_eq!(
            std::fs::read(dir.join(format!("out1/frame_{f}.qbk"))).unwrap(),
            want
        );
    }
    assert!(!dir.join("out/frame_0002.qbk").exists());
    assert!(!dir.join("out/frame_0003.qbk").exists());

    // The manifest: frames, failure, gap, global ranges over the baked files.
    let m: Value =
        serde_json::from_slice(&std::fs::read(dir.join("out/frame_sequence.json")).unwrap())
            .unwrap();
    assert_eq!(m["input_pattern"], "cache/fluid_data_####.vdb");
    assert_eq!(m["output_pattern"], "out/frame_%04d.qbk");
    let frames: Vec<u64> = m["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["frame"].as_u64().unwrap())
        .collect();
    assert_eq!(frames, [1, 4]);
    assert_eq!(m["frames"][1]["output"], "out/frame_0004.qbk");
    assert_eq!(m["failed"][0]["frame"], 2);
    assert_eq!(m["failed"][0]["input"], "cache/fluid_data_0002.vdb");
    assert_eq!(m["missing"], serde_json::json!([3]));
    for (i, name) in ["q", "speed"].iter().enumerate() {
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for f in ["0001", "0004"] {
            let view = BrickFileView::open(&dir.join(format!("out/frame_{f}.qbk"))).unwrap();
            let field = view.file().fields.iter().find(|x| x.name == *name).unwrap();
            lo = lo.min(field.min.to_native());
            hi = hi.max(field.max.to_native());
        }
        assert_eq!(m["fields"][i]["name"], *name);
        assert_eq!(m["fields"][i]["min"].as_f64().unwrap() as f32, lo);
        assert_eq!(m["fields"][i]["max"].as_f64().unwrap() as f32, hi);
    }
    // The two scenes differ, so the global range is wider than frame 1's.
    assert_ne!(m["fields"][0]["min"], m["frames"][0]["fields"][0]["min"]);
}

#[test]
fn sequence_pattern_errors_exit_2_and_default_outputs_go_next_to_the_inputs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let o = run(&["bake", "none_####.vdb"], dir);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr)
        .contains("none_####.vdb: no file matches the frame pattern"));
    synth(dir, "abc", "f_01.vdb");
    let o = run(&["bake", "f_##.vdb", "-o", "single.qbk"], dir);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("the output must be one too"));
    // Without -o: next to the inputs.
    let o = run(&["bake", "f_##.vdb", "--quiet"], dir);
    assert!(o.status.success(), "{o:?}");
    assert!(dir.join("f_01.qbk").exists() && dir.join("f_sequence.json").exists());
}

/// A sequence bakes `--jobs` frames at once, each within its share of `--memory`: a share
/// too small for a frame is refused in the budget the user gave (the whole of it, how many
/// share it) and the least that would do is that share times the jobs. The advice works.
#[test]
fn a_share_of_the_memory_budget_too_small_names_the_whole_budget() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // Two frames whose bakes need about 9 MiB each even with every value on disk.
    let o = qbricks_lab()
        .current_dir(dir)
        .args([
            "synth",
            "wake",
            "--n0",
            "96",
            "--frames",
            "2",
            "-o",
            "w_####.vdb",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{o:?}");
    let o = run(
        &[
            "bake",
            "w_####.vdb",
            "-o",
            "a_####.qbk",
            "--jobs",
            "2",
            "--memory",
            "16M",
        ],
        dir,
    );
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("more than its share of the --memory budget: 8 MiB of 16 MiB, shared by 2 frames baked at once"),
        "{err}"
    );
    let least: u64 = err
        .split("give --memory ")
        .nth(1)
        .and_then(|s| s.split('M').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no advice in {err}"));
    assert!(least > 16 && least.is_multiple_of(2), "{err}");
    assert!(err.contains("or fewer --jobs"), "{err}");
    let advised = format!("{least}M");
    let o = run(
        &[
            "bake",
            "w_####.vdb",
            "-o",
            "b_####.qbk",
            "--jobs",
            "2",
            "--memory",
            &advised,
        ],
        dir,
    );
    assert!(o.status.success(), "{o:?}");
    assert!(dir.join("b_0001.qbk").exists() && dir.join("b_0002.qbk").exists());
    // Alone, a frame gets the whole budget: 16M does.
    let o = run(
        &["bake", "w_0001.vdb", "-o", "c.qbk", "--memory", "16M"],
        dir,
    );
    assert!(o.status.success(), "{o:?}");
}
