//! `qbricks-view render` and `probe` from the command line: exit codes, JSON keys, files.

use std::path::{Path, PathBuf};

use crate::common::{qbricks_view, root};
use qbricks_viewer::testvol;

/// The bundled sample if present, else a small test volume in `dir`.
fn sample(dir: &Path) -> PathBuf {
    let bundled = root().join("data/wake_small.qbk");
    if bundled.exists() {
        return bundled;
    }
    let q = |p: [f64; 3]| (p[0] / 4.0).sin() * (p[1] / 5.0).cos() * 0.1;
    let s = |p: [f64; 3]| 0.05 + 0.001 * p[2];
    let file = testvol::nested(8, [0.0; 3], &[("q", &q), ("speed", &s)], 8);
    let path = dir.join("t.qbk");
    format::writer::write(&path, &file).expect("write");
    path
}

fn run(args: &[&str], cwd: &Path) -> (i32, String, String) {
    let out = qbricks_view()
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn render_writes_a_png_and_reports_json() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = sample(dir.path());
    let png = dir.path().join("out.png");
    let state = dir.path().join("view.json");
    let (code, stdout, stderr) = run(
        &[
            file.to_str().expect("utf8"),
            "-o",
            png.to_str().expect("utf8"),
            "--width",
            "64",
            "--height",
            "48",
            "--strategy",
            "exact",
            "--threads",
            "2",
            "--repeat",
            "2",
            "--json",
            "--save-state",
            state.to_str().expect("utf8"),
        ]
        .iter()
        .copied()
        .fold(vec!["render"], |mut v, a| {
            v.push(a);
            v
        }),
        dir.path(),
    );
    assert_eq!(code, 0, "stderr: {stderr}");
    let j: serde_json::Value = serde_json::from_str(stdout.trim()).expect("json");
    for k in [
        "ms",
        "open_ms",
        "rays",
        "samples_per_ray",
        "mrays_per_s",
        "hit_fraction",
        "width",
        "height",
        "strategy",
        "mode",
        "threads",
    ] {
        assert!(j.get(k).is_some(), "missing key {k} in {j}");
    }
    assert_eq!(j["rays"], 64 * 48);
    assert_eq!(j["width"], 64);
    assert_eq!(j["strategy"], "exact");
    assert_eq!(j["threads"], 2);
    let img = image::open(&png).expect("png").to_rgb8();
    assert_eq!((img.width(), img.height()), (64, 48));
    // The saved state reproduces the picture.
    let png2 = dir.path().join("again.png");
    let (code, _, stderr) = run(
        &[
            "render",
            file.to_str().expect("utf8"),
            "-o",
            png2.to_str().expect("utf8"),
            "--state",
            state.to_str().expect("utf8"),
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "stderr: {stderr}");
    let img2 = image::open(&png2).expect("png").to_rgb8();
    assert_eq!(img.as_raw(), img2.as_raw());
    // No temporary files are left behind.
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .expect("ls")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.contains(".tmp")), "{names:?}");

    // --pixel explains one ray.
    let (code, stdout, stderr) = run(
        &[
            "render",
            file.to_str().expect("utf8"),
            "--width",
            "64",
            "--height",
            "48",
            "--pixel",
            "32,24",
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "stderr: {stderr}");
    let j: serde_json::Value = serde_json::from_str(&stdout).expect("json");
    assert!(
        j["rays"][0]["events"]
            .as_array()
            .is_some_and(|e| !e.is_empty()),
        "{j}"
    );
}

