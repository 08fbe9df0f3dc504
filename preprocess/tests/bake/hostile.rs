//! Issue 32, the library's side: inputs that made a bake abort, bake nonsense or answer
//! wrongly without a word. Each is now refused before anything large is allocated, or
//! baked with a warning that names every grid involved. (The same inputs through the
//! command line, under an address-space limit, are in the root `tests/cross_crate/`.)

use qbricks_preprocess::bake::{bake, BakeError, BakeGrid, BakeOptions};
use qbricks_preprocess::fields::FieldKind;
use qbricks_preprocess::grid::{AnyGrid, Grid, Leaf, Tile, Transform, LEAF_VOXELS};

fn unit(w: f64, t: f64) -> Transform {
    Transform {
        voxel_size: [w; 3],
        translation: [t; 3],
    }
}

/// A vec3 grid of full leaves over `lo..hi` (multiples of 8), value `f(ijk)`.
fn vel(
    name: &str,
    t: Transform,
    lo: [i32; 3],
    hi: [i32; 3],
    f: impl Fn([i32; 3]) -> [f32; 3],
) -> Grid<[f32; 3]> {
    let mut leaves = Vec::new();
    for x in (lo[0]..hi[0]).step_by(8) {
        for y in (lo[1]..hi[1]).step_by(8) {
            for z in (lo[2]..hi[2]).step_by(8) {
                leaves.push(Leaf {
                    origin: [x, y, z],
                    active: [u64::MAX; 8],
                    values: Box::new(std::array::from_fn(|n| {
                        f([
                            x + (n >> 6) as i32,
                            y + ((n >> 3) & 7) as i32,
                            z + (n & 7) as i32,
                        ])
                    })),
                });
            }
        }
    }
    Grid {
        name: name.into(),
        transform: t,
        background: [0.0; 3],
        leaves,
        tiles: vec![],
    }
}

fn density(lo: [i32; 3], hi: [i32; 3]) -> Grid<f32> {
    let mut leaves = Vec::new();
    for x in (lo[0]..hi[0]).step_by(8) {
        for y in (lo[1]..hi[1]).step_by(8) {
            for z in (lo[2]..hi[2]).step_by(8) {
                leaves.push(Leaf {
                    origin: [x, y, z],
                    active: [u64::MAX; 8],
                    values: Box::new([1.0; LEAF_VOXELS]),
                });
            }
        }
    }
    Grid {
        name: "density".into(),
        transform: unit(1.0, 0.0),
        background: 0.25,
        leaves,
        tiles: vec![],
    }
}

fn swirl(i: [i32; 3]) -> [f32; 3] {
    [0.1 * i[1] as f32, -0.1 * i[0] as f32, 0.05 * i[2] as f32]
}

/// A file of a few kilobytes can hold one active tile of 4096³ voxels. It used to be
/// expanded cell by cell until the allocation failed (SIGABRT); now the bake's memory
/// estimate (bytes per cell of everything it allocates) refuses it first, in the shared
/// limit's words.
#[test]
fn a_huge_tile_is_refused_by_the_memory_estimate_before_it_is_expanded() {
    let g = Grid {
        name: "vel".into(),
        transform: unit(1.0, 0.0),
        background: [0.0f32; 3],
        leaves: vec![],
        tiles: vec![Tile {
            origin: [0; 3],
            size: 4096,
            value: [1.0, 0.0, 0.0],
        }],
    };
    let e = bake(vec![AnyGrid::Vec3s(g)], &BakeOptions::default()).expect_err("too large");
    assert!(matches!(e, BakeError::Memory(_)), "{e:?}");
    let m = e.to_string();
    assert!(
        m.starts_with("the bake of 68719476736 input cells (grid \"vel\") needs about ")
            && m.contains(" MiB, more than the limit of "),
        "{m}"
    );
    // The cells' values (12 bytes of single-precision velocity) and the fields go to
    // scratch files and stay there, read a window at a time, so what is held is the masks
    // (36 bytes a block: the tile's blocks are all wholly active, and share one pattern)
    // and the 3 bytes of structure a cell: 3.07 bytes per cell, 0.2 TiB.
    assert!(m.contains("needs about 201280 MiB"), "{m}");
}

