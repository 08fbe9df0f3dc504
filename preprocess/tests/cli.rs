//! The `qbricks-bake` commands from the command line: `--help`, `bake --json` against the
//! file it wrote, exit code 2 with a one-line message naming the file on bad input, and
//! the moved `synth` and `accuracy` (now `qbricks-lab`'s) saying where they went. (The hostile cases shared with
//! `qbricks-view` are the table in the root `tests/cross_crate/cli_cases.rs`.)

mod common;

use std::process::Output;

use common::qbricks_bake;
use format::BrickFileView;

fn run(args: &[&str]) -> Output {
    qbricks_bake()
        .args(args)
        .output()
        .expect("run qbricks-bake")
}

#[test]
fn help_lists_every_subcommand() {
    let out = run(&["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for sub in ["inspect", "bake"] {
        assert!(text.contains(sub), "--help lacks {sub}:\n{text}");
    }
}

#[test]
fn bake_json_summary_matches_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("tiny.vdb");
    std::fs::copy(common::root().join("data/wake_small.vdb"), &vdb).expect("copy sample");

    let out = qbricks_bake()
        .arg("bake")
        .arg(&vdb)
        .args([
            "--json",
            "--fields",
            "q,speed,velocity",
            "--stencil",
            "cross-level",
        ])
        .output()
        .expect("run bake");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    let mut keys: Vec<&str> = v
        .as_object()
        .expect("object")
        .keys()
        .map(|k| k.as_str())
        .collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "bricks",
            "dropped_cells",
            "fields",
            "input_cells",
            "kd_nodes",
            "leaf_cells",
            "nonfinite",
            "nonfinite_derived",
            "output",
            "peak_memory",
            "regions",
            "seconds"
        ]
    );
    let qbk = dir.path().join("tiny.qbk");
    assert_eq!(v["output"].as_str(), Some(qbk.to_str().expect("utf8")));
    let view = BrickFileView::open(&qbk).expect("open baked file");
    let f = view.file();
    assert_eq!(v["bricks"].as_u64(), Some(f.bricks.len() as u64));
    assert_eq!(v["regions"].as_u64(), Some(f.regions.len() as u64));
    assert_eq!(v["kd_nodes"].as_u64(), Some(f.kd_nodes.len() as u64));
    let leaf = v["leaf_cells"].as_u64().expect("leaf_cells");
    assert_eq!(leaf, f.fields[0].values.len() as u64);
    assert_eq!(
        v["input_cells"].as_u64(),
        Some(leaf + v["dropped_cells"].as_u64().expect("dropped"))
    );
    let names: Vec<&str> = v["fields"]
        .as_array()
        .expect("fields")
        .iter()
        .map(|f| f["name"].as_str().expect("name"))
        .collect();
    assert_eq!(
        names,
        ["q", "speed", "velocity_x", "velocity_y", "velocity_z"]
    );
    assert_eq!(f.provenance.source.as_str(), "tiny.vdb");
    assert_eq!(f.provenance.grids.len(), 3);
}

/// A missing input (`inspect`, `bake`), an output over the input and an unknown grid: one
/// line naming the file, exit code 2.
#[test]
fn bake_and_inspect_errors_are_one_line_naming_the_file_with_exit_2() {
    for sub in ["inspect", "bake"] {
        let out = run(&[sub, "/nonexistent/dir/flow.vdb"]);
        assert_eq!(out.status.code(), Some(2), "{sub}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{sub}: {err}");
        assert!(err.contains("/nonexistent/dir/flow.vdb"), "{sub}: {err}");
    }

    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("tiny.vdb");
    std::fs::copy(common::root().join("data/wake_small.vdb"), &vdb).expect("copy sample");
    for args in [
        vec!["-o", vdb.to_str().expect("utf8")],
        vec!["--grid", "nope"],
    ] {
        let out = qbricks_bake()
            .arg("bake")
            .arg(&vdb)
            .args(&args)
            .output()
            .expect("run bake");
        assert_eq!(out.status.code(), Some(2));
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains("tiny.vdb"), "{err}");
    }
}

#[test]
fn moved_commands_exit_2_naming_qbricks_lab() {
    for sub in ["synth", "accuracy"] {
        let out = run(&[sub, "wake", "--n0", "16", "-o", "x.vdb"]);
        assert_eq!(out.status.code(), Some(2), "{sub}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{sub}: {err}");
        assert!(
            err.contains(&format!("moved: run `qbricks-lab {sub}")),
            "{sub}: {err}"
        );
    }
}