#[test]
fn render_errors_are_one_line_with_exit_code_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Default file missing (cwd has no data/).
    let (code, _, stderr) = run(&["render", "-o", "x.png"], dir.path());
    assert_eq!(code, 2);
    assert!(stderr.contains("data/wake_small.qbk"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    // Missing and garbage files.
    let (code, _, stderr) = run(&["render", "nope.qbk", "-o", "x.png"], dir.path());
    assert_eq!(code, 2);
    assert!(stderr.contains("nope.qbk"), "{stderr}");
    std::fs::write(dir.path().join("bad.qbk"), b"garbage garbage garbage").expect("write");
    let (code, _, stderr) = run(&["render", "bad.qbk", "-o", "x.png"], dir.path());
    assert_eq!(code, 2);
    assert!(stderr.contains("bad.qbk"), "{stderr}");
    // Bad flag values.
    let file = sample(dir.path());
    let f = file.to_str().expect("utf8");
    for bad in [
        vec!["render", f, "-o", "x.png", "--eye", "1,2"],
        vec!["render", f, "-o", "x.png", "--width", "0"],
        vec!["render", f, "--pixel", "9999,0"],
    ] {
        let (code, _, stderr) = run(&bad, dir.path());
        assert_eq!(code, 2, "{bad:?}: {stderr}");
    }
    assert!(!dir.path().join("x.png").exists());
}

/// One value's lowest mantissa bit flipped: the archive is still valid, but the payload
/// checksum no longer matches. `render` refuses the file by default and renders it with
/// `--no-checksum`.
#[test]
fn render_no_checksum_opens_a_file_whose_payload_checksum_fails() {
    let dir = tempfile::tempdir().expect("tempdir");
    let good = std::fs::read(sample(dir.path())).expect("read");
    let flipped = testvol::with_one_value_flipped(&good);
    std::fs::write(dir.path().join("flipped.qbk"), &flipped).expect("write");

    let args = [
        "render",
        "flipped.qbk",
        "-o",
        "x.png",
        "--width",
        "16",
        "--height",
        "16",
    ];
    let (code, _, stderr) = run(&args, dir.path());
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("checksum"), "{stderr}");
    assert!(!dir.path().join("x.png").exists());
    // The checksum is verified beside the frame: nothing else is written either, not the
    // view state, the report or a pixel's trace.
    let more = ["--save-state", "st.json", "--json", "--pixel", "3,3"];
    let (code, stdout, stderr) = run(&[&args[..], &more[..]].concat(), dir.path());
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("flipped.qbk") && stderr.contains("checksum"),
        "{stderr}"
    );
    assert!(stdout.is_empty(), "{stdout}");
    assert!(!dir.path().join("x.png").exists() && !dir.path().join("st.json").exists());
    let pixel = ["render", "flipped.qbk", "--pixel", "3,3"];
    let (code, stdout, stderr) = run(&pixel, dir.path());
    assert_eq!((code, stdout.as_str()), (2, ""), "{stderr}");

    let (code, _, stderr) = run(&[&args[..], &["--no-checksum"]].concat(), dir.path());
    assert_eq!(code, 0, "{stderr}");
    assert!(dir.path().join("x.png").exists());
}