/// A grid translated to 1e300 with voxels of 0.1 has every centre at the same double.
/// It used to bake into a file of zero-size bricks; now it is refused naming the grid.
/// Up to 2^26 finest voxels out, data bakes into the same bricks and regions as at the
/// origin (leaf cells are classified and supports snapped as they are near it).
#[test]
fn grids_too_far_from_the_origin_are_refused_and_far_ones_bake_as_near_ones() {
    let far = vel("vel", unit(0.1, 1e300), [0; 3], [8; 3], swirl);
    let e = bake(vec![AnyGrid::Vec3s(far)], &BakeOptions::default()).expect_err("far");
    assert!(matches!(e, BakeError::FarFromOrigin { .. }), "{e:?}");
    assert!(
        e.to_string().starts_with(
            "grid \"vel\" (voxel size 0.1): voxels reach 1e300 from the origin, 1.0e301 \
             voxels of the finest size 0.1 out: too far for double precision"
        ),
        "{e}"
    );

    // Cell widths that are no binary fractions, so that coordinates out there round.
    let two = |shift: f64| {
        let coarse = vel("c", unit(0.2, 0.1 + shift), [0; 3], [16; 3], swirl);
        let fine = vel("f", unit(0.1, 0.05 + shift), [8; 3], [24; 3], swirl);
        vec![AnyGrid::Vec3s(coarse), AnyGrid::Vec3s(fine)]
    };
    let (near, _) = bake(two(0.0), &BakeOptions::default()).expect("near");
    for k in [20, 24, 26] {
        for frac in [0.0, 0.37, 0.813] {
            let shift = 0.1 * 2f64.powi(k) * 0.99 * (1.0 - 0.5 * frac);
            let (out, _) = bake(two(shift), &BakeOptions::default()).expect("out");
            assert_eq!(out.bricks.len(), near.bricks.len(), "2^{k}, {frac}");
            assert_eq!(out.regions.len(), near.regions.len(), "2^{k}, {frac}");
        }
    }
    let e = bake(two(0.1 * 2f64.powi(27)), &BakeOptions::default()).expect_err("2^27 out");
    assert!(matches!(e, BakeError::FarFromOrigin { .. }), "{e:?}");
}

/// Two grids of one voxel size overlapping: averaged by the viewer, so a disagreement is
/// a warning with both names, the overlap and the largest difference; agreement (one
/// field split into two grids) stays silent.
#[test]
fn overlapping_grids_of_one_size_warn_when_their_values_differ() {
    let t = unit(1.0, 0.0);
    let a = vel("a", t, [0; 3], [16; 3], |_| [1.0, 0.0, 0.0]);
    let b = vel("b", t, [8, 0, 0], [24, 16, 16], |_| [2.0, 0.0, 0.0]);
    let (_, s) = bake(
        vec![AnyGrid::Vec3s(a.clone()), AnyGrid::Vec3s(b)],
        &BakeOptions::default(),
    )
    .expect("bake");
    assert_eq!(
        s.warnings,
        [
            "grids \"a\" and \"b\" (voxel size 1) overlap in 2048 cells, 2048 of them with \
          different values (largest difference 1, at voxel [8, 0, 0] of \"a\"); the file \
          keeps both and the viewer averages them there"
        ]
    );

    let same = vel("b", t, [8, 0, 0], [24, 16, 16], |_| [1.0, 0.0, 0.0]);
    let (_, s) = bake(
        vec![AnyGrid::Vec3s(a.clone()), AnyGrid::Vec3s(same)],
        &BakeOptions::default(),
    )
    .expect("bake");
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);

    // Two grids of one name are told apart; grids that only touch do not overlap.
    let mut b2 = vel("a", t, [8, 0, 0], [24, 16, 16], |i| [i[0] as f32, 0.0, 0.0]);
    let (_, s) = bake(
        vec![AnyGrid::Vec3s(a.clone()), AnyGrid::Vec3s(b2.clone())],
        &BakeOptions::default(),
    )
    .expect("bake");
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(
        s.warnings[0].starts_with(
            "grids \"a\" (1st of 2 of that name) and \"a\" (2nd of 2 of that name) (voxel size 1) overlap in 2048 cells, 2048 of them"
        ),
        "{}",
        s.warnings[0]
    );
    b2.leaves.retain(|l| l.origin[0] >= 16);
    let (_, s) = bake(
        vec![AnyGrid::Vec3s(a), AnyGrid::Vec3s(b2)],
        &BakeOptions::default(),
    )
    .expect("bake");
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
}

/// An extra field baked where its grid has no voxels read its background silently; now
/// partial coverage is a warning with the share, and none a refusal naming both boxes.
#[test]
fn an_extra_field_warns_with_its_coverage_and_is_refused_when_it_covers_nothing() {
    let opts = BakeOptions {
        fields: Some(vec![FieldKind::Q, FieldKind::Scalar("density".into())]),
        ..BakeOptions::default()
    };
    let v = || AnyGrid::Vec3s(vel("vel", unit(1.0, 0.0), [0; 3], [16; 3], swirl));
    let (_, s) = bake(vec![v(), AnyGrid::Float(density([0; 3], [16; 3]))], &opts).expect("covered");
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);

    let (file, s) = bake(
        vec![v(), AnyGrid::Float(density([0; 3], [8, 16, 16]))],
        &opts,
    )
    .expect("half");
    assert_eq!(
        s.warnings,
        [
            "field \"density\": grid \"density\" covers 50.0 % of the velocity's leaf cells (2048 \
          of 4096); the others read its background 0.25"
        ]
    );
    let d = file
        .fields
        .iter()
        .find(|f| f.name == "density")
        .expect("field");
    assert_eq!((d.min, d.max), (0.25, 1.0));

    let e = bake(vec![v(), AnyGrid::Float(density([96; 3], [104; 3]))], &opts)
        .expect_err("nowhere near");
    assert_eq!(
        e.to_string(),
        "field \"density\": grid \"density\" has no active voxel at any of the velocity's 4096 \
         leaf cells, so every value would be its background 0.25 (its voxels lie in [95.5, \
         95.5, 95.5]..[103.5, 103.5, 103.5], the velocity's cells in [-0.5, -0.5, \
         -0.5]..[15.5, 15.5, 15.5])"
    );
}

