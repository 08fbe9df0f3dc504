//! `qbricks-view render` on frame sequences and with `--colour-field` / `--iso-field`, on
//! small closed-form frames written with `testvol` (the end-to-end test through
//! `qbricks-bake` is `tests/cross_crate/render_sequence.rs`).

use std::path::Path;
use std::process::{Command, Output};

use format::sequence::{FieldRange, Manifest, ManifestFrame};
use qbricks_viewer::testvol::{self, GridSpec};

fn qbricks_view(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_qbricks-view"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run qbricks-view")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A frame over the unit cube: `q` a cone around the centre (its default iso surface a
/// sphere of radius 0.45), `speed` = x, `density` = y. With `hot_corner`, speed also has
/// a narrow bump of height 3 at the corner (1, 1, 1), far from the sphere: the pictures
/// are the same but the frame's own speed range is three times wider.
fn write_frame(path: &Path, hot_corner: bool) {
    write_frame_scaled(path, hot_corner, 1.0);
}

/// [`write_frame`] with `q` multiplied by `q_scale`: the same sphere at a frame's own
/// default iso value (a fraction of its maximum), and a shrinking flow's frame.
fn write_frame_scaled(path: &Path, hot_corner: bool, q_scale: f64) {
    let q = move |p: [f64; 3]| {
        let d: f64 = p.iter().map(|x| (x - 0.5) * (x - 0.5)).sum::<f64>().sqrt();
        q_scale * (1.0 - 2.0 * d)
    };
    let speed = move |p: [f64; 3]| {
        let c: f64 = p.iter().map(|x| (x - 1.0) * (x - 1.0)).sum();
        p[0] + if hot_corner {
            3.0 * (-c / 0.01).exp()
        } else {
            0.0
        }
    };
    let density = |p: [f64; 3]| p[1];
    let grid = GridSpec::covering([0.0; 3], [1.0; 3], 1.0 / 16.0);
    let file = testvol::build(
        &[grid],
        &[("q", &q), ("speed", &speed), ("density", &density)],
        8,
    );
    format::writer::write(path, &file).expect("write frame");
}

fn png(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

fn distinct_colours(img: &image::RgbImage) -> usize {
    let mut c: Vec<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    c.sort_unstable();
    c.dedup();
    c.len()
}

/// One explicit camera: a frame alone frames its own surface and a sequence the frames'
/// common box (issue 26), and these tests compare the two pictures pixel for pixel.
const SMALL: [&str; 10] = [
    "--width",
    "64",
    "--height",
    "48",
    "--aov",
    "value",
    "--eye",
    "2.1,-1.9,1.8",
    "--look-at",
    "0.5,0.5,0.5",
];

#[test]
fn one_colour_map_for_the_whole_sequence() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    write_frame(&d.join("f_0001.qbk"), false);
    write_frame(&d.join("f_0002.qbk"), true);

    // Each frame alone colours speed over its own range: the same surface, different colours.
    for f in ["0001", "0002"] {
        let out = qbricks_view(
            &[
                &[
                    "render",
                    &format!("f_{f}.qbk"),
                    "-o",
                    &format!("alone_{f}.png"),
                ][..],
                &SMALL,
            ]
            .concat(),
            d,
        );
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let (a1, a2) = (
        png(&d.join("alone_0001.png")),
        png(&d.join("alone_0002.png")),
    );
    assert_ne!(
        a1, a2,
        "frames rendered alone should differ (their ranges do)"
    );

    // As a sequence without a manifest: the union of the frames' ranges, said on stderr,
    // and the same pixels in both frames.
    let out = qbricks_view(
        &[
            &["render", "f_####.qbk", "-o", "seq/f_####.png"][..],
            &SMALL,
        ]
        .concat(),
        d,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("no manifest") && err.contains("union of the 2 frame"),
        "{err}"
    );
    let (s1, s2) = (
        png(&d.join("seq/f_0001.png")),
        png(&d.join("seq/f_0002.png")),
    );
    assert!(
        distinct_colours(&s1) > 8,
        "the surface should show a colour ramp"
    );
    assert_eq!(s1, s2, "one value, one colour, in every frame");
    // The wider range of frame 2 applies to frame 1 too.
    assert_eq!(s2, a2);

    // With a manifest, its ranges win (here a speed range much wider than the frames').
    // It lists both frames as baked: a file it does not list is not a frame of its bake.
    let baked = |frame: u64| ManifestFrame {
        frame,
        input: format!("in_{frame:04}.vdb"),
        output: format!("f_{frame:04}.qbk"),
        leaf_cells: 0,
        fields: vec![],
    };
    let manifest = Manifest {
        input_pattern: "in_####.vdb".into(),
        output_pattern: "f_####.qbk".into(),
        frames: vec![baked(1), baked(2)],
        failed: vec![],
        missing: vec![],
        fields: vec![FieldRange {
            name: "speed".into(),
            min: 0.0,
            max: 40.0,
        }],
    };
    std::fs::write(
        d.join("f_sequence.json"),
        serde_json::to_string(&manifest).expect("json"),
    )
    .expect("manifest");
    let out = qbricks_view(
        &[
            &["render", "f_%04d.qbk", "-o", "man/f_%04d.png"][..],
            &SMALL,
        ]
        .concat(),
        d,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("f_sequence.json"), "{}", stderr(&out));
    let (m1, m2) = (
        png(&d.join("man/f_0001.png")),
        png(&d.join("man/f_0002.png")),
    );
    assert_eq!(m1, m2);
    assert_ne!(m1, s1, "the manifest's range should change the colours");

    // A manifest that is not one is an error naming it.
    std::fs::write(d.join("f_sequence.json"), "{\"fields\": 3}").expect("manifest");
    let out = qbricks_view(&["render", "f_####.qbk", "-o", "bad/f_####.png"], d);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("f_sequence.json"), "{}", stderr(&out));
    assert!(!d.join("bad/f_0001.png").exists());
}

#[test]
fn field_overrides_change_the_picture_and_unknown_names_fail() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    write_frame(&d.join("one.qbk"), false);
    let render = |extra: &[&str], out: &str| {
        let o = qbricks_view(
            &[
                &[
                    "render",
                    "one.qbk",
                    "-o",
                    out,
                    "--width",
                    "64",
                    "--height",
                    "48",
                    "--overlays",
                    "none",
                ][..],
                // One camera for all: without it each iso field frames its own surface.
                &SMALL[6..],
                extra,
            ]
            .concat(),
            d,
        );
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        png(&d.join(out))
    };
    let base = render(&[], "base.png");
    // Speed grows along x, density along y: other colours on the same surface.
    let by_density = render(&["--colour-field", "density"], "density.png");
    assert_ne!(base, by_density);
    assert_eq!(
        by_density,
        render(&["--color-field", "density"], "density2.png")
    );
    // Naming the default field changes nothing.
    assert_eq!(base, render(&["--colour-field", "speed"], "speed.png"));
    // The iso surface of density (a plane y = 0.5 at the middle of its range) instead of
    // Q's sphere: other pixels hit.
    let hit = |img: &image::RgbImage| -> Vec<bool> {
        let bg = img.get_pixel(0, 0).0;
        img.pixels().map(|p| p.0 != bg).collect()
    };
    let plane = render(&["--iso-field", "density"], "plane.png");
    let changed = hit(&plane)
        .iter()
        .zip(hit(&base))
        .filter(|(a, b)| **a != *b)
        .count();
    assert!(
        changed > 200,
        "the plane should cover other pixels than the sphere ({changed} of 3072 differ)"
    );
    let lower = render(&["--iso-field", "density", "--iso", "0.2"], "plane2.png");
    assert_ne!(plane, lower);

    // Unknown names: one line naming the file and listing the fields, exit 2, no image.
    for (flag, file) in [
        ("--colour-field", "one.qbk"),
        ("--iso-field", "one.qbk"),
        ("--colour-field", "f_####.qbk"),
    ] {
        if file.contains('#') {
            write_frame(&d.join("f_0001.qbk"), false);
        }
        let o = qbricks_view(&["render", file, "-o", "x_####.png", flag, "vorticity"], d);
        assert_eq!(o.status.code(), Some(2), "{flag} {file}");
        let err = stderr(&o);
        let last = err
            .trim_end()
            .lines()
            .last()
            .unwrap_or_default()
            .to_string();
        assert!(
            last.contains(file)
                && last.contains(flag)
                && last.contains("\"vorticity\"")
                && last.contains("q, speed, density"),
            "{err}"
        );
        if !file.contains('#') {
            assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        }
        assert!(!d.join("x_0001.png").exists());
    }
}