#[test]
fn probe_prints_fields_and_gradients() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = sample(dir.path());
    let f = file.to_str().expect("utf8");
    let view = format::BrickFileView::open(&file).expect("open");
    let names: Vec<String> = view
        .file()
        .fields
        .iter()
        .map(|f| f.name.to_string())
        .collect();
    let b = &view.file().bounds;
    let (lo, hi) = (b.min.map(|x| x.to_native()), b.max.map(|x| x.to_native()));
    // A line from outside through the data and out again.
    let line = format!(
        "{},{},{}:{},{},{}:21",
        lo[0] - 1.0,
        0.5 * (lo[1] + hi[1]),
        0.5 * (lo[2] + hi[2]),
        hi[0] + 1.0,
        0.5 * (lo[1] + hi[1]),
        0.5 * (lo[2] + hi[2])
    );
    let (code, stdout, stderr) = run(&["probe", f, "--line", &line, "--json"], dir.path());
    assert_eq!(code, 0, "stderr: {stderr}");
    let j: serde_json::Value = serde_json::from_str(&stdout).expect("json");
    let pts = j.as_array().expect("list");
    assert_eq!(pts.len(), 21);
    for p in pts {
        for k in ["x", "y", "z", "gradient"] {
            assert!(p.get(k).is_some(), "missing {k}: {p}");
        }
        for n in &names {
            assert!(p.get(n).is_some(), "missing field {n}: {p}");
        }
    }
    // Outside the data: no numbers (JSON null stands for NaN); inside: numbers.
    assert!(pts[0][names[0].as_str()].is_null() && pts[0]["gradient"][0].is_null());
    assert!(pts[10][names[0].as_str()].is_number() && pts[10]["gradient"][2].is_number());

    // CSV points with a header line; text output has a header and one row per point.
    let csv = dir.path().join("p.csv");
    let mid: Vec<f64> = (0..3).map(|a| 0.5 * (lo[a] + hi[a])).collect();
    std::fs::write(
        &csv,
        format!(
            "x,y,z\n{},{},{}\n{},{},{}\n",
            mid[0],
            mid[1],
            mid[2],
            lo[0] - 5.0,
            0,
            0
        ),
    )
    .expect("csv");
    let (code, stdout, stderr) = run(
        &["probe", f, "--points", csv.to_str().expect("utf8")],
        dir.path(),
    );
    assert_eq!(code, 0, "stderr: {stderr}");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 3, "{stdout}");
    assert!(lines[2].contains("NaN"), "{stdout}");

    // Bad input.
    std::fs::write(&csv, "x,y,z\n1,2\n").expect("csv");
    let (code, _, stderr) = run(
        &["probe", f, "--points", csv.to_str().expect("utf8")],
        dir.path(),
    );
    assert_eq!(code, 2);
    assert!(stderr.contains("line 2"), "{stderr}");
    let (code, _, _) = run(&["probe", f, "--line", "0,0,0:1,1,1:0"], dir.path());
    assert_eq!(code, 2);
    let (code, _, _) = run(&["probe", f], dir.path());
    assert_eq!(code, 2);
}

