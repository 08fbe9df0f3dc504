//! `synth` on the boxes of a layout file (`--boxes`): what it writes reads back as the
//! boxes asked for, and bakes into a file with those levels and boxes. The layout is issue
//! 33's independent one (`docs/bench/layouts/independent.json`) with cells 4× wider, so the
//! test is fast; the boxes, their nesting and the solid sphere are the same.

use crate::common::bake::cells;
use crate::common::root;
use lab::synth::{write_scene, BoxLayout, GridLayout, SynthOptions};
use qbricks_preprocess::bake::{bake, BakeOptions};
use qbricks_preprocess::grid::{AnyGrid, Grid, Vec3};
use qbricks_preprocess::vdb::write::Compression;
use qbricks_preprocess::vdb::{MetaValue, VdbFile};

/// `independent.json` with every cell width times `scale`.
fn scaled_independent(scale: f64) -> BoxLayout {
    let text = std::fs::read_to_string(root().join("docs/bench/layouts/independent.json"))
        .expect("docs/bench/layouts/independent.json");
    let mut layout = BoxLayout::from_json(&text).expect("valid JSON");
    for b in &mut layout.boxes {
        b.cell *= scale;
    }
    layout
}

fn options(layout: &BoxLayout) -> SynthOptions {
    SynthOptions {
        scene: "wake".into(),
        // Not used with boxes: a layout of its own is sampled whatever these say.
        n0: 7,
        levels: 1,
        compression: Compression::Zip,
        speed_grids: false,
        staggered: false,
        frame: 1,
        boxes: Some(layout.clone()),
    }
}

/// Whether voxel `ijk` of `g` should be active: in the box and in no obstacle (written
/// here again, not taken from the lab).
fn active(g: &GridLayout, ijk: [i64; 3]) -> bool {
    let centre = ijk.map(|i| (i as f64 + 0.5) * g.voxel_size);
    (0..3).all(|a| ijk[a] >= g.lo[a] && ijk[a] < g.hi[a])
        && !g.obstacles.iter().any(|o| o.contains(centre))
}

/// Every voxel of the box of `g`.
fn box_voxels(g: &GridLayout) -> impl Iterator<Item = [i64; 3]> + '_ {
    (g.lo[0]..g.hi[0]).flat_map(move |i| {
        (g.lo[1]..g.hi[1]).flat_map(move |j| (g.lo[2]..g.hi[2]).map(move |k| [i, j, k]))
    })
}

/// Index box `[lo, hi)` of a grid's active voxels.
fn active_box(g: &Grid<Vec3>) -> ([i32; 3], [i32; 3]) {
    let mut lo = [i32::MAX; 3];
    let mut hi = [i32::MIN; 3];
    for leaf in &g.leaves {
        for (ijk, _) in leaf.active_voxels() {
            for a in 0..3 {
                lo[a] = lo[a].min(ijk[a]);
                hi[a] = hi[a].max(ijk[a] + 1);
            }
        }
    }
    (lo, hi)
}

