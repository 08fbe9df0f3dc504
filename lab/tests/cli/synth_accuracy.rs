//! `qbricks-lab synth` output and summary, `accuracy --json --plot`, and exit code 2 with a
//! one-line message on bad input.

use std::process::Output;

use crate::common::{peak_memory, qbricks_lab};

fn run(args: &[&str]) -> Output {
    qbricks_lab().args(args).output().expect("run qbricks-lab")
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
fn synth_bad_input_exits_2_with_one_line() {
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
            "GiB, more than the limit of 1024 GiB",
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

/// A small layout: `docs/bench/layouts/independent.json` with cells 8× wider.
const SMALL_LAYOUT: &str = r#"{"boxes": [
    {"cell": 0.5,   "min": [-2, -2, -2],          "max": [6, 2, 2]},
    {"cell": 0.25,  "min": [-1, -1.25, -1.25],    "max": [4, 1.25, 1.25]},
    {"cell": 0.125, "min": [-0.75, -0.75, -0.75], "max": [2, 0.75, 0.75]}]}"#;

#[test]
fn synth_on_a_layout_writes_its_boxes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let layout = dir.path().join("small.json");
    std::fs::write(&layout, SMALL_LAYOUT).expect("layout");
    let out = dir.path().join("b.vdb");
    let o = run(&[
        "synth",
        "wake",
        "--boxes",
        layout.to_str().expect("utf-8 path"),
        "-o",
        out.to_str().expect("utf-8 path"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    // Finest first: 22×12×12, 20×10×10 and 16×8×8 cells.
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 4, "{text}");
    for (line, (name, cells)) in lines.iter().zip([
        ("vel_l0", 22 * 12 * 12),
        ("vel_l1", 20 * 10 * 10),
        ("vel_l2", 16 * 8 * 8),
    ]) {
        assert!(line.starts_with(name), "{text}");
        assert!(
            line.contains(&format!("active voxels {cells:>10}")),
            "{text}"
        );
    }
    assert!(out.exists());
}

#[test]
fn synth_bad_layouts_exit_2_with_one_line_naming_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("x.vdb");
    let out = out.to_str().expect("utf-8 path");
    let file = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).expect("layout");
        p.to_str().expect("utf-8 path").to_string()
    };
    let off = file("off.json", &SMALL_LAYOUT.replace("[4, 1.25", "[4.1, 1.25"));
    let nest = file("nest.json", &SMALL_LAYOUT.replace("[2, 0.75", "[4.5, 0.75"));
    let json = file("json.json", "{\"boxes\": [");
    let missing = dir.path().join("none.json");
    let missing = missing.to_str().expect("utf-8 path");
    let cases: Vec<(Vec<&str>, String)> = vec![
        (
            vec!["synth", "wake", "--boxes", &off, "-o", out],
            format!("qbricks-lab: {off}: boxes[1]: x max 4.1 does not lie on the box's cells"),
        ),
        (
            vec!["synth", "wake", "--boxes", &nest, "-o", out],
            format!("qbricks-lab: {nest}: boxes[2]: x max 4.5 is outside boxes[1]"),
        ),
        (
            vec!["synth", "wake", "--boxes", &json, "-o", out],
            format!("qbricks-lab: {json}: not a box layout: EOF while parsing"),
        ),
        (
            vec!["synth", "wake", "--boxes", missing, "-o", out],
            format!("qbricks-lab: {missing}: "),
        ),
        (
            vec!["synth", "nope", "--boxes", &nest, "-o", out],
            format!("qbricks-lab: {nest}: boxes[2]"),
        ),
        (
            vec!["synth", "wake", "--boxes", &off, "-o", &off],
            "qbricks-lab: ".to_string(),
        ),
    ];
    for (args, start) in cases {
        let o = run(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(
            err.starts_with(&start),
            "{args:?}: {err}\nexpected: {start}"
        );
    }
    // The layout file named as the output is refused before anything is written.
    assert_eq!(
        std::fs::read_to_string(&off).expect("layout kept"),
        SMALL_LAYOUT.replace("[4, 1.25", "[4.1, 1.25")
    );
    assert!(!std::path::Path::new(out).exists());
    // A good layout of an unknown scene names the scene.
    let good = file("good.json", SMALL_LAYOUT);
    let o = run(&["synth", "vortex-street", "--boxes", &good, "-o", out]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("unknown scene \"vortex-street\""), "{err}");
    // A layout replaces --n0 and --levels: giving both is a usage error.
    let o = run(&["synth", "wake", "--boxes", &good, "--n0", "16", "-o", out]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("cannot be used with"), "{err}");
}