/// `--mode dvr` without `--strategy` uses the dvr strategy `uniform` (pre-integrated)
/// quietly, or `bisect` with `--no-preintegrated`, while an explicit `--strategy exact` in
/// dvr mode says what it does instead; a negative step is refused by the view-state check
/// (not mistaken for a flag).
#[test]
fn render_dvr_picks_its_default_strategy_and_refuses_a_negative_step() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = sample(dir.path());
    let f = file.to_str().expect("utf-8 path");
    let (code, out, err) = run(
        &[
            "render", f, "-o", "d.png", "--mode", "dvr", "--width", "16", "--height", "12",
            "--json",
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert_eq!(j["strategy"], "uniform");
    assert!(!err.contains("note"), "{err}");
    let (code, out, err) = run(
        &[
            "render",
            f,
            "-o",
            "p.png",
            "--mode",
            "dvr",
            "--no-preintegrated",
            "--width",
            "16",
            "--height",
            "12",
            "--json",
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert_eq!(j["strategy"], "bisect");

    let (code, _, err) = run(
        &[
            "render",
            f,
            "-o",
            "e.png",
            "--mode",
            "dvr",
            "--strategy",
            "exact",
            "--width",
            "16",
            "--height",
            "12",
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("samples as `uniform`"), "{err}");

    let (code, _, err) = run(&["render", f, "-o", "n.png", "--step", "-1"], dir.path());
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("step") && err.contains("-1"), "{err}");
}

/// Issue 27 from the command line: clip and slice planes and two surfaces render a PNG;
/// `--pixel` lists the clip interval, the slice and the hits; a bad plane is refused
/// naming the flag, with nothing written.
#[test]
fn cutting_flags_render_and_explain_a_pixel() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = sample(dir.path());
    let f = file.to_str().expect("utf8");
    let png = dir.path().join("cut.png");
    let p = png.to_str().expect("utf8");
    let cut: &[&str] = &[
        "--iso",
        "0.005,0.05",
        "--iso-opacity",
        "0.3,1",
        "--clip",
        "z<0.3",
        "--slice",
        "0,0,0:0,0,1",
        "--slice-opacity",
        "0.5",
        "--slice-contours",
        "--width",
        "64",
        "--height",
        "40",
        "--ortho",
        "9",
        "--eye",
        "2,0,9",
        "--look-at",
        "2,0,0",
        "--up",
        "0,1,0",
    ];
    let mut args = vec!["render", f, "-o", p];
    args.extend_from_slice(cut);
    let (code, _, stderr) = run(&args, dir.path());
    assert_eq!(code, 0, "{stderr}");
    assert!(png.exists());
    let mut args = vec!["render", f, "--pixel", "32,20"];
    args.extend_from_slice(cut);
    let (code, stdout, stderr) = run(&args, dir.path());
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("json");
    let events = v["rays"][0]["events"].as_array().expect("events");
    let kinds: Vec<&str> = events.iter().filter_map(|e| e["event"].as_str()).collect();
    assert_eq!(kinds.first(), Some(&"clip"), "{kinds:?}");
    // Looking down z from z = 9: the clip keeps z < 0.3, so from t = 8.7 on.
    assert!((events[0]["t0"].as_f64().expect("t0") - 8.7).abs() < 1e-9);
    let slice = events
        .iter()
        .find(|e| e["event"] == "slice")
        .expect("the centre ray meets the slice");
    assert!((slice["t"].as_f64().expect("t") - 9.0).abs() < 1e-9);
    assert!(slice["value"].as_f64().is_some());
    let ts: Vec<f64> = events.iter().filter_map(|e| e["t"].as_f64()).collect();
    assert!(ts.windows(2).all(|w| w[0] <= w[1]), "in ray order: {ts:?}");

    for (bad, want) in [
        (&["--clip", "w>1"][..], "--clip"),
        (&["--slice", "1,2,3:0,0,0"], "--slice"),
        (
            &["--iso", "0.1", "--iso-opacity", "0.5,0.5"],
            "--iso-opacity",
        ),
    ] {
        let out = dir.path().join("bad.png");
        let mut args = vec!["render", f, "-o", out.to_str().expect("utf8")];
        args.extend(bad);
        let (code, _, stderr) = run(&args, dir.path());
        assert_eq!(code, 2, "{bad:?}: {stderr}");
        assert!(stderr.contains(want), "{bad:?}: {stderr}");
        assert!(!out.exists(), "{bad:?} wrote a file");
    }
}

/// `render` opens a file checking only what does not grow with the data, and a part a
/// frame reads that fails its check fails the render as an open would have: the exit
/// code of a file refused at open, the
/// file and the part named, no picture written. `info` still checks everything at open.
#[test]
fn render_refuses_a_damaged_part_it_reads_and_writes_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let q = |p: [f64; 3]| (p[0] / 4.0).sin() * (p[1] / 5.0).cos() * 0.1;
    let base = testvol::nested(8, [0.0; 3], &[("q", &q)], 8);
    let b = base.region_bricks[0] as usize;
    let mut brick = base.clone();
    brick.bricks[b].first_value = brick.fields[0].values.len() as u64;
    let mut tree = base;
    tree.kd_axes[0] = 7;
    for (name, file, part) in [
        ("brick.qbk", brick, format!("bricks[{b}]")),
        ("tree.qbk", tree, "kd_axes[0]".to_string()),
    ] {
        let path = dir.path().join(name);
        format::writer::write(&path, &file).expect("write");
        let png = dir.path().join(format!("{name}.png"));
        let (code, _, err) = run(
            &[
                "render",
                path.to_str().expect("utf8"),
                "-o",
                png.to_str().expect("utf8"),
                "--width",
                "32",
                "--height",
                "32",
            ],
            dir.path(),
        );
        assert_ne!(code, 0, "{name}: {err}");
        assert!(
            err.contains(name) && err.contains(&part) && err.contains("archive is invalid"),
            "{name}: {err}"
        );
        assert!(!png.exists(), "{name}: a picture was written");
        let (info_code, _, err) = run(&["info", path.to_str().expect("utf8")], dir.path());
        assert_eq!(
            info_code, code,
            "{name}: info opened it, or failed otherwise: {err}"
        );
        assert!(err.contains(&part), "{name}: {err}");
    }
}
