//! Measures the reader on a file of at least 1 GiB: open time with and without the
//! checksum, the split into checksum / rkyv validation / schema checks, and resident
//! memory right after open. Each open runs in a fresh child process so that RSS is not
//! polluted by the writer.
//!
//! ```sh
//! cargo run --release -p qbricks-format --example bigfile -- [DIR] [GIB] [--cold]
//! ```
//! Writes `DIR/bigfile.qbk` (default: the system temp dir, 1 GiB of values), measures,
//! and deletes it. `--cold` drops the file's pages from the page cache before each open
//! (with GNU `dd iflag=nocache`), so the open reads from disk.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use qbricks_format::header::{checksum, HEADER_LEN};
use qbricks_format::kd::BuildNode;
use qbricks_format::{
    query, validate, writer, Aabb, ArchivedBrickFile, Brick, BrickFile, BrickFileView, Field,
    Level, OpenOptions, Provenance, Region, ValueRange,
};

const DIM: u32 = 8; // cells per brick axis

fn build(gib: f64) -> BrickFile {
    let fields = 2usize;
    let cells_per_brick = (DIM * DIM * DIM) as u64;
    let want_bytes = gib * (1u64 << 30) as f64;
    let bricks_wanted = (want_bytes / (fields as f64 * 4.0 * cells_per_brick as f64)).ceil();
    // Bricks on an n x n x m lattice, one region per brick, balanced KD-tree.
    let n = (bricks_wanted.cbrt().ceil() as u32).max(1);
    let m = ((bricks_wanted / f64::from(n * n)).ceil() as u32).max(1);
    let w = 1.0;
    let mut bricks = Vec::new();
    let mut regions = Vec::new();
    let mut boxes = Vec::new();
    let mut first_value = 0u64;
    for z in 0..m {
        for y in 0..n {
            for x in 0..n {
                let origin = [x, y, z].map(|c| f64::from(c * DIM) * w);
                bricks.push(Brick {
                    level: 0,
                    origin,
                    cell_width: w,
                    inv_cell_width: 1.0 / w,
                    dims: [DIM; 3],
                    first_value,
                });
                let lo = origin.map(|c| c - 0.5 * w);
                boxes.push(Aabb {
                    min: lo,
                    max: lo.map(|c| c + f64::from(DIM) * w),
                });
                regions.push(Region {
                    bricks_start: regions.len() as u32,
                    bricks_len: 1,
                });
                first_value += cells_per_brick;
            }
        }
    }
    let n_bricks = bricks.len();
    let values = |f: usize| -> Vec<f32> {
        (0..first_value)
            .map(|i| ((i as f32) * 1e-3 + f as f32).sin())
            .collect()
    };
    let mut built = Vec::new();
    let ids: Vec<u32> = (0..n_bricks as u32).collect();
    build_kd(&boxes, ids, &mut built);
    let (kd_root, kd_nodes, kd_axes) = qbricks_format::kd::pack(&built);
    let extent = [n, n, m].map(|c| f64::from(c * DIM) * w - 0.5 * w);
    BrickFile {
        provenance: Provenance {
            source: "bigfile.vdb".into(),
            grids: vec![],
            bake_options: "{}".into(),
            tool_version: "bench".into(),
        },
        bounds: Aabb {
            min: [-0.5 * w; 3],
            max: extent,
        },
        levels: vec![Level {
            cell_width: w,
            cells: first_value,
            bricks: n_bricks as u32,
        }],
        fields: (0..fields)
            .map(|f| Field {
                name: format!("f{f}"),
                min: -1.0,
                max: 1.0,
                histogram: vec![0; 64],
                values: values(f),
            })
            .collect(),
        region_bricks: (0..n_bricks as u32).collect(),
        region_ranges: vec![
            ValueRange {
                min: -1.0,
                max: 1.0
            };
            n_bricks * fields
        ],
        bricks,
        regions,
        kd_root,
        kd_nodes,
        kd_axes,
    }
}

/// Median split on the widest axis of the region centres; returns the node index.
fn build_kd(boxes: &[Aabb], mut ids: Vec<u32>, nodes: &mut Vec<BuildNode>) -> u32 {
    let at = nodes.len() as u32;
    nodes.push(BuildNode::Leaf { region: None });
    if ids.len() == 1 {
        nodes[at as usize] = BuildNode::Leaf {
            region: Some(ids[0]),
        };
        return at;
    }
    let lo = |i: u32, a: usize| boxes[i as usize].min[a];
    let spread = |a: usize| {
        let (mn, mx) = ids.iter().fold((f64::MAX, f64::MIN), |(mn, mx), &i| {
            (mn.min(lo(i, a)), mx.max(lo(i, a)))
        });
        mx - mn
    };
    let axis = (0..3)
        .max_by(|&a, &b| spread(a).total_cmp(&spread(b)))
        .unwrap_or(0);
    ids.sort_by(|&a, &b| lo(a, axis).total_cmp(&lo(b, axis)));
    let mid = ids.len() / 2;
    let split = lo(ids[mid], axis);
    let right_ids = ids.split_off(mid);
    let left = build_kd(boxes, ids, nodes);
    let right = build_kd(boxes, right_ids, nodes);
    nodes[at as usize] = BuildNode::Inner {
        axis: axis as u8,
        split,
        left,
        right,
    };
    at
}