/// A bake gives the memory its stages free back before the next stage allocates (the
/// decoded leaves as they become cells, the input values once they are fields) and keeps a
/// single-precision velocity single: its peak is the fields' derivation, about 26 bytes a
/// cell on a dense 160³ velocity grid (4.1 M cells, 106 MB). It held 47 when freed leaves
/// stayed in the allocator's heaps, and 37 with the velocity widened to f64.
/// Memory is measured, not time: the bake's own peak resident memory.
#[test]
fn bake_peak_memory_stays_near_its_cells() {
    use qbricks_preprocess::grid::AnyGrid;
    use qbricks_preprocess::vdb::write::{write_vdb, Compression};
    let dir = tempfile::tempdir().expect("tempdir");
    let (vdb, qbk) = (dir.path().join("abc.vdb"), dir.path().join("abc.qbk"));
    // The ABC flow on 160³ cells of [0, 2π)³.
    let grid = abc_grid("vel", std::f64::consts::TAU / 160.0, 0, 160);
    write_vdb(&vdb, &[AnyGrid::Vec3s(grid)], Compression::Zip).expect("write");
    let peak = bake_peak(&vdb, &qbk, &[]);
    assert!(qbk.exists());
    let cells = 160.0f64.powi(3);
    let per_cell = peak as f64 / cells;
    // 25.8 measured: 12 bytes of single-precision velocity and 8 of fields a cell, and a
    // fixed 20 MB. Widening the velocity to f64, or holding the decoded leaves beside the
    // cells, gave 37. (That the VDB file's pages go once decoded, and that fields go to
    // disk past 256 MiB, show only on larger bakes: `vdb::mapped` and
    // `fields_kept_on_disk_give_the_same_file` test those.)
    assert!(per_cell < 30.0, "{per_cell:.1} bytes a cell at the peak");
}

/// Bakes `vdb` into `qbk` with `args` on two threads (the allocator keeps an arena per
/// thread: fixed, so a bound holds on any machine) and returns the bake's peak resident
/// memory as it reports it (`peak_memory` of `--json`: its own `VmHWM`; `wait4` would count
/// what this test process held when it started the bake, while other tests ran in it).
fn bake_peak(vdb: &std::path::Path, qbk: &std::path::Path, args: &[&str]) -> u64 {
    let out = qbricks_bake()
        .arg("bake")
        .arg(vdb)
        .arg("-o")
        .arg(qbk)
        .arg("--json")
        .args(args)
        .env("RAYON_NUM_THREADS", "2")
        .output()
        .expect("run qbricks-bake");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    v["peak_memory"].as_u64().expect("peak_memory")
}

/// The ABC flow on a grid of `n³` cells of width `h` from index `lo` on, sampled at the
/// cell centres (`translation` h/2), single precision.
fn abc_grid(name: &str, h: f64, lo: i32, n: i32) -> qbricks_preprocess::grid::Grid<[f32; 3]> {
    use qbricks_preprocess::grid::{Grid, Leaf, Transform, LEAF_VOXELS};
    let mut leaves = Vec::new();
    for x in (lo..lo + n).step_by(8) {
        for y in (lo..lo + n).step_by(8) {
            for z in (lo..lo + n).step_by(8) {
                let values = Box::new(std::array::from_fn::<_, LEAF_VOXELS, _>(|k| {
                    let p = [
                        x + (k >> 6) as i32,
                        y + ((k >> 3) & 7) as i32,
                        z + (k & 7) as i32,
                    ]
                    .map(|i| (f64::from(i) + 0.5) * h);
                    [
                        (p[2].sin() + p[1].cos()) as f32,
                        (p[0].sin() + p[2].cos()) as f32,
                        (p[1].sin() + p[0].cos()) as f32,
                    ]
                }));
                leaves.push(Leaf {
                    origin: [x, y, z],
                    active: [u64::MAX; 8],
                    values,
                });
            }
        }
    }
    Grid {
        name: name.into(),
        transform: Transform {
            voxel_size: [h; 3],
            translation: [0.5 * h; 3],
        },
        background: [0.0; 3],
        leaves,
        tiles: Vec::new(),
    }
}

