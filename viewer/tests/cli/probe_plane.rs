//! `qbricks-view probe --plane` from the command line: the three output files against the
//! library's samples (and `.npy` against numpy, when it is installed), the plane's CSV
//! against `probe --points` at the same points, the summary line, and every refusal
//! leaving no output behind.

use std::path::{Path, PathBuf};

use crate::common::qbricks_view;
use qbricks_viewer::probe::plane::{self, PlaneSpec, ResolutionSpec};
use qbricks_viewer::testvol;
use qbricks_viewer::volume::Volume;

/// A two-level test volume (`testvol::nested`, n = 8: data over [-1, 17]³, the fine level
/// over [4, 12]³) with fields `q` and `speed`, written to `dir/t.qbk`.
fn volume_file(dir: &Path) -> PathBuf {
    let q = |p: [f64; 3]| (p[0] / 3.0).sin() * (p[1] / 5.0).cos() + 0.1 * p[2];
    let s = |p: [f64; 3]| 0.05 + 0.001 * p[0] * p[2];
    let file = testvol::nested(8, [0.0; 3], &[("q", &q), ("speed", &s)], 8);
    let path = dir.join("t.qbk");
    format::writer::write(&path, &file).expect("write");
    path
}

fn run(args: &[&str], cwd: &Path) -> (i32, Vec<u8>, String) {
    let out = qbricks_view()
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run");
    (
        out.status.code().unwrap_or(-1),
        out.stdout,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The library's samples of `spec` at `res` in the file.
fn library_samples(file: &Path, spec: &str, res: &str, fields: &[usize]) -> plane::PlaneSamples {
    let view = format::BrickFileView::open(file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    let b = &view.file().bounds;
    let plane = PlaneSpec::parse(spec)
        .expect("spec")
        .resolve(b.min.map(|x| x.to_native()), b.max.map(|x| x.to_native()))
        .expect("plane");
    let res = ResolutionSpec::parse(res)
        .expect("res")
        .resolve(&plane)
        .expect("res");
    plane::sample(&vol, &plane, res, fields).expect("sample")
}

/// The names in `dir` (to see that a refused run left no file, not even a temporary one).
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

const SPEC: &str = "-2,-1.5,6.25:21,0,1:0,19,0";

#[test]
fn plane_files_hold_the_librarys_samples_and_say_their_layout() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = volume_file(dir.path());
    let f = file.to_str().expect("utf8");
    let want = library_samples(&file, SPEC, "11,6", &[1, 0]);
    assert!(want.outside > 0 && want.outside < 66, "{}", want.outside);

    let (code, stdout, err) = run(
        &[
            "probe",
            f,
            "--plane",
            SPEC,
            "--resolution",
            "11,6",
            "--fields",
            "speed,q",
            "-o",
            "p.npy",
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    assert!(stdout.is_empty());
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with("qbricks-view: --plane: 11x6 samples (NU x NV) of speed, q on origin [-2.0, -1.5, 6.25] u [21.0, 0.0, 1.0] v [0.0, 19.0, 0.0], written to p.npy as float32 [j, i, field], shape (6, 11, 2), fields in that order: speed, q; "),
        "{err}"
    );
    assert!(
        err.ends_with(&format!("; {} outside the data (NaN)\n", want.outside)),
        "{err}"
    );
    let npy = std::fs::read(dir.path().join("p.npy")).expect("npy");
    let read = npyz::NpyFile::new(&npy[..]).expect("npy header");
    assert_eq!(read.shape(), [6, 11, 2]);
    let values: Vec<f32> = read.into_vec().expect("values");
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&values), bits(&want.values));

    // numpy reads the same array: shape, dtype, NaN count and every byte.
    let python = Path::new("/usr/bin/python3");
    let has_numpy = std::process::Command::new(python)
        .args(["-c", "import numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if has_numpy {
        let out = std::process::Command::new(python)
            .args([
                "-c",
                "import sys, numpy as np\n\
                 a = np.load(sys.argv[1])\n\
                 print(a.shape, a.dtype.str, int(np.isnan(a[:, :, 0]).sum()))\n\
                 print(a.tobytes().hex())",
                "p.npy",
            ])
            .current_dir(dir.path())
            .output()
            .expect("python3");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8_lossy(&out.stdout);
        let mut lines = text.lines();
        assert_eq!(
            lines.next(),
            Some(format!("(6, 11, 2) <f4 {}", want.outside).as_str())
        );
        let hex: String = want
            .values
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(lines.next(), Some(hex.as_str()));
    } else {
        eprintln!("skipped the numpy check: /usr/bin/python3 cannot import numpy");
    }

    // JSON by extension (every field, the file's order), and CSV by --format whatever the
    // name is.
    let (code, _, err) = run(
        &[
            "probe",
            f,
            "--plane",
            SPEC,
            "--resolution",
            "11,6",
            "-o",
            "p.JSON",
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains("float32"), "{err}");
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("p.JSON")).expect("json"))
            .expect("parse json");
    assert_eq!(j["fields"], serde_json::json!(["q", "speed"]));
    assert_eq!(j["resolution"], serde_json::json!([11, 6]));
    assert_eq!(j["outside"], want.outside);
    let (i, jj) = (7, 4);
    assert_eq!(
        j["values"]["speed"][jj][i].as_f64(),
        Some(f64::from(want.sample(i as u32, jj as u32)[0]))
    );
    let (code, _, err) = run(
        &[
            "probe",
            f,
            "--plane",
            SPEC,
            "--resolution",
            "11,6",
            "--format",
            "csv",
            "-o",
            "plane",
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    let csv = std::fs::read_to_string(dir.path().join("plane")).expect("csv");
    assert_eq!(csv.lines().count(), 1 + 66);
    assert!(csv.starts_with("i,j,x,y,z,q,speed\n0,0,-1.045"), "{csv}");
    assert_eq!(
        names(dir.path()),
        ["p.JSON", "p.npy", "plane", "t.qbk"],
        "no temporary file left"
    );
}

/// The plane's CSV against `probe --points` at the points it printed: the same text for
/// every value, on the level boundaries (x = 4 and 12) and outside the data (NaN).
#[test]
fn plane_csv_matches_probe_points_at_its_points() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = volume_file(dir.path());
    let f = file.to_str().expect("utf8");
    // y=6 over x, z in [-1, 17]: 9 samples a side put x at 0, 2, …, 16.
    let (code, plane_csv, err) = run(
        &["probe", f, "--plane", "y=6", "--resolution", "9"],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    assert!(
        err.starts_with("qbricks-view: --plane: 9x9 samples (NU x NV) of q, speed on origin [-1.0, 6.0, -1.0] u [18.0, 0.0, 0.0] v [0.0, 0.0, 18.0], written to stdout; 0 outside"),
        "{err}"
    );
    let plane_csv = String::from_utf8(plane_csv).expect("utf8");
    let rows: Vec<Vec<&str>> = plane_csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 81);
    assert!(
        rows.iter().any(|r| r[2] == "4"),
        "a sample on the fine level's face"
    );
    // And a few points outside the data, probed as NaN by both.
    let (code, outside, err) = run(
        &[
            "probe",
            f,
            "--plane",
            "-5,3,3:2,0,0:0,1,0",
            "--resolution",
            "2,1",
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("; 2 outside the data (NaN)"), "{err}");
    assert!(
        err.contains("warning: --plane: every sample lies outside the data"),
        "{err}"
    );
    let outside = String::from_utf8(outside).expect("utf8");
    let all: Vec<Vec<&str>> = rows
        .into_iter()
        .chain(outside.lines().skip(1).map(|l| l.split(',').collect()))
        .collect();

    let points: String = all
        .iter()
        .map(|r| format!("{},{},{}\n", r[2], r[3], r[4]))
        .collect();
    std::fs::write(dir.path().join("pts.csv"), points).expect("points");
    let (code, probed, err) = run(&["probe", f, "--points", "pts.csv"], dir.path());
    assert_eq!(code, 0, "{err}");
    let probed = String::from_utf8(probed).expect("utf8");
    let probed: Vec<Vec<&str>> = probed
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(probed.len(), all.len());
    for (p, r) in probed.iter().zip(&all) {
        // probe: x,y,z,q,speed,…; plane: i,j,x,y,z,q,speed.
        assert_eq!(p[..5], r[2..7], "probe {p:?} vs plane {r:?}");
    }
    assert!(all.last().is_some_and(|r| r[5] == "NaN"));
}

#[test]
fn bad_planes_are_refused_and_leave_no_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = volume_file(dir.path());
    let f = file.to_str().expect("utf8");
    let cases: &[(&[&str], &str)] = &[
        (
            &["--plane", "0,0,0:1,0,0", "-o", "o.csv"],
            "qbricks-view: --plane: expected OX,OY,OZ:UX,UY,UZ:VX,VY,VZ (an origin and two edge vectors) or x=C, y=C, z=C, found `0,0,0:1,0,0`",
        ),
        (
            &["--plane", "0,0,0:0,0,0:0,1,0", "-o", "o.csv"],
            "qbricks-view: --plane: U [0.0, 0.0, 0.0] has zero length",
        ),
        (
            &["--plane", "0,0,0:1,1,0:2,2,0", "-o", "o.npy"],
            "qbricks-view: --plane: U [1.0, 1.0, 0.0] and V [2.0, 2.0, 0.0] are parallel: they span no plane",
        ),
        (
            &["--plane", "0,0,0:1,0,0:0,nan,0", "-o", "o.csv"],
            "qbricks-view: --plane: V: expected a finite number, found `nan`",
        ),
        (
            &["--plane", "z=inf", "-o", "o.csv"],
            "qbricks-view: --plane: z=inf: expected a finite coordinate",
        ),
        (
            &["--plane", "z=1", "--resolution", "16385,4", "-o", "o.csv"],
            "qbricks-view: --resolution: expected 1..=16384, found 16385",
        ),
        (
            &["--plane", "z=1", "--resolution", "0", "-o", "o.csv"],
            "qbricks-view: --resolution: expected 1..=16384, found 0",
        ),
        (
            &["--plane", "z=1", "--resolution", "8x8", "-o", "o.csv"],
            "qbricks-view: --resolution: expected NU,NV or N (whole numbers of samples), found `8x8`",
        ),
        (
            &["--plane", "z=1", "--fields", "q,nope", "-o", "o.csv"],
            "qbricks-view: t.qbk: --fields: no field named \"nope\" (fields: q, speed)",
        ),
        (
            &["--plane", "z=1", "--fields", "q,speed,q", "-o", "o.csv"],
            "qbricks-view: t.qbk: --fields: \"q\" is named twice",
        ),
        (
            &["--plane", "z=1", "-o", "o.txt"],
            "qbricks-view: -o o.txt: no format is named .txt: name the file .csv, .json or .npy, or give --format",
        ),
        (
            &["--plane", "z=1", "--format", "npy", "-o", "o.csv"],
            "qbricks-view: -o o.csv: the name says csv but --format says npy",
        ),
        (
            &["--plane", "z=1", "--json", "-o", "o.npy"],
            "qbricks-view: -o o.npy: the name says npy but --format (--json) says json",
        ),
        (
            &["--plane", "z=1", "--format", "npy"],
            "qbricks-view: --format npy: the array is binary; give -o FILE.npy (or -o /dev/stdout)",
        ),
        (
            &["--plane", "z=1", "-o", "t.qbk"],
            "qbricks-view: t.qbk: -o would overwrite the brick file t.qbk, an input of this run",
        ),
    ];
    let before = std::fs::read(&file).expect("read");
    for (args, message) in cases {
        let mut all = vec!["probe", "t.qbk"];
        all.extend_from_slice(args);
        let (code, stdout, err) = run(&all, dir.path());
        assert_eq!(code, 2, "{all:?}: {err}");
        assert!(stdout.is_empty(), "{all:?}");
        assert_eq!(err.trim_end(), *message, "{all:?}");
        assert_eq!(names(dir.path()), ["t.qbk"], "{all:?} left a file");
    }
    assert_eq!(
        std::fs::read(&file).expect("read"),
        before,
        "the input is intact"
    );
    // Flags that clash with --plane: clap's usage error.
    for args in [
        &["probe", f, "--plane", "z=1", "--line", "0,0,0:1,1,1:3"][..],
        &["probe", f, "--plane", "z=1", "--points", "pts.csv"],
        &["probe", f, "--plane", "z=1", "--field", "q"],
        &["probe", f, "--plane", "z=1", "--json", "--format", "csv"],
        &["probe", f, "--resolution", "4"],
    ] {
        let (code, _, err) = run(args, dir.path());
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.starts_with("error: "), "{args:?}: {err}");
    }
    // Flags that mean something only with --plane are refused with the others too.
    for flag in [
        &["--resolution", "4"][..],
        &["--fields", "q"],
        &["-o", "x.csv"],
        &["--format", "csv"],
    ] {
        for input in [&["--line", "0,0,0:1,1,1:3"][..], &["--points", "pts.csv"]] {
            let args = [&["probe", f][..], input, flag].concat();
            let (code, stdout, err) = run(&args, dir.path());
            assert_eq!(code, 2, "{args:?}: {err}");
            assert!(stdout.is_empty(), "{args:?}");
            assert_eq!(
                err,
                format!(
                    "qbricks-view: {} is for --plane; --points and --line print their report on stdout\n",
                    flag[0]
                )
            );
        }
    }
    assert_eq!(names(dir.path()), ["t.qbk"]);
}