fn status(key: &str) -> String {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key))
                .map(|l| l[key.len()..].trim().to_owned())
        })
        .unwrap_or_else(|| "?".into())
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Child process: one open, then the split of its work, RSS in between.
fn measure_open(path: &Path, verify: bool) {
    let rss_before = status("VmRSS:");
    let t = Instant::now();
    let view = BrickFileView::open_with(
        path,
        &OpenOptions {
            verify_checksum: verify,
            ..OpenOptions::default()
        },
    )
    .expect("open");
    let open_ms = ms(t);
    let rss = status("VmRSS:");
    let (anon, file) = (status("RssAnon:"), status("RssFile:"));
    let gb = view.byte_len() as f64 / 1e9;
    println!(
        "open (checksum {}): {open_ms:.1} ms = {:.2} GB/s; VmRSS before {rss_before}, after {rss} (RssAnon {anon}, RssFile {file})",
        if verify { "on " } else { "off" },
        gb / (open_ms / 1e3)
    );
    // `file()` is a stored reference: time a million calls.
    let t = Instant::now();
    let mut acc = 0usize;
    for _ in 0..1_000_000 {
        acc = acc.wrapping_add(std::hint::black_box(view.file()).bricks.len());
    }
    let file_ns = t.elapsed().as_secs_f64() * 1e3;
    println!("  view.file(): {file_ns:.3} ns per call ({acc})");
    if !verify {
        return;
    }
    // Split of the work (pages are warm now).
    let payload = view.payload();
    let t = Instant::now();
    let sum = checksum(payload);
    let c_ms = ms(t);
    let t = Instant::now();
    let archived =
        rkyv::access::<ArchivedBrickFile, rkyv::rancor::Error>(payload).expect("bytecheck");
    let a_ms = ms(t);
    let t = Instant::now();
    validate::check(archived).expect("schema");
    let v_ms = ms(t);
    let pgb = payload.len() as f64 / 1e9;
    println!(
        "  checksum xxh3 {c_ms:.1} ms ({:.2} GB/s, {sum:#x}); rkyv bytecheck {a_ms:.1} ms ({:.2} GB/s); schema checks {v_ms:.1} ms",
        pgb / (c_ms / 1e3),
        pgb / (a_ms / 1e3)
    );
    let t = Instant::now();
    let b = query::bounds(archived);
    let mut hits = 0usize;
    for i in 0..100_000 {
        let f = i as f64 / 100_000.0;
        let p = [0, 1, 2].map(|a| b.min[a] + (b.max[a] - b.min[a]) * f);
        hits += usize::from(query::region_at(archived, p).is_some());
    }
    println!(
        "  region_at: {:.0} ns per query ({hits} hits)",
        t.elapsed().as_secs_f64() * 1e9 / 1e5
    );
    let _ = HEADER_LEN;
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("--child") {
        let path = PathBuf::from(&args[2]);
        measure_open(&path, args[3] == "on");
        return;
    }
    let dir = args
        .get(1)
        .map(PathBuf::from)
        .unwrap_or_else(std::env::temp_dir);
    let gib: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let path = dir.join("bigfile.qbk");

    let t = Instant::now();
    let file = build(gib);
    println!(
        "built {} bricks, {} regions, {} KD nodes in {:.1} s",
        file.bricks.len(),
        file.regions.len(),
        file.kd_nodes.len(),
        t.elapsed().as_secs_f64()
    );
    let t = Instant::now();
    let bytes = writer::write(&path, &file).expect("write");
    let s = t.elapsed().as_secs_f64();
    println!(
        "wrote {} ({bytes} bytes = {:.2} GiB) in {s:.1} s ({:.2} GB/s incl. fsync)",
        path.display(),
        bytes as f64 / (1u64 << 30) as f64,
        bytes as f64 / 1e9 / s
    );
    drop(file);

    let exe = std::env::current_exe().expect("exe");
    let cold = args.iter().any(|a| a == "--cold");
    for verify in ["on", "off", "on"] {
        if cold {
            // Drop this file's pages from the page cache (GNU dd: POSIX_FADV_DONTNEED).
            let dropped = Command::new("dd")
                .args([
                    &format!("if={}", path.display()),
                    "iflag=nocache",
                    "count=0",
                    "status=none",
                ])
                .status()
                .is_ok_and(|s| s.success());
            println!("(page cache for the file dropped: {dropped})");
        }
        let status = Command::new(&exe)
            .args(["--child", path.to_str().expect("utf8"), verify])
            .status()
            .expect("child");
        assert!(status.success());
    }
    std::fs::remove_file(&path).expect("delete the big file");
    println!("deleted {}", path.display());
}
