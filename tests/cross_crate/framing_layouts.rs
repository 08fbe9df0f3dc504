//! Issue 26, "framing": the default camera must frame the structure of any layout, not only
//! the bundled sample's nested grids (`viewer/tests/render/defaults.rs`). Here a frame of
//! the bundled cache baked with `qbricks-bake` (one 32³ level), a single-grid file from
//! `qbricks-lab synth wake-single --n0 48`, and the whole cache as a sequence, whose one
//! camera frames the union of the frames' surfaces: rendered bare (`--overlays none`), the
//! structure's bounding box in the picture covers ≥ 60 % of the width or height, is
//! centred within 15 % and is not cut at the edges. Measured at 800×600: the cache frame
//! 69 % × 48 %, centre off by (+1 %, −3 %); the single grid 73 % × 49 %, (0 %, −1 %); the
//! sequence's union over its four frames (200×150) 60 % × 69 %, (+0.5 %, −2 %).

use std::path::Path;
use std::process::{Command, Output};

use crate::common;

fn run(bin: &str, args: &[&str], dir: &Path) -> Output {
    let out = Command::new(common::bin(bin))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("run");
    assert!(
        out.status.success(),
        "{bin} {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The box of the pixels that differ from the background (the top-left pixel) by more
/// than 6 in a channel, as (x0, x1, y0, y1), `None` for an empty picture; and the size.
fn structure_box(png: &Path) -> (Option<[u32; 4]>, u32, u32) {
    let img = image::open(png)
        .unwrap_or_else(|e| panic!("{}: {e}", png.display()))
        .to_rgb8();
    let bg = img.get_pixel(0, 0).0;
    let mut b: Option<[u32; 4]> = None;
    for (x, y, p) in img.enumerate_pixels() {
        if (0..3).all(|c| p.0[c].abs_diff(bg[c]) <= 6) {
            continue;
        }
        b = Some(match b {
            None => [x, x, y, y],
            Some([x0, x1, y0, y1]) => [x0.min(x), x1.max(x), y0.min(y), y1.max(y)],
        });
    }
    (b, img.width(), img.height())
}

/// Fill (fraction of width, height) and offset of the centre from the image's centre
/// (fractions of width, height) of a structure box.
fn measure([x0, x1, y0, y1]: [u32; 4], w: u32, h: u32) -> ([f64; 2], [f64; 2]) {
    let (fw, fh) = (f64::from(w), f64::from(h));
    let fill = [f64::from(x1 - x0 + 1) / fw, f64::from(y1 - y0 + 1) / fh];
    let off = [
        (f64::from(x0 + x1 + 1) / 2.0 - fw / 2.0) / fw,
        (f64::from(y0 + y1 + 1) / 2.0 - fh / 2.0) / fh,
    ];
    (fill, off)
}

fn assert_framed(what: &str, b: [u32; 4], w: u32, h: u32) {
    let (fill, off) = measure(b, w, h);
    assert!(fill[0].max(fill[1]) >= 0.6, "{what}: fills only {fill:?}");
    assert!(
        fill[0] <= 0.95 && fill[1] <= 0.95,
        "{what}: cut at the edges: {fill:?}"
    );
    assert!(
        off[0].abs() <= 0.15 && off[1].abs() <= 0.15,
        "{what}: off-centre by {off:?}"
    );
}

#[test]
fn a_cache_frame_and_a_single_grid_are_framed_centred() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let d = tmp.path();
    let cache = common::root().join("data/cache/fluid_data_0001.vdb");
    run(
        "qbricks-bake",
        &[
            "bake",
            &cache.display().to_string(),
            "-o",
            "cache1.qbk",
            "--quiet",
        ],
        d,
    );
    run(
        "qbricks-lab",
        &["synth", "wake-single", "--n0", "48", "-o", "single.vdb"],
        d,
    );
    run(
        "qbricks-bake",
        &["bake", "single.vdb", "-o", "single.qbk", "--quiet"],
        d,
    );
    for name in ["cache1", "single"] {
        let png = format!("{name}.png");
        run(
            "qbricks-view",
            &[
                "render",
                &format!("{name}.qbk"),
                "-o",
                &png,
                "--overlays",
                "none",
            ],
            d,
        );
        let (b, w, h) = structure_box(&d.join(&png));
        let b = b.unwrap_or_else(|| panic!("{name}: the default picture is empty"));
        assert_framed(name, b, w, h);
    }
}

#[test]
fn a_sequence_frames_the_union_of_its_frames_surfaces() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let d = tmp.path();
    let cache = common::root().join("data/cache/fluid_data_####.vdb");
    run(
        "qbricks-bake",
        &[
            "bake",
            &cache.display().to_string(),
            "-o",
            "out/frame_####.qbk",
            "--quiet",
        ],
        d,
    );
    let out = run(
        "qbricks-view",
        &[
            "render",
            "out/frame_####.qbk",
            "-o",
            "png/frame_####.png",
            "--overlays",
            "none",
            "--width",
            "200",
            "--height",
            "150",
        ],
        d,
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("one camera for every frame, on the union of the iso surfaces of 4"),
        "{err}"
    );
    // The ring moves: one frame alone may sit off-centre, their union may not.
    let mut union: Option<[u32; 4]> = None;
    let (mut w, mut h) = (0, 0);
    for f in 1..=4 {
        let (b, fw, fh) = structure_box(&d.join(format!("png/frame_{f:04}.png")));
        let b = b.unwrap_or_else(|| panic!("frame {f} is empty"));
        (w, h) = (fw, fh);
        union = Some(match union {
            None => b,
            Some(u) => [
                u[0].min(b[0]),
                u[1].max(b[1]),
                u[2].min(b[2]),
                u[3].max(b[3]),
            ],
        });
    }
    assert_framed("the sequence", union.expect("frames"), w, h);
}
