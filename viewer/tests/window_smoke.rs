//! The real window under Xvfb: `--screenshot` saves a picture of the whole window with
//! the rendered volume in it, and `--orbit-frames --json` reports its frame rates.
//!
//! Needs `xvfb-run` (Debian's xvfb and xauth) and Mesa's GL; `.ci/run` installs them and
//! sets QBRICKS_REQUIRE_XVFB=1 so a missing X server fails instead of skipping.
#![cfg(feature = "gui")]

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sample() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/wake_small.qbk")
}

fn have_xvfb() -> bool {
    let found = Command::new("sh")
        .args(["-c", "command -v xvfb-run"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var_os("QBRICKS_REQUIRE_XVFB").is_none(),
            "xvfb-run is not installed but QBRICKS_REQUIRE_XVFB is set"
        );
        eprintln!("skipping: xvfb-run not installed (apt-get install xvfb xauth)");
    }
    found
}

/// Runs qbricks-view with `args` in a fresh X server.
/// Runs the viewer under `xvfb-run`, with its X authority file in a directory of ours: left
/// to itself, xvfb-run makes its own under /tmp and, when removing it fails at exit (seen
/// once under the whole suite's parallel load), exits 5 in place of the viewer's status.
fn in_xvfb(args: &[&str], dir: &Path) -> Output {
    let runtime = tempfile::tempdir().expect("runtime dir");
    let auth = runtime.path().join("Xauthority");
    std::fs::write(&auth, b"").expect("auth file");
    Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1400x1000x24"])
        .arg("-f")
        .arg(&auth)
        .arg(env!("CARGO_BIN_EXE_qbricks-view"))
        .args(args)
        .current_dir(dir)
        .env("XDG_RUNTIME_DIR", runtime.path())
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("run xvfb-run")
}

#[test]
fn screenshot_shows_the_rendered_volume_and_the_panel() {
    if !have_xvfb() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let shot = dir.path().join("window.png");
    let file = sample();
    let out = in_xvfb(
        &[
            file.to_str().expect("utf8"),
            "--size",
            "1000x700",
            "--threads",
            "2",
            "--screenshot",
            shot.to_str().expect("utf8"),
        ],
        dir.path(),
    );
    assert!(
        out.status.success(),
        "exit {:?}: {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&shot).expect("a PNG").to_rgb8();
    let (w, h) = img.dimensions();
    assert!(w >= 1000 && h >= 700, "{w}x{h}");
    // The central area (right of the panel, above the status line) holds the picture:
    // the shaded rings give many colours.
    let mut central = HashSet::new();
    for y in h / 8..h * 7 / 8 {
        for x in w * 2 / 5..w * 19 / 20 {
            central.insert(img.get_pixel(x, y).0);
        }
    }
    assert!(
        central.len() > 200,
        "only {} colours in the image area",
        central.len()
    );
    // The side panel is there: its column differs from the image background and holds
    // light text.
    let mut panel = HashSet::new();
    for y in 0..h {
        for x in 0..w / 5 {
            panel.insert(img.get_pixel(x, y).0);
        }
    }
    assert!(
        panel.len() > 20,
        "only {} colours in the panel",
        panel.len()
    );
    let bright_text = (0..h)
        .flat_map(|y| (0..w / 5).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&c| c > 150))
        .count();
    assert!(bright_text > 100, "no panel text found");
}