/// Non-finite values found in two grids: one warning (or one refusal) naming both, each
/// with its count; it used to name the first grid only, with the total.
#[test]
fn non_finite_values_in_two_grids_name_both() {
    let mut fine = vel("fine", unit(1.0, 0.0), [0; 3], [8; 3], swirl);
    fine.leaves[0].values[1] = [f32::NAN, 0.0, 0.0];
    fine.leaves[0].values[2] = [0.0, f32::INFINITY, 0.0];
    let mut coarse = vel("coarse", unit(2.0, 0.0), [0; 3], [8; 3], swirl);
    coarse.leaves[0].values[511] = [0.0, 0.0, f32::NAN];
    let grids = vec![AnyGrid::Vec3s(fine), AnyGrid::Vec3s(coarse)];
    let (_, s) = bake(grids.clone(), &BakeOptions::default()).expect("repaired");
    assert_eq!(s.nonfinite, 3);
    assert_eq!(
        s.warnings,
        [
            "replaced 3 non-finite values by the average of their finite neighbours: 2 in grid \
          \"fine\" (first at voxel [0, 0, 1]), 1 in grid \"coarse\" (first at voxel [7, 7, 7])"
        ]
    );
    let strict = BakeOptions {
        strict: true,
        ..BakeOptions::default()
    };
    let e = bake(grids, &strict).expect_err("strict");
    assert!(
        e.to_string().starts_with(
            "3 non-finite values: 2 in grid \"fine\" (first at voxel [0, 0, 1]), 1 in grid \
             \"coarse\""
        ),
        "{e}"
    );

    // Q overflowing f32 in both grids (velocities of 1e30): both named with their counts.
    let huge = |i: [i32; 3]| [1e30 * i[1] as f32, -1e30 * i[0] as f32, 0.0];
    let grids = vec![
        AnyGrid::Vec3s(vel("fine", unit(1.0, 0.0), [0; 3], [8; 3], huge)),
        AnyGrid::Vec3s(vel("coarse", unit(2.0, 0.0), [0; 3], [8; 3], huge)),
    ];
    let (held, s) = bake(grids.clone(), &BakeOptions::default()).expect("clamped");
    // Clamped the same when the values are kept in scratch files (changed through their
    // mapping).
    let dir = tempfile::tempdir().expect("tempdir");
    let spilled = BakeOptions {
        spill: qbricks_preprocess::bake::Spill {
            dir: Some(dir.path().to_path_buf()),
            above: 0,
            chunk: 100,
            window: 4096,
            structure: 0,
        },
        ..BakeOptions::default()
    };
    let grids = grids.into_iter().map(BakeGrid::from).collect();
    let (baked, s2) = qbricks_preprocess::bake::bake_kept(grids, &spilled, &|_| {}).expect("kept");
    assert_eq!(s2, s);
    let path = dir.path().join("clamped.qbk");
    baked.write(&path).expect("write");
    assert!(std::fs::read(&path).expect("read") == format::writer::to_bytes(&held).expect("bytes"));
    let q = s
        .warnings
        .iter()
        .find(|w| w.starts_with("field \"q\""))
        .expect("q warning");
    assert!(
        q.contains("in grid \"fine\" (first at voxel")
            && q.contains("in grid \"coarse\" (first at voxel"),
        "{q}"
    );
    // Every leaf cell's Q is about 1e60.
    assert_eq!(s.nonfinite_derived, s.leaf_cells, "{q}");
}

/// The archive bound's lower estimate divides by the largest brick's cells: any
/// `--max-brick` (up to u32::MAX) bakes, without overflow.
#[test]
fn the_largest_max_brick_bakes() {
    let g = vel("vel", unit(1.0, 0.0), [0; 3], [16; 3], swirl);
    let opts = BakeOptions {
        max_brick: u32::MAX,
        ..BakeOptions::default()
    };
    let (file, _) = bake(vec![AnyGrid::Vec3s(g)], &opts).expect("bake");
    assert_eq!(file.bricks.len(), 1);
}