#[test]
fn sequence_argument_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    write_frame(&d.join("f_0001.qbk"), false);
    let cases: [(&[&str], &str); 7] = [
        (
            &[
                "render",
                "f_####.qbk",
                "-o",
                "f_####.png",
                "--iso-per-frame",
                "--iso",
                "0.1",
            ],
            "--iso-per-frame takes each frame's own default iso value, --iso gives one",
        ),
        (
            &["render", "f_0001.qbk", "-o", "a.png", "--iso-per-frame"],
            "--iso-per-frame chooses the iso value of each frame of a sequence",
        ),
        (
            &["render", "f_####.qbk", "-o", "one.png"],
            "must be a pattern",
        ),
        (&["render", "f_####.qbk"], "expected -o"),
        (
            &["render", "g_####.qbk", "-o", "g_####.png"],
            "no file matches",
        ),
        (
            &["render", "f_0001.qbk", "-o", "a.png", "--frames", "1..2"],
            "--frames needs a frame sequence",
        ),
        (
            &[
                "render",
                "f_####.qbk",
                "-o",
                "f_####.png",
                "--frames",
                "3..1",
            ],
            "after the last",
        ),
    ];
    for (args, want) in cases {
        let o = qbricks_view(args, d);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
    }
    // Output over the input, frame by frame, is refused for that frame.
    let o = qbricks_view(&["render", "f_####.qbk", "-o", "f_####.qbk"], d);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("would overwrite"), "{}", stderr(&o));
    assert!(format::BrickFileView::open(&d.join("f_0001.qbk")).is_ok());
}