#[test]
fn accuracy_prints_every_key_and_plots_a_png() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plot = dir.path().join("acc.png");
    let out = qbricks_lab()
        .args([
            "accuracy", "wake", "--n0", "8", "16", "--points", "200", "--json",
        ])
        .arg("--plot")
        .arg(&plot)
        .output()
        .expect("run qbricks-lab accuracy");
    assert!(
        out.status.success(),
        "accuracy failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON");
    assert_eq!(v["scene"], "wake");
    let res = v["resolutions"].as_array().expect("resolutions");
    assert_eq!(res.len(), 2);
    let stats = ["points", "max", "rms", "max_rel", "rms_rel"];
    for r in res {
        for key in [
            "stored_q",
            "stored_speed",
            "reconstructed_q",
            "boundary_q",
            "stored_vorticity",
            "stored_lambda2",
            "reconstructed_vorticity",
            "reconstructed_lambda2",
            "boundary_vorticity",
            "boundary_lambda2",
        ] {
            for s in stats {
                assert!(r[key][s].is_number(), "{key}.{s} missing: {r}");
            }
        }
        for key in ["position", "normal_deg"] {
            for st in stats {
                assert!(r["surface"][key][st].is_number(), "surface.{key}.{st}: {r}");
            }
        }
        for key in ["iso", "rays", "hits"] {
            assert!(r["surface"][key].is_number(), "surface.{key}: {r}");
        }
        // Three nested grids; at n0 8 a level can be covered entirely by the finer one,
        // so two or three levels keep cells. Points near the level boundaries exist.
        let levels = r["levels"].as_array().expect("levels").len();
        assert!((2..=3).contains(&levels), "{levels} levels");
        assert!(r["boundary_q"]["points"].as_u64() > Some(0));
    }
    let orders = v["orders"].as_array().expect("orders");
    assert_eq!(orders.len(), 1);
    for key in [
        "stored_q_rms",
        "stored_q_max",
        "reconstructed_q_rms",
        "stored_vorticity_rms",
        "stored_lambda2_rms",
        "stored_lambda2_max",
        "boundary_lambda2_rms",
    ] {
        assert!(orders[0][key].is_number(), "{key}: {}", orders[0]);
    }
    // Null when a resolution has no surface hits (the n0-8 wake may have none).
    for key in ["surface_position_rms", "normal_angle_rms"] {
        assert!(orders[0].get(key).is_some(), "{key}: {}", orders[0]);
    }
    let png = std::fs::read(&plot).expect("plot written");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "plot is not a PNG");
    image::load_from_memory(&png).expect("plot decodes");

    let bad = qbricks_lab()
        .args(["accuracy", "nope", "--n0", "8"])
        .output()
        .expect("run accuracy");
    assert_eq!(bad.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&bad.stderr)
            .trim_end()
            .lines()
            .count(),
        1
    );
}

/// `synth` samples its grids a batch of leaves at a time while it writes them: its peak
/// memory stays far below the file it writes (before streaming, `abc --n0 256` held its
/// 206 MB of leaves and the encoded file beside them: 413 MB at the peak; streamed, about
/// 45 MB). Memory is measured, not time: the child's maximum resident set from `wait4`.
#[test]
fn synth_memory_stays_below_the_file_it_writes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("abc.vdb");
    let child = qbricks_lab()
        .args(["synth", "abc", "--n0", "256", "--compression", "none", "-o"])
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("run qbricks-lab");
    let peak = peak_memory(child);
    let file = std::fs::metadata(&out).expect("output").len();
    assert!(file > 150 << 20, "{file}");
    assert!(
        peak < file / 2,
        "peak resident {} MB for a {} MB file",
        peak >> 20,
        file >> 20
    );
}

/// A raw (`--compression none`) file larger than the free space of its disk is refused at
/// once, before anything is sampled, naming the directory; nothing is left behind.
#[test]
#[allow(unsafe_code)]
fn synth_refuses_a_raw_file_its_disk_cannot_hold() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = std::ffi::CString::new(dir.path().to_str().expect("utf-8 path")).expect("path");
    // SAFETY: `st` is plain data that `statvfs` fills; `path` is a valid C string.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    assert_eq!(unsafe { libc::statvfs(path.as_ptr(), &mut st) }, 0);
    let free = st.f_bavail as f64 * st.f_frsize as f64;
    // 12 bytes a voxel: a cube 30 % larger than the free space.
    let n0 = (1.3 * free / 12.0).cbrt().ceil() as u64;
    if n0 > 2500 {
        eprintln!(
            "{} GB free: a file too large for it would take too much memory to plan",
            free / 1e9
        );
        return;
    }
    let out = dir.path().join("abc.vdb");
    let o = run(&[
        "synth",
        "abc",
        "--n0",
        &n0.to_string(),
        "--compression",
        "none",
        "-o",
        out.to_str().expect("utf-8 path"),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains(&format!("MiB free in {}", dir.path().display())),
        "{err}"
    );
    assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 0);
}