/// `--memory`: a bake kept within a budget a third of what it takes unbudgeted keeps its
/// values on disk, stays under the budget and a fixed overhead (its peak resident memory),
/// and
/// writes the same file byte for byte; here on two levels whose boundary runs through the
/// coarse grid's blocks, a staggered velocity and an extra scalar field. A budget below
/// what the structure alone needs is refused naming the least that would do, and no file
/// is written.
#[test]
fn a_bake_within_a_memory_budget_stays_under_it_and_writes_the_same_file() {
    use qbricks_preprocess::grid::{AnyGrid, Grid};
    use qbricks_preprocess::vdb::write::{write_vdb, Compression};
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("two.vdb");
    let h = std::f64::consts::TAU / 128.0;
    let coarse = abc_grid("vel", h, 0, 128);
    // Fine cells over coarse cells 36..100: the level boundary cuts coarse blocks.
    let fine = abc_grid("vel", 0.5 * h, 72, 128);
    let density = Grid {
        name: "density".to_string(),
        transform: coarse.transform,
        background: 0.0f32,
        leaves: coarse
            .leaves
            .iter()
            .map(|l| qbricks_preprocess::grid::Leaf {
                origin: l.origin,
                active: l.active,
                values: Box::new(l.values.map(|v| v[0] * v[1])),
            })
            .collect(),
        tiles: Vec::new(),
    };
    let grids = [
        AnyGrid::Vec3s(coarse),
        AnyGrid::Vec3s(fine),
        AnyGrid::Float(density),
    ];
    write_vdb(&vdb, &grids, Compression::Zip).expect("write");
    drop(grids);
    let bake = |out: &str, extra: &[&str]| {
        let qbk = dir.path().join(out);
        let args = [
            &["--layout", "staggered", "--fields", "q,speed,density"],
            extra,
        ]
        .concat();
        let peak = bake_peak(&vdb, &qbk, &args);
        (peak, std::fs::read(&qbk).expect("written"))
    };
    let (free_peak, free) = bake("free.qbk", &[]);
    let budget = 64u64 << 20;
    let (peak, within) = bake("within.qbk", &["--memory", "64M"]);
    eprintln!(
        "peak {} MiB unbudgeted, {} MiB within --memory 64M",
        free_peak >> 20,
        peak >> 20
    );
    assert!(free_peak > 3 * budget, "{free_peak}");
    assert!(within == free, "the budgeted bake wrote another file");
    // Within the budget and the fixed overhead the docs state (the program, its threads'
    // stacks, the pages the kernel maps around faults): 45-53 MiB measured, and 25-32 MiB
    // at budgets of 16 to 24 MiB, run to run.
    assert!(peak <= budget + (16 << 20), "{} MiB", peak >> 20);
    // The least budget: every value and the regions and KD-tree in scratch files.
    let (least_peak, least) = bake("least.qbk", &["--memory", "16M"]);
    eprintln!("peak {} MiB within --memory 16M", least_peak >> 20);
    assert!(least == free, "the bake within 16M wrote another file");
    assert!(
        least_peak <= (16 << 20) + (16 << 20),
        "{} MiB",
        least_peak >> 20
    );

    // An uncompressed grid of 49 MB, whose pages the reader maps: locating its leaves walks
    // every buffer, so the pages walked must go behind the walk well within a small budget
    // (64 MiB of them were held before they went: 42 MiB peaks at a budget of 24M).
    let raw = dir.path().join("raw.vdb");
    let grid = abc_grid("vel", std::f64::consts::TAU / 160.0, 0, 160);
    write_vdb(&raw, &[AnyGrid::Vec3s(grid)], Compression::None).expect("write");
    let small = 20u64 << 20;
    let raw_peak = bake_peak(&raw, &dir.path().join("raw.qbk"), &["--memory", "20M"]);
    eprintln!(
        "peak {} MiB within --memory 20M, 49 MB uncompressed",
        raw_peak >> 20
    );
    assert!(raw_peak <= small + (16 << 20), "{} MiB", raw_peak >> 20);

    // A budget below what the structure of 16.8 M cells needs (eight active 128³ tiles: a
    // file of a few kilobytes) is refused before anything is decoded, naming the least.
    let tile = dir.path().join("tile.vdb");
    let mut grid = abc_grid("vel", h, 0, 0);
    for k in 0..8 {
        grid.tiles.push(qbricks_preprocess::grid::Tile {
            origin: [k & 1, (k >> 1) & 1, k >> 2].map(|c| 128 * c),
            size: 128,
            value: [1.0, 0.0, 0.0],
        });
    }
    write_vdb(&tile, &[AnyGrid::Vec3s(grid)], Compression::Zip).expect("write");
    let out = run(&[
        "bake",
        tile.to_str().expect("utf-8"),
        "-o",
        dir.path().join("small.qbk").to_str().expect("utf-8"),
        "--memory",
        "16M",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("the bake of 16777216 input cells (grid \"vel\") needs about ")
            && err.contains("even with every value kept on disk")
            && err.contains("give --memory "),
        "{err}"
    );
    assert!(!dir.path().join("small.qbk").exists());
}

/// The estimate counts about one brick a wholly active block, but whole blocks apart from
/// each other, off the tiles bricks are cut from (one voxel at -4 anchors the tiles there),
/// make eight each. A budget the estimate accepts is then checked again once the bricks
/// are made: refused before the fields are derived, naming a budget that does, within
/// which the bake stays (and writes the unbudgeted file).
#[test]
fn a_bake_making_more_bricks_than_estimated_is_refused_once_they_are_made() {
    use qbricks_preprocess::grid::{AnyGrid, Grid, Leaf};
    use qbricks_preprocess::vdb::write::{write_vdb, Compression};
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("apart.vdb");
    let whole = abc_grid("vel", 0.1, 0, 8).leaves.remove(0);
    let mut leaves = Vec::new();
    for x in 0..24 {
        for y in 0..24 {
            for z in 0..24 {
                leaves.push(Leaf {
                    origin: [x, y, z].map(|c| 16 * c),
                    ..whole.clone()
                });
            }
        }
    }
    let mut lone = Leaf {
        origin: [-8; 3],
        active: [0; 8],
        ..whole.clone()
    };
    let n = qbricks_preprocess::grid::leaf_offset(4, 4, 4);
    lone.active[n >> 6] |= 1 << (n & 63);
    leaves.push(lone);
    let grid = Grid {
        leaves,
        ..abc_grid("vel", 0.1, 0, 0)
    };
    write_vdb(&vdb, &[AnyGrid::Vec3s(grid)], Compression::Zip).expect("write");
    let path = |name: &str| dir.path().join(name);
    let bake = |out: &str, memory: &str| {
        let out = run(&[
            "bake",
            vdb.to_str().expect("utf-8"),
            "-o",
            path(out).to_str().expect("utf-8"),
            "--memory",
            memory,
            "--json",
        ]);
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).to_string(),
        )
    };
    let least = |err: &str| -> u64 {
        let m = err
            .split("give --memory ")
            .nth(1)
            .and_then(|t| t.split('M').next())
            .unwrap_or_else(|| panic!("no least budget named: {err}"));
        m.parse().expect("MiB")
    };
    // The estimate's least, from the blocks.
    let (code, err) = bake("a.qbk", "16M");
    assert_eq!(code, Some(2), "{err}");
    let early = least(&err);
    // Accepted by the estimate, refused once the 110 593 bricks are made.
    let (code, err) = bake("b.qbk", &format!("{early}M"));
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.starts_with("qbricks-bake: ")
            && err.contains("the bake of 7077889 input cells (grid \"vel\") needs about ")
            && err.contains(&format!("more than the --memory budget of {early} MiB")),
        "{err}"
    );
    assert!(!path("b.qbk").exists());
    let late = least(&err);
    assert!(late > early, "{early}M, then {late}M");
    // Within what it names the bake runs, and stays under it and the fixed overhead.
    let peak = bake_peak(&vdb, &path("c.qbk"), &["--memory", &format!("{late}M")]);
    eprintln!(
        "least {early}M from the blocks, {late}M from the bricks: peak {} MiB",
        peak >> 20
    );
    assert!(peak <= (late << 20) + (16 << 20), "{} MiB", peak >> 20);
    let free = path("free.qbk");
    bake_peak(&vdb, &free, &[]);
    assert!(std::fs::read(&free).expect("free") == std::fs::read(path("c.qbk")).expect("c"));
    let view = BrickFileView::open(&free).expect("open");
    assert_eq!(view.file().bricks.len(), 24 * 24 * 24 * 8 + 1);
}