/// Issue 26: a frame whose Q is ten times smaller than the others' lies below the
/// sequence's default iso value (10 % of the sequence's maximum, its own maximum); it
/// takes its own default, said on stderr, and shows the same sphere as the others.
/// `--iso-per-frame` gives every frame its own; a given `--iso` is kept everywhere.
#[test]
fn a_frame_the_sequence_iso_leaves_empty_takes_its_own() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    write_frame_scaled(&d.join("f_0001.qbk"), false, 1.0);
    write_frame_scaled(&d.join("f_0002.qbk"), false, 0.1);
    write_frame_scaled(&d.join("f_0003.qbk"), false, 1.0);
    let run = |extra: &[&str], out: &str| {
        let pattern = format!("{out}/f_####.png");
        let args = [
            &[
                "render",
                "f_####.qbk",
                "-o",
                &pattern,
                "--width",
                "64",
                "--height",
                "48",
                "--overlays",
                "none",
            ][..],
            extra,
        ]
        .concat();
        let o = qbricks_view(&args, d);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        let imgs: Vec<image::RgbImage> = (1..=3)
            .map(|f| png(&d.join(format!("{out}/f_{f:04}.png"))))
            .collect();
        (stderr(&o), imgs)
    };
    let covered = |img: &image::RgbImage| {
        let bg = img.get_pixel(0, 0).0;
        img.pixels()
            .filter(|p| (0..3).any(|c| p.0[c].abs_diff(bg[c]) > 6))
            .count()
    };

    let (err, imgs) = run(&[], "auto");
    assert!(
        err.contains("except a frame it leaves nearly empty"),
        "{err}"
    );
    let line = err
        .lines()
        .find(|l| l.contains("frame 2: iso q = "))
        .unwrap_or_else(|| panic!("no line for frame 2: {err}"));
    assert!(
        line.contains("(the frame's own default; the sequence's "),
        "{line}"
    );
    assert!(
        !err.contains("frame 1: iso") && !err.contains("frame 3: iso"),
        "{err}"
    );
    // One camera on the union of the spheres: frame 2 draws the same sphere.
    assert!(
        err.contains("union of the iso surfaces of 3 frame(s)"),
        "{err}"
    );
    let (c1, c2) = (covered(&imgs[0]), covered(&imgs[1]));
    assert!(c1 > 300, "frame 1 covers {c1} of 3072 pixels");
    assert!(
        c2.abs_diff(c1) * 20 <= c1,
        "frame 2 covers {c2} pixels, frame 1 {c1}"
    );

    let (err, imgs) = run(&["--iso-per-frame"], "per");
    assert!(
        err.contains("each frame's own default (--iso-per-frame)"),
        "{err}"
    );
    for f in 1..=3 {
        assert!(
            err.contains(&format!("frame {f}: iso q = ")),
            "frame {f}: {err}"
        );
    }
    assert!(imgs.iter().all(|i| covered(i) > 300));

    // A given value stays, even where it leaves frame 2 empty: a warning, no switch.
    let (err, imgs) = run(&["--iso", "0.5"], "given");
    assert!(
        err.contains("iso q = 0.5 in every frame, as given"),
        "{err}"
    );
    assert!(!err.contains("own default"), "{err}");
    assert!(
        err.contains("frame 2: the iso value 0.5 is outside the range of q"),
        "{err}"
    );
    assert!(covered(&imgs[0]) > 100);
    assert_eq!(covered(&imgs[1]), 0, "frame 2 at iso 0.5 should be empty");
}
