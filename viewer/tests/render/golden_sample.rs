//! Golden images of the bundled sample scene (`data/wake_small.qbk` with the sphere mesh),
//! one per mode, rendered through the `qbricks-view render` command exactly as a user runs
//! it. The bundled file is checked against the baker elsewhere
//! (`preprocess/tests/bake/sample.rs`), so a change
//! in baking, reconstruction, sampling, shading or camera shows up here as a PSNR drop.
//! Regenerate with `QBRICKS_UPDATE_GOLDEN=1` after checking the new pictures by eye.

use crate::common::{self, qbricks_view};

/// Same threshold as the synthetic-scene goldens: round-off changes stay far above it,
/// a 10 % change of the iso value (0.05 → 0.045) falls below it (43 dB, measured).
const MIN_PSNR: f64 = 45.0;

fn render_sample(name: &str, extra: &[&str]) {
    let dir = tempfile::tempdir().expect("tempdir");
    let png = dir.path().join(format!("{name}.png"));
    let out = qbricks_view()
        .current_dir(common::root())
        .args(["render", "data/wake_small.qbk", "-o"])
        .arg(&png)
        .args([
            "--mesh",
            "data/sphere.obj",
            "--eye",
            "0.6,3.3,5.0",
            "--look-at",
            "2.0,0,0",
            "--width",
            "200",
            "--height",
            "125",
            // The bare picture: the goldens pin the renderer; the overlays have their
            // own tests.
            "--overlays",
            "none",
        ])
        .args(extra)
        .output()
        .expect("run qbricks-view");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&png).expect("rendered png").to_rgb8();
    common::check_golden(name, img.width(), img.height(), img.as_raw(), MIN_PSNR);
}

#[test]
fn bundled_sample_iso_exact_matches_its_golden_image() {
    render_sample("sample_iso_exact", &["--mode", "iso", "--iso", "0.05"]);
}

#[test]
fn bundled_sample_default_dvr_with_shadows_matches_its_golden_image() {
    // The default dvr: `uniform` with pre-integrated opacity (see BENCHMARKS.md).
    render_sample(
        "sample_dvr_default",
        &["--mode", "dvr", "--iso", "0.05", "--spp", "2", "--shadows"],
    );
}
