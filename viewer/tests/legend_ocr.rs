//! The legend read back from rendered pictures by an independent reader: `tesseract` OCR
//! of the right-hand part of `qbricks-view render`'s PNG of the bundled sample, at
//! 640×480 and at 4K. The field's name, at least three tick numbers, all inside the colour
//! map's range and in order, and the iso value must come out. `.ci/run` installs
//! tesseract and sets QBRICKS_REQUIRE_TESSERACT=1, so a missing reader fails there instead
//! of skipping.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

fn have_tesseract() -> bool {
    let ok = Command::new("tesseract")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            std::env::var_os("QBRICKS_REQUIRE_TESSERACT").is_none(),
            "tesseract is not installed but QBRICKS_REQUIRE_TESSERACT is set"
        );
        eprintln!("skipped: tesseract is not installed");
    }
    ok
}

/// Renders the sample at `w`×`h` with the legend only; returns the picture and the view
/// state it was rendered with.
fn render(dir: &Path, w: u32, h: u32) -> (image::RgbImage, serde_json::Value) {
    let png = dir.join(format!("legend_{w}x{h}.png"));
    let state = dir.join(format!("legend_{w}x{h}.json"));
    let out = Command::new(env!("CARGO_BIN_EXE_qbricks-view"))
        .current_dir(root())
        .args(["render", "data/wake_small.qbk", "--overlays", "legend"])
        // A camera that keeps the rings left of the legend: the reader is given the
        // legend's side of the picture, and a ring behind its numbers is not the legend.
        .args(["--eye", "4,-14,6", "--look-at", "2,0,0"])
        .args(["--width", &w.to_string(), "--height", &h.to_string()])
        .arg("-o")
        .arg(&png)
        .arg("--save-state")
        .arg(&state)
        .output()
        .expect("run qbricks-view");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&png).expect("png").to_rgb8();
    let state =
        serde_json::from_str(&std::fs::read_to_string(&state).expect("state")).expect("state json");
    (img, state)
}

/// OCR of the legend's side of the picture (the right 22 %), scaled up so that the crop
/// is at least 1,000 pixels high (tesseract misreads capitals under about 15 pixels).
fn read_legend(dir: &Path, img: &image::RgbImage) -> String {
    let (w, h) = img.dimensions();
    let x0 = w * 78 / 100;
    let crop = image::imageops::crop_imm(img, x0, 0, w - x0, h).to_image();
    let k = (1000.0 / f64::from(h)).max(1.0);
    let crop = image::imageops::resize(
        &crop,
        (f64::from(w - x0) * k) as u32,
        (f64::from(h) * k) as u32,
        image::imageops::FilterType::Lanczos3,
    );
    let path = dir.join(format!("crop_{w}x{h}.png"));
    crop.save(&path).expect("save crop");
    let out = Command::new("tesseract")
        .arg(&path)
        .args(["stdout", "--psm", "6"])
        .output()
        .expect("run tesseract");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn the_legend_reads_back_at_640x480_and_at_4k() {
    if !have_tesseract() {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    for (w, h) in [(640, 480), (3840, 2160)] {
        let (img, state) = render(dir.path(), w, h);
        let text = read_legend(dir.path(), &img);
        let field = state["colormap"]["field"].as_str().expect("field");
        let points = state["colormap"]["points"].as_array().expect("points");
        let value = |p: &serde_json::Value| p["value"].as_f64().expect("value");
        let (lo, hi) = (value(&points[0]), value(&points[points.len() - 1]));
        assert!(
            text.lines().any(|l| l.trim().eq_ignore_ascii_case(field)),
            "{w}x{h}: the field name {field:?} is not read back: {text:?}"
        );
        // Tick numbers: lines that are one number, top to bottom (descending values).
        let ticks: Vec<f64> = text
            .lines()
            .filter_map(|l| l.trim().parse::<f64>().ok())
            .collect();
        assert!(
            (3..=7).contains(&ticks.len()),
            "{w}x{h}: {} tick numbers read: {text:?}",
            ticks.len()
        );
        for t in &ticks {
            assert!(
                (lo..=hi).contains(t),
                "{w}x{h}: tick {t} outside the map's range {lo}..{hi}: {text:?}"
            );
        }
        assert!(
            ticks.windows(2).all(|p| p[0] > p[1]),
            "{w}x{h}: ticks not in order: {ticks:?}"
        );
        // The iso value, written under the bar (the iso field is not the colour field).
        let iso = state["iso"].as_f64().expect("iso");
        let read: f64 = text
            .lines()
            .find_map(|l| l.split_once('=').filter(|(k, _)| k.contains('q')))
            .and_then(|(_, v)| v.trim().parse().ok())
            .unwrap_or_else(|| panic!("{w}x{h}: no iso line: {text:?}"));
        // Printed with 3 significant digits.
        assert!(
            (read - iso).abs() <= 5e-3 * iso.abs(),
            "{w}x{h}: iso read {read}, view has {iso}"
        );
    }
}
