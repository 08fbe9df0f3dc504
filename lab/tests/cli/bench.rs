//! `qbricks-lab bench` on the bundled sample at a tiny size: it runs, prints a JSON list
//! with every key for every strategy × step, and the plot is a PNG. Timings are never
//! asserted (the benchmark is not a test).

use crate::common::{qbricks_lab, qbricks_view, root};

const KEYS: [&str; 8] = [
    "strategy",
    "step",
    "ms",
    "samples_per_ray",
    "rmse",
    "psnr",
    "miss_rate",
    "false_hit_rate",
];

fn bench(extra: &[&str], plot: &std::path::Path) -> Vec<serde_json::Value> {
    let out = qbricks_lab()
        .current_dir(root())
        .args(["bench", "data/wake_small.qbk", "--json", "--size", "24x16"])
        .args([
            "--repeat",
            "1",
            "--threads",
            "1",
            "--reference-step",
            "0.05",
        ])
        .arg("--plot")
        .arg(plot)
        .args(extra)
        .output()
        .expect("run qbricks-lab bench");
    assert!(
        out.status.success(),
        "bench failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON");
    v.as_array().expect("a JSON list").clone()
}

#[test]
fn bench_prints_every_key_and_plots_a_png() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Dvr runs every strategy and step with and without pre-integrated opacity.
    for (mode, strategies, ways) in [
        ("iso", vec!["uniform", "paper", "bisect", "exact"], 1),
        ("dvr", vec!["uniform", "paper", "bisect"], 2),
    ] {
        let state = dir.path().join(format!("{mode}.json"));
        // A state in the wanted mode, saved by `render` (the bench reads states, not flags).
        let st = qbricks_view()
            .current_dir(root())
            .args([
                "render",
                "data/wake_small.qbk",
                "--pixel",
                "0,0",
                "--mode",
                mode,
            ])
            .arg("--save-state")
            .arg(&state)
            .output()
            .expect("run render");
        assert!(
            st.status.success(),
            "{}",
            String::from_utf8_lossy(&st.stderr)
        );
        let plot = dir.path().join(format!("{mode}.png"));
        let runs = bench(&["--state", state.to_str().expect("utf-8 path")], &plot);
        assert_eq!(runs.len(), strategies.len() * 5 * ways, "{mode}: runs");
        for run in &runs {
            for key in KEYS {
                assert!(run.get(key).is_some(), "{mode}: run without `{key}`: {run}");
            }
            assert_eq!(run["mode"], mode);
            let rmse = run["rmse"].as_f64().expect("rmse is a number");
            assert!((0.0..=1.0).contains(&rmse), "{run}");
            for k in ["miss_rate", "false_hit_rate"] {
                let r = run[k].as_f64().expect("rate is a number");
                assert!((0.0..=1.0).contains(&r), "{run}");
            }
        }
        let got: Vec<&str> = runs.iter().filter_map(|r| r["strategy"].as_str()).collect();
        for s in &strategies {
            assert_eq!(
                got.iter().filter(|g| *g == s).count(),
                5 * ways,
                "{mode}: {s}"
            );
        }
        assert!(runs.iter().any(|r| r["pareto"] == true));
        let pre = runs.iter().filter(|r| r["preintegrated"] == true).count();
        assert_eq!(pre, if ways == 2 { runs.len() / 2 } else { 0 }, "{mode}");
        let png = std::fs::read(&plot).expect("plot written");
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{mode}: plot is not a PNG");
        image::load_from_memory(&png).expect("plot decodes");
    }
}

#[test]
fn bench_bad_arguments_exit_2_with_one_line() {
    for args in [
        vec!["bench", "data/wake_small.qbk", "--size", "0x3"],
        vec!["bench", "data/wake_small.qbk", "--reference-step", "-1"],
        vec!["bench", "data/wake_small.qbk", "--repeat", "0"],
        vec!["bench", "/nonexistent/x.qbk"],
    ] {
        let out = qbricks_lab()
            .current_dir(root())
            .args(&args)
            .output()
            .expect("run bench");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    }
}
