//! A baked frame sequence rendered with one view (issue 15): the bundled cache baked with
//! `qbricks-bake`, then `qbricks-view render 'out/frame_####.qbk' -o 'png/frame_####.png'`
//! with a missing and a corrupt frame in the middle — the others finish, the failures are
//! named, the exit code is 2, and no partial image is left.

use crate::common;
use std::path::Path;
use std::process::{Command, Output};

use serde_json::Value;

fn run(bin: &str, args: &[&str], dir: &Path) -> Output {
    Command::new(common::bin(bin))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("run")
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|r| {
            r.map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn bundled_cache_with_a_missing_and_a_corrupt_frame() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path();
    let cache = common::root().join("data/cache/fluid_data_####.vdb");
    let o = run(
        "qbricks-bake",
        &[
            "bake",
            &cache.display().to_string(),
            "-o",
            "out/frame_####.qbk",
            "--fields",
            "q,speed,density",
            "--quiet",
        ],
        dir,
    );
    assert!(o.status.success(), "{o:?}");
    // Frame 2 gone, frame 3 damaged (one byte of its payload: the checksum catches it).
    std::fs::remove_file(dir.join("out/frame_0002.qbk")).expect("rm");
    let bad = dir.join("out/frame_0003.qbk");
    let mut bytes = std::fs::read(&bad).expect("read");
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x5a;
    std::fs::write(&bad, &bytes).expect("write");

    let view = |extra: &[&str], png: &str| {
        let pattern = format!("{png}/frame_####.png");
        let args = [
            &[
                "render",
                "out/frame_####.qbk",
                "-o",
                &pattern,
                "--width",
                "96",
                "--height",
                "72",
                "--colour-field",
                "density",
            ][..],
            extra,
        ]
        .concat();
        run("qbricks-view", &args, dir)
    };

    // Every frame of 1..4 is asked for: 2 is missing, 3 corrupt, 1 and 4 are drawn.
    let o = view(&["--frames", "1..4", "--json"], "png");
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("field ranges of the whole sequence from out/frame_sequence.json"),
        "{err}"
    );
    assert!(err.contains("out/frame_0002.qbk: no such file"), "{err}");
    assert!(
        err.lines()
            .any(|l| l.starts_with("qbricks-view: out/frame_0003.qbk: ") && l.contains("checksum")),
        "{err}"
    );
    let last = err.trim_end().lines().last().unwrap_or_default();
    assert_eq!(
        last,
        "qbricks-view: out/frame_####.qbk: 2 of 4 frames failed: out/frame_0002.qbk, out/frame_0003.qbk"
    );
    assert_eq!(
        names(&dir.join("png")),
        ["frame_0001.png", "frame_0004.png"]
    );
    // One JSON report per frame, in order; the failed ones carry their error.
    let lines: Vec<Value> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect();
    assert_eq!(lines.len(), 4);
    for (i, l) in lines.iter().enumerate() {
        assert_eq!(l["frame"], i as u64 + 1);
        let failed = i == 1 || i == 2;
        assert_eq!(l.get("error").is_some(), failed, "{l}");
        assert_eq!(l.get("rays").is_some(), !failed, "{l}");
    }
    assert_eq!(lines[0]["width"], 96);
    assert_eq!(lines[3]["output"], "png/frame_0004.png");

    // Without --frames the existing files are the sequence: the gap is a warning, the
    // corrupt frame still fails.
    let o = view(&[], "png2");
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("warning: out/frame_####.qbk: 1 frame(s) missing: 2"),
        "{err}"
    );
    assert!(
        err.contains("1 of 3 frames failed: out/frame_0003.qbk"),
        "{err}"
    );
    assert_eq!(
        names(&dir.join("png2")),
        ["frame_0001.png", "frame_0004.png"]
    );

    // The images are the same as a clean run's: one view state for the sequence, whatever
    // failed around a frame.
    std::fs::write(&bad, {
        bytes[mid] ^= 0x5a;
        &bytes
    })
    .expect("repair");
    let o = view(&["--frames", "3..4"], "png3");
    assert!(o.status.success(), "{o:?}");
    assert_eq!(
        std::fs::read(dir.join("png/frame_0004.png")).expect("png"),
        std::fs::read(dir.join("png3/frame_0004.png")).expect("png")
    );
    // The smoke shows: the surface is coloured, not the background alone.
    let img = image::open(dir.join("png3/frame_0003.png"))
        .expect("png")
        .to_rgb8();
    let bg = img.get_pixel(0, 0).0;
    assert!(img.pixels().filter(|p| p.0 != bg).count() > 50);
}
