//! `qbricks-view info` on a written file: JSON keys and values, text, bad files.

use std::path::Path;

use crate::common::qbricks_view;

use format::{Aabb, Brick, BrickFile, Field, Level, Provenance, Region, ValueRange};

fn sample() -> BrickFile {
    // Two levels: a 4x2x1 brick of width 0.5 and a 1x1x1 brick of width 1.
    BrickFile {
        provenance: Provenance {
            source: "wake_small.vdb".into(),
            grids: vec![],
            bake_options: "{}".into(),
            tool_version: "0.1.0".into(),
        },
        bounds: Aabb {
            min: [-0.5, -0.5, -0.5],
            max: [3.0, 1.0, 0.5],
        },
        levels: vec![
            Level {
                cell_width: 0.5,
                cells: 8,
                bricks: 1,
            },
            Level {
                cell_width: 1.0,
                cells: 1,
                bricks: 1,
            },
        ],
        fields: vec![
            Field {
                name: "q".into(),
                min: -0.25,
                max: 4.0,
                histogram: vec![3, 6],
                values: vec![1.0; 9],
            },
            Field {
                name: "speed".into(),
                min: 0.0,
                max: 2.5,
                histogram: vec![],
                values: vec![2.0; 9],
            },
        ],
        bricks: vec![
            Brick {
                level: 0,
                origin: [0.0; 3],
                cell_width: 0.5,
                inv_cell_width: 1.0 / 0.5,
                dims: [4, 2, 1],
                first_value: 0,
            },
            Brick {
                level: 1,
                origin: [2.0, 0.0, 0.0],
                cell_width: 1.0,
                inv_cell_width: 1.0,
                dims: [1, 1, 1],
                first_value: 8,
            },
        ],
        // One region, the whole bounds: the tree is a lone leaf.
        regions: vec![Region {
            bricks_start: 0,
            bricks_len: 2,
        }],
        region_bricks: vec![0, 1],
        region_ranges: vec![ValueRange { min: 0.0, max: 4.0 }; 2],
        kd_root: format::kd::leaf_ref(Some(0)),
        kd_nodes: vec![],
        kd_axes: vec![],
    }
}

fn view(args: &[&str]) -> std::process::Output {
    qbricks_view()
        .args(args)
        .output()
        .expect("run qbricks-view")
}

fn write_sample(dir: &Path) -> (std::path::PathBuf, u64) {
    let path = dir.join("sample.qbk");
    let n = format::writer::write(&path, &sample()).expect("write");
    (path, n)
}

#[test]
fn info_json_has_the_documented_keys_and_values() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (path, bytes) = write_sample(dir.path());
    let out = view(&["info", path.to_str().expect("utf8"), "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    for key in [
        "format_version",
        "bytes",
        "cells",
        "bricks",
        "regions",
        "kd_nodes",
        "levels",
        "bounds_min",
        "bounds_max",
        "fields",
        "source",
    ] {
        assert!(j.get(key).is_some(), "missing key {key}: {j}");
    }
    assert_eq!(j["format_version"], format::FORMAT_VERSION);
    assert_eq!(j["bytes"], bytes);
    assert_eq!(j["cells"], 9);
    assert_eq!(j["bricks"], 2);
    assert_eq!(j["regions"], 1);
    assert_eq!(j["kd_nodes"], 0);
    assert_eq!(j["source"], "wake_small.vdb");
    assert_eq!(j["bounds_min"], serde_json::json!([-0.5, -0.5, -0.5]));
    assert_eq!(j["bounds_max"], serde_json::json!([3.0, 1.0, 0.5]));
    assert_eq!(
        j["levels"],
        serde_json::json!([
            {"level": 0, "cell_width": 0.5, "cells": 8, "bricks": 1},
            {"level": 1, "cell_width": 1.0, "cells": 1, "bricks": 1},
        ])
    );
    let fields = j["fields"].as_array().expect("fields");
    assert_eq!(fields.len(), 2);
    assert_eq!(fields[0]["name"], "q");
    assert_eq!(fields[0]["min"], -0.25);
    assert_eq!(fields[0]["max"], 4.0);
    assert_eq!(fields[1]["name"], "speed");
    assert_eq!(fields[1]["max"], 2.5);
    assert_eq!(j["checksum_verified"], true);

    let out = view(&[
        "info",
        path.to_str().expect("utf8"),
        "--json",
        "--no-checksum",
    ]);
    assert!(out.status.success());
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(j["checksum_verified"], false);
}

#[test]
fn info_text_mentions_the_counts() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (path, _) = write_sample(dir.path());
    let out = view(&["info", path.to_str().expect("utf8")]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).expect("utf8");
    assert!(text.contains("9 cells in 2 bricks"), "{text}");
    assert!(text.contains("wake_small.vdb"), "{text}");
    assert!(text.contains("speed: min 0, max 2.5"), "{text}");
}

#[test]
fn info_on_bad_or_missing_files_exits_2_with_one_line_naming_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (path, _) = write_sample(dir.path());
    let good = std::fs::read(&path).expect("read");

    let truncated = dir.path().join("truncated.qbk");
    std::fs::write(&truncated, &good[..good.len() - 3]).expect("write");
    let mut newer = good.clone();
    newer[8] = 9;
    let future = dir.path().join("future.qbk");
    std::fs::write(&future, &newer).expect("write");
    let mut flipped = good.clone();
    let last = flipped.len() - 20;
    flipped[last] ^= 0xFF;
    let corrupt = dir.path().join("corrupt.qbk");
    std::fs::write(&corrupt, &flipped).expect("write");
    let missing = dir.path().join("missing.qbk");

    for (file, expect) in [
        (&truncated, "expected"),
        (&future, "version 9"),
        (&corrupt, "checksum"),
        (&missing, "missing.qbk"),
    ] {
        let out = view(&["info", file.to_str().expect("utf8"), "--json"]);
        assert_eq!(out.status.code(), Some(2), "{}", file.display());
        assert!(out.stdout.is_empty());
        let err = String::from_utf8(out.stderr).expect("utf8");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.starts_with("qbricks-view: "), "{err}");
        let name = file.file_name().expect("name").to_str().expect("utf8");
        assert!(err.contains(name) && err.contains(expect), "{err}");
    }
}
