//! Helpers shared by the viewer's integration tests (`cli/`, `render/`), each of which
//! includes this module as `#[path = "../common/mod.rs"] mod common;`.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

/// The `qbricks-view` binary of this package (cargo builds it for the integration tests).
pub fn qbricks_view() -> Command {
    Command::new(env!("CARGO_BIN_EXE_qbricks-view"))
}

/// Repository root (the bundled samples are in its `data/`).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the crate is in the workspace root")
        .to_path_buf()
}

/// Peak signal-to-noise ratio in dB of two 8-bit images of the same size (∞ if equal).
pub fn psnr(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len(), "psnr: images differ in size");
    let se: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| {
            let d = f64::from(*x) - f64::from(*y);
            d * d
        })
        .sum();
    if se == 0.0 {
        return f64::INFINITY;
    }
    let mse = se / a.len() as f64;
    10.0 * (255.0 * 255.0 / mse).log10()
}

/// Compares an RGB8 image with `viewer/tests/golden/NAME.png` by PSNR (at least `min_psnr`
/// dB).
///
/// With `QBRICKS_UPDATE_GOLDEN=1` the golden file is (re)written instead. On a mismatch
/// the rendered image is saved in the temp dir and its path printed.
pub fn check_golden(name: &str, width: u32, height: u32, rgb: &[u8], min_psnr: f64) {
    let golden = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(format!("{name}.png"));
    if std::env::var_os("QBRICKS_UPDATE_GOLDEN").is_some_and(|v| v == "1") {
        std::fs::create_dir_all(golden.parent().expect("golden dir")).expect("mkdir golden");
        image::save_buffer(&golden, rgb, width, height, image::ColorType::Rgb8)
            .expect("write golden");
        eprintln!("updated {}", golden.display());
        return;
    }
    let want = image::open(&golden)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (run with QBRICKS_UPDATE_GOLDEN=1 to create it)",
                golden.display()
            )
        })
        .to_rgb8();
    let actual = std::env::temp_dir().join(format!("qbricks-golden-{name}.actual.png"));
    assert_eq!(
        (want.width(), want.height()),
        (width, height),
        "{}: golden size differs",
        golden.display()
    );
    let p = psnr(want.as_raw(), rgb);
    if p < min_psnr {
        let _ = image::save_buffer(&actual, rgb, width, height, image::ColorType::Rgb8);
        panic!(
            "{name}: PSNR {p:.2} dB < {min_psnr} dB against {} (rendered image: {}; \
             QBRICKS_UPDATE_GOLDEN=1 accepts the change)",
            golden.display(),
            actual.display()
        );
    }
}