#[test]
fn orbit_reports_frame_rates_as_json() {
    if !have_xvfb() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let file = sample();
    let out = in_xvfb(
        &[
            "open",
            file.to_str().expect("utf8"),
            "--size",
            "640x480",
            "--threads",
            "2",
            "--orbit-frames",
            "12",
            "--json",
        ],
        dir.path(),
    );
    assert!(
        out.status.success(),
        "exit {:?}: {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().last().expect("a JSON line");
    let j: serde_json::Value = serde_json::from_str(line).expect("JSON");
    for key in [
        "preview_fps",
        "ui_frame_ms_p50",
        "ui_frame_ms_max",
        "refine_ms",
        "full_frame_ms",
        "preview_scale",
        "preview_scale_p50",
        "preview_scale_max",
        "preview_scale_counts",
        "orbit_frames",
        "previews_shown",
        "window",
        "threads",
        "jobs",
        "first_ui_ms",
        "framed_ms",
    ] {
        assert!(j.get(key).is_some(), "missing {key}: {j}");
    }
    assert_eq!(j["orbit_frames"], 12);
    // One view per orbit frame plus the first: the window must not keep changing its own
    // view (a status line that wrapped once made the image size oscillate forever).
    let jobs = j["jobs"].as_u64().unwrap_or(u64::MAX);
    assert!(
        jobs <= 12 + 3,
        "{jobs} views submitted for a 12-frame orbit"
    );
    assert_eq!(j["threads"], 2);
    // At the smallest divisor (3) or coarser, and the coarsest shown no finer than the
    // median.
    assert!(j["preview_scale"].as_u64().unwrap_or(0) >= 3);
    let (p50, max) = (
        j["preview_scale_p50"].as_u64(),
        j["preview_scale_max"].as_u64(),
    );
    assert!(
        p50.is_some_and(|m| m >= 3 && max.is_some_and(|x| x >= m)),
        "{j}"
    );
    assert!(j["refine_ms"].as_f64().unwrap_or(-1.0) > 0.0);
    assert!(j["previews_shown"].as_u64().unwrap_or(0) >= 1, "{j}");
    // The divisors counted add up to the previews shown, the coarsest among them.
    let counts = j["preview_scale_counts"].as_object().expect("an object");
    let total: u64 = counts.values().filter_map(|v| v.as_u64()).sum();
    assert_eq!(Some(total), j["previews_shown"].as_u64(), "{j}");
    let coarsest = counts.keys().filter_map(|k| k.parse::<u64>().ok()).max();
    assert_eq!(coarsest, max, "{j}");
    // The first UI frame comes before (or with) the framed view the orbit starts from.
    let (first, framed) = (j["first_ui_ms"].as_f64(), j["framed_ms"].as_f64());
    assert!(
        first.is_some_and(|f| f > 0.0 && framed.is_some_and(|g| g >= f)),
        "{j}"
    );
}

/// A scripted window (`--screenshot`) on a file that does not open has nothing to show:
/// it exits 2 naming the file, at once, and writes no screenshot (as `render` writes no
/// image). It used to save a picture of the error panel and exit 0.
#[test]
fn a_screenshot_of_a_file_that_fails_to_open_fails_and_writes_nothing() {
    if !have_xvfb() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let bad = dir.path().join("bad.qbk");
    std::fs::write(&bad, b"not a qbk file").expect("write");
    for (file, frames) in [("nope.qbk", Some("5")), ("bad.qbk", None)] {
        let shot = dir.path().join("window.png");
        let mut args = vec![file, "--size", "800x600", "--screenshot", "window.png"];
        if let Some(n) = frames {
            args.extend(["--frames", n]);
        }
        let started = std::time::Instant::now();
        let out = in_xvfb(&args, dir.path());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{file}: {err}");
        assert!(
            err.starts_with(&format!("qbricks-view: {file}: ")),
            "{file}: {err}"
        );
        assert!(!shot.exists(), "{file}: a screenshot was written");
        assert!(
            started.elapsed() < std::time::Duration::from_secs(60),
            "{file}: took {:?}",
            started.elapsed()
        );
    }
}

/// Runs a scripted window (`--screenshot`) on `file` in `dir` and checks that it is
/// refused as `render` refuses it: exit 2, the message holding each of `needles`, no
/// screenshot written.
fn assert_screenshot_refused(file: &str, dir: &Path, needles: &[&str]) {
    let args = [file, "--size", "800x600", "--screenshot", "window.png"];
    let out = in_xvfb(&args, dir);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{file}: {err}");
    for needle in needles {
        assert!(err.contains(needle), "{file}: no {needle:?} in {err}");
    }
    assert!(
        !dir.join("window.png").exists(),
        "{file}: a screenshot was written"
    );
}

/// A scripted window on a file whose structure is damaged where its frames read it (a
/// brick's values past the arrays; the window opens files to be checked where they are
/// read, see `dataset::render_options`): it fails as `render` does, exit 2 naming the
/// file and the part, and writes no screenshot.
#[test]
fn a_screenshot_of_a_file_damaged_where_frames_read_it_fails_and_writes_nothing() {
    if !have_xvfb() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let q = |p: [f64; 3]| (p[0] / 4.0).sin() * (p[1] / 5.0).cos() * 0.1;
    let mut file = qbricks_viewer::testvol::nested(8, [0.0; 3], &[("q", &q)], 8);
    let b = file.region_bricks[0] as usize;
    file.bricks[b].first_value = file.fields[0].values.len() as u64;
    format::writer::write(&dir.path().join("damaged.qbk"), &file).expect("write");
    let part = format!("bricks[{b}]");
    assert_screenshot_refused("damaged.qbk", dir.path(), &["damaged.qbk", &part]);
}

/// A scripted window on a file whose payload checksum fails (one value's lowest bit
/// flipped: the archive stays valid). The window opens files without waiting for the
/// checksum and verifies it once the camera is framed: the run fails as `render` does,
/// exit 2 naming the file and the checksum, and writes no screenshot.
#[test]
fn a_screenshot_of_a_file_whose_checksum_fails_writes_nothing() {
    if !have_xvfb() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let good = std::fs::read(sample()).expect("read the sample");
    let flipped = qbricks_viewer::testvol::with_one_value_flipped(&good);
    std::fs::write(dir.path().join("flipped.qbk"), &flipped).expect("write");
    assert_screenshot_refused("flipped.qbk", dir.path(), &["flipped.qbk", "checksum"]);
}