/// Synth `layout`, read it back, bake it, and check both against the layout.
fn check(layout: &BoxLayout) {
    let want = layout.grids("wake").expect("valid layout");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("boxes.vdb");
    let (summary, _) = write_scene(&path, &options(layout)).expect("write");
    assert_eq!(
        summary.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(),
        ["vel_l0", "vel_l1", "vel_l2"]
    );

    // The file: one grid per box, finest first, cell-centred, every voxel of the box
    // outside the obstacles active and no other; the layout in the file's metadata.
    let file = VdbFile::open(&path).expect("open");
    assert_eq!(
        file.metadata.get("boxes"),
        Some(&MetaValue::String(layout.to_json()))
    );
    assert_eq!(file.metadata.get("levels"), Some(&MetaValue::Int32(3)));
    assert_eq!(file.metadata.get("n0"), None);
    let grids = file.read_all().expect("read");
    assert_eq!(grids.len(), 3);
    let mut active_counts = Vec::new();
    for (g, w) in grids.iter().zip(&want) {
        let AnyGrid::Vec3s(g) = g else {
            panic!("{}: not a vec3s grid", w.name);
        };
        assert_eq!(g.name, w.name);
        assert_eq!(g.transform.voxel_size, [w.voxel_size; 3]);
        assert_eq!(g.transform.translation, [0.5 * w.voxel_size; 3]);
        let (lo, hi) = active_box(g);
        assert_eq!(lo.map(i64::from), w.lo, "{}", w.name);
        assert_eq!(hi.map(i64::from), w.hi, "{}", w.name);
        let n = box_voxels(w).filter(|&v| active(w, v)).count() as u64;
        assert_eq!(g.active_voxel_count(), n, "{}", w.name);
        for leaf in &g.leaves {
            for (ijk, _) in leaf.active_voxels() {
                assert!(active(w, ijk.map(i64::from)), "{}: {ijk:?}", w.name);
            }
        }
        active_counts.push(n);
    }

    // The bake: three levels of the widths asked for; a level's leaf cells are its active
    // cells less those whose eight finer cells are all active (the boxes lie on the
    // coarser cells, so a covered cell is covered whole), and they span its whole box.
    let (baked, bake_summary) = bake(grids, &BakeOptions::default()).expect("bake");
    let widths: Vec<f64> = baked.levels.iter().map(|l| l.cell_width).collect();
    assert_eq!(
        widths,
        want.iter().map(|w| w.voxel_size).collect::<Vec<_>>()
    );
    for (level, w) in want.iter().enumerate() {
        let covered = match level.checked_sub(1) {
            None => 0,
            Some(f) => box_voxels(w)
                .filter(|&v| active(w, v))
                .filter(|v| {
                    (0..8).all(|c| {
                        let child: [i64; 3] =
                            std::array::from_fn(|a| 2 * v[a] + ((c >> a) & 1) as i64);
                        active(&want[f], child)
                    })
                })
                .count() as u64,
        };
        assert_eq!(
            baked.levels[level].cells,
            active_counts[level] - covered,
            "level {level}"
        );
    }
    assert_eq!(
        bake_summary.leaf_cells,
        baked.levels.iter().map(|l| l.cells).sum::<u64>()
    );
    let mut spans = vec![([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]); want.len()];
    for c in cells(&baked, 0) {
        assert!(
            !layout.obstacles.iter().any(|o| o.contains(c.centre)),
            "a leaf cell in an obstacle: {c:?}"
        );
        let (lo, hi) = &mut spans[c.level as usize];
        for a in 0..3 {
            lo[a] = lo[a].min(c.centre[a] - 0.5 * c.width);
            hi[a] = hi[a].max(c.centre[a] + 0.5 * c.width);
        }
    }
    for (level, (lo, hi)) in spans.iter().enumerate() {
        let b = &layout.boxes[want.len() - 1 - level];
        for a in 0..3 {
            assert!(
                (lo[a] - b.min[a]).abs() < 1e-12,
                "level {level} axis {a}: {lo:?}"
            );
            assert!(
                (hi[a] - b.max[a]).abs() < 1e-12,
                "level {level} axis {a}: {hi:?}"
            );
        }
    }
    // The provenance names the grids with their levels, finest first.
    let names: Vec<(&str, u32)> = baked
        .provenance
        .grids
        .iter()
        .map(|g| (g.name.as_str(), g.level))
        .collect();
    assert_eq!(names, [("vel_l0", 0), ("vel_l1", 1), ("vel_l2", 2)]);
}

#[test]
fn a_layout_reads_back_and_bakes_into_its_levels_and_boxes() {
    let layout = scaled_independent(4.0);
    assert_eq!(layout.obstacles.len(), 1);
    check(&layout);
    // Without the solid sphere, every level is its box less the finer box.
    let mut boxes_only = layout;
    boxes_only.obstacles.clear();
    check(&boxes_only);
}

/// `n0` and `levels` do not change what a layout writes.
#[test]
fn a_layout_ignores_n0_and_levels() {
    let layout = scaled_independent(8.0);
    let dir = tempfile::tempdir().expect("tempdir");
    let a = dir.path().join("a.vdb");
    let b = dir.path().join("b.vdb");
    write_scene(&a, &options(&layout)).expect("a");
    let mut other = options(&layout);
    other.n0 = 64;
    other.levels = 5;
    write_scene(&b, &other).expect("b");
    assert!(std::fs::read(&a).expect("a") == std::fs::read(&b).expect("b"));
}
