//! Bake pipeline on in-memory grids sampled from closed-form flows.

use crate::common::bake::{cells, field, reconstruct, region_boxes};
use crate::common::Rng;
use format::BrickFile;
use qbricks_preprocess::bake::{bake, BakeError, BakeGrid, BakeOptions};
use qbricks_preprocess::derive::Stencil;
use qbricks_preprocess::fields::FieldKind;
use qbricks_preprocess::grid::{leaf_offset, AnyGrid, Grid, Leaf, Transform, LEAF_VOXELS};

/// ABC flow `u = (A sin z + C cos y, B sin x + A cos z, C sin y + B cos x)`.
const A: f64 = 1.0;
const B: f64 = 0.8;
const C: f64 = 0.6;

fn abc(p: [f64; 3]) -> [f64; 3] {
    let [x, y, z] = p;
    [
        A * z.sin() + C * y.cos(),
        B * x.sin() + A * z.cos(),
        C * y.sin() + B * x.cos(),
    ]
}

fn abc_q(p: [f64; 3]) -> f64 {
    let [x, y, z] = p;
    // g01 = -C sin y, g10 = B cos x, g02 = A cos z, g20 = -B sin x, g12 = -A sin z,
    // g21 = C cos y; diagonal zero. Q = -(g01 g10 + g02 g20 + g12 g21).
    let g01 = -C * y.sin();
    let g10 = B * x.cos();
    let g02 = A * z.cos();
    let g20 = -B * x.sin();
    let g12 = -A * z.sin();
    let g21 = C * y.cos();
    -(g01 * g10 + g02 * g20 + g12 * g21)
}

/// The ABC flow's velocity gradient in closed form (entries as in [`abc_q`]).
fn abc_gradient(p: [f64; 3]) -> [[f64; 3]; 3] {
    let [x, y, z] = p;
    [
        [0.0, -C * y.sin(), A * z.cos()],
        [B * x.cos(), 0.0, -A * z.sin()],
        [-B * x.sin(), C * y.cos(), 0.0],
    ]
}

/// A grid of width `w` whose cell `i` is centred at `t + i*w`, active on `lo..hi`.
fn sample(
    name: &str,
    w: f64,
    t: f64,
    lo: [i32; 3],
    hi: [i32; 3],
    f: &dyn Fn([f64; 3]) -> [f64; 3],
) -> Grid<[f64; 3]> {
    let mut leaves: Vec<Leaf<[f64; 3]>> = Vec::new();
    let b0 = lo.map(|c| c.div_euclid(8) * 8);
    let mut z0 = b0[2];
    while z0 < hi[2] {
        let mut y0 = b0[1];
        while y0 < hi[1] {
            let mut x0 = b0[0];
            while x0 < hi[0] {
                let mut leaf = Leaf {
                    origin: [x0, y0, z0],
                    active: [0; 8],
                    values: Box::new([[0.0; 3]; LEAF_VOXELS]),
                };
                for z in 0..8 {
                    for y in 0..8 {
                        for x in 0..8 {
                            let ijk = [x0 + x, y0 + y, z0 + z];
                            if (0..3).all(|a| ijk[a] >= lo[a] && ijk[a] < hi[a]) {
                                let n = leaf_offset(x as usize, y as usize, z as usize);
                                leaf.active[n >> 6] |= 1 << (n & 63);
                                leaf.values[n] = f(ijk.map(|c| t + c as f64 * w));
                            }
                        }
                    }
                }
                if leaf.active.iter().any(|&m| m != 0) {
                    leaves.push(leaf);
                }
                x0 += 8;
            }
            y0 += 8;
        }
        z0 += 8;
    }
    Grid {
        name: name.into(),
        transform: Transform {
            voxel_size: [w; 3],
            translation: [t; 3],
        },
        background: [0.0; 3],
        leaves,
        tiles: vec![],
    }
}

const L: f64 = std::f64::consts::TAU;

/// Coarse grid of `n³` cells over `[0, L]³` and a fine grid (half the width) over the
/// middle half `[L/4, 3L/4]³`; the lattices nest.
fn two_level(n: i32, f: &dyn Fn([f64; 3]) -> [f64; 3]) -> Vec<AnyGrid> {
    let w = L / n as f64;
    let coarse = sample("vel", w, 0.5 * w, [0; 3], [n; 3], f);
    let h = 0.5 * w;
    let fine = sample("vel", h, 0.5 * h, [n / 2; 3], [3 * n / 2; 3], f);
    vec![AnyGrid::Vec3d(coarse), AnyGrid::Vec3d(fine)]
}

/// `grids` as `bake_kept` takes them.
fn kept(grids: &[AnyGrid]) -> Vec<BakeGrid> {
    grids.iter().cloned().map(BakeGrid::from).collect()
}

/// (max, rms) of |Q − Q_exact| over leaf cells at least `margin` from the domain edge.
fn q_error(file: &BrickFile, margin: f64) -> (f64, f64) {
    let q = field(file, "q");
    let (mut max, mut sum, mut n) = (0.0f64, 0.0, 0usize);
    for c in cells(file, q) {
        let (p, v) = (c.centre, c.value);
        if p.iter().all(|&x| x > margin && x < L - margin) {
            let e = (v as f64 - abc_q(p)).abs();
            max = max.max(e);
            sum += e * e;
            n += 1;
        }
    }
    (max, (sum / n as f64).sqrt())
}

fn opts(stencil: Stencil) -> BakeOptions {
    BakeOptions {
        stencil,
        source: "test.vdb".into(),
        ..BakeOptions::default()
    }
}

#[test]
fn q_converges_at_second_order() {
    for stencil in [Stencil::Central, Stencil::CrossLevel] {
        let mut errs = vec![];
        for n in [16, 32] {
            let (file, _) = bake(two_level(n, &abc), &opts(stencil)).expect("bake");
            errs.push(q_error(&file, 0.1 * L));
        }
        let (max_ratio, rms_ratio) = (errs[0].0 / errs[1].0, errs[0].1 / errs[1].1);
        eprintln!("{stencil:?}: errors {errs:?}, ratios max {max_ratio:.2} rms {rms_ratio:.2}");
        assert!(rms_ratio > 3.0, "{stencil:?}: RMS error ratio {rms_ratio}");
        if stencil == Stencil::Central {
            assert!(max_ratio > 3.0, "{stencil:?}: max error ratio {max_ratio}");
        }
    }
}

/// RMS |value − exact| of `name` over leaf cells at least `margin` from the domain edge,
/// and over those of them within two coarse cells (`w`) of the fine box's faces.
fn rms_errors(
    file: &BrickFile,
    name: &str,
    exact: &dyn Fn([f64; 3]) -> f64,
    margin: f64,
    w: f64,
) -> (f64, f64) {
    let (mut all, mut near) = ((0.0, 0usize), (0.0, 0usize));
    for c in cells(file, field(file, name)) {
        let p = c.centre;
        if !p.iter().all(|&x| x > margin && x < L - margin) {
            continue;
        }
        let e = (f64::from(c.value) - exact(p)).powi(2);
        all = (all.0 + e, all.1 + 1);
        // Distance to the fine box [L/4, 3L/4]³'s surface.
        let inside = p.iter().all(|&x| (0.25 * L..=0.75 * L).contains(&x));
        let d = if inside {
            p.iter()
                .map(|&x| (x - 0.25 * L).min(0.75 * L - x))
                .fold(f64::INFINITY, f64::min)
        } else {
            p.iter()
                .map(|&x| (0.25 * L - x).max(x - 0.75 * L).max(0.0))
                .map(|d| d * d)
                .sum::<f64>()
                .sqrt()
        };
        if d < 2.0 * w {
            near = (near.0 + e, near.1 + 1);
        }
    }
    assert!(near.1 > 0);
    (
        (all.0 / all.1 as f64).sqrt(),
        (near.0 / near.1 as f64).sqrt(),
    )
}

/// Vorticity and λ2 come from Q's gradient stencil, with its cross-level treatment, so they
/// converge at (at least) its second order on the two-level ABC flow, over all cells and next to the
/// level boundary; helicity is 1 (ABC with equal wave numbers is a Beltrami flow, ω = u).
#[test]
fn vorticity_and_lambda2_converge_like_q_across_a_level_boundary() {
    use qbricks_preprocess::measures;
    type Exact = fn([f64; 3]) -> f64;
    let exact: [(&str, Exact); 3] = [
        ("q", abc_q),
        ("vorticity", |p| {
            measures::vorticity_magnitude(&abc_gradient(p))
        }),
        ("lambda2", |p| measures::lambda2(&abc_gradient(p))),
    ];
    for stencil in [Stencil::Central, Stencil::CrossLevel] {
        let mut errs = vec![];
        for n in [16, 32] {
            let o = BakeOptions {
                fields: Some(vec![
                    FieldKind::Q,
                    FieldKind::Vorticity,
                    FieldKind::Lambda2,
                    FieldKind::Helicity,
                ]),
                ..opts(stencil)
            };
            let (file, s) = bake(two_level(n, &abc), &o).expect("bake");
            let w = L / n as f64;
            errs.push(exact.map(|(name, f)| rms_errors(&file, name, &f, 0.1 * L, w)));
            // ω = u: the helicity is 1 up to the stencil's error (which the direction of a
            // small u near a stagnation point does not survive), never past [−1, 1].
            let h = &s.fields[3];
            assert_eq!(h.name, "helicity");
            assert!(h.max <= 1.0 && h.min >= -1.0, "{h:?}");
            let hv = &file.fields[field(&file, "helicity")].values;
            let aligned = hv.iter().filter(|&&v| v > 0.95).count();
            assert!(
                aligned as f64 > 0.95 * hv.len() as f64,
                "{aligned} of {}",
                hv.len()
            );
            // Q from the shared gradient is the Q of a plain bake, bit for bit.
            let (plain, _) = bake(two_level(n, &abc), &opts(stencil)).expect("bake");
            assert_eq!(
                file.fields[field(&file, "q")].values,
                plain.fields[field(&plain, "q")].values
            );
        }
        let order = |k: usize, near: bool| {
            let e = |i: usize| if near { errs[i][k].1 } else { errs[i][k].0 };
            (e(0) / e(1)).log2()
        };
        for near in [false, true] {
            let q = order(0, near);
            eprintln!(
                "{stencil:?} {}: orders q {q:.2}, vorticity {:.2}, lambda2 {:.2}",
                if near {
                    "near the boundary"
                } else {
                    "all cells"
                },
                order(1, near),
                order(2, near)
            );
            assert!(q > 1.6, "{stencil:?}: Q order {q}");
            for (k, name) in [(1, "vorticity"), (2, "lambda2")] {
                let o = order(k, near);
                // At least Q's order (within the scatter of two resolutions).
                assert!(
                    o > 1.6 && o > q - 0.3,
                    "{stencil:?} near {near}: {name} order {o} vs Q {q}"
                );
            }
        }
    }
}

#[test]
fn summary_counts_match_the_stored_cells_and_covered_cells_are_dropped() {
    let n = 16;
    let (file, s) = bake(two_level(n, &abc), &opts(Stencil::Central)).expect("bake");
    let coarse = (n as u64).pow(3);
    let fine = (n as u64).pow(3);
    assert_eq!(s.input_cells, coarse + fine);
    // The fine box covers exactly (n/2)³ coarse cells.
    assert_eq!(s.dropped_cells, (n as u64 / 2).pow(3));
    assert_eq!(s.leaf_cells, s.input_cells - s.dropped_cells);
    let stored: u64 = file
        .bricks
        .iter()
        .map(|b| b.dims.iter().map(|&d| d as u64).product::<u64>())
        .sum();
    assert_eq!(stored, s.leaf_cells);
    assert!(file
        .bricks
        .iter()
        .all(|b| b.dims.iter().all(|&d| (1..=8).contains(&d))));
    assert_eq!(file.levels.len(), 2);
    assert_eq!(file.levels[0].cells + file.levels[1].cells, s.leaf_cells);
    // Every level-1 stored cell lies outside (or straddles) the fine box.
    let w = L / n as f64;
    for c in cells(&file, 0) {
        let p = c.centre;
        if c.width > 0.75 * w {
            assert!(
                p.iter().any(|&x| !(0.25 * L..=0.75 * L).contains(&x)),
                "covered cell at {p:?}"
            );
        }
    }
    // Speed at a leaf cell is |u|.
    let sp = field(&file, "speed");
    for c in cells(&file, sp).into_iter().take(200) {
        let (p, v) = (c.centre, c.value);
        let u = abc(p);
        let e = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
        assert!((v as f64 - e).abs() < 1e-5);
    }
    // A tree of N leaves has N - 1 inner nodes (the stored ones); every region is a leaf.
    assert!(s.regions > 0 && s.kd_nodes + 1 >= s.regions);
}

#[test]
fn region_bounds_are_conservative_and_kd_tree_finds_regions() {
    let (file, _) = bake(two_level(8, &abc), &opts(Stencil::Central)).expect("bake");
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let nf = file.fields.len();
    let (lo, hi) = (file.bounds.min, file.bounds.max);
    let boxes = region_boxes(&file);
    assert!(
        boxes.iter().all(|b| !b.is_empty()),
        "every region is in a leaf"
    );
    let mut inside = 0;
    for _ in 0..400 {
        let p = [0, 1, 2].map(|a| lo[a] + rng.next() * (hi[a] - lo[a]));
        let brute = boxes
            .iter()
            .position(|r| (0..3).all(|a| p[a] >= r.min[a] && p[a] < r.max[a]));
        let found = file.region_at(p);
        assert_eq!(
            found,
            brute.map(|r| r as u32),
            "kd-tree vs brute force at {p:?}"
        );
        let Some(r) = found else { continue };
        let ids = file.bricks_of(r);
        let all: Vec<u32> = (0..file.bricks.len() as u32).collect();
        for f in 0..nf {
            let Some(v) = reconstruct(&file, ids, f, p) else {
                continue;
            };
            // The region's bricks are all the bricks whose support reaches p.
            let v_all = reconstruct(&file, &all, f, p).expect("inside supports");
            assert!((v - v_all).abs() <= 1e-9 * (1.0 + v.abs()));
            let range = file.region_ranges[r as usize * nf + f];
            assert!(
                v >= range.min as f64 - 1e-6 && v <= range.max as f64 + 1e-6,
                "field {f} value {v} outside region {r} range {range:?}"
            );
            inside += 1;
        }
    }
    assert!(inside > 100);
}

#[test]
fn same_bytes_on_one_and_two_threads() {
    let grids = two_level(8, &abc);
    let bytes = |threads| {
        let o = BakeOptions {
            threads: Some(threads),
            fields: Some(vec![FieldKind::Q, FieldKind::Speed, FieldKind::Velocity]),
            ..opts(Stencil::CrossLevel)
        };
        let (file, _) = bake(grids.clone(), &o).expect("bake");
        format::writer::to_bytes(&file).expect("serialise")
    };
    assert_eq!(bytes(1), bytes(2));
}

#[test]
fn nonfinite_values_replaced_or_refused() {
    let mut grids = two_level(8, &abc);
    if let AnyGrid::Vec3d(g) = &mut grids[0] {
        g.leaves[0].values[leaf_offset(1, 1, 1)] = [f64::NAN, 0.0, 0.0];
        g.leaves[0].values[leaf_offset(2, 1, 1)] = [0.0, f64::INFINITY, 0.0];
    }
    let (file, s) = bake(grids.clone(), &opts(Stencil::Central)).expect("bake");
    assert_eq!(s.nonfinite, 2);
    assert_eq!(s.warnings.len(), 1);
    assert!(file
        .fields
        .iter()
        .all(|f| f.values.iter().all(|v| v.is_finite())));
    let strict = BakeOptions {
        strict: true,
        ..opts(Stencil::Central)
    };
    match bake(grids, &strict) {
        Err(BakeError::NonFinite { count, .. }) => assert_eq!(count, 2),
        other => panic!("expected NonFinite, got {:?}", other.map(|r| r.1)),
    }
}

/// `g` with every value converted by `f`, named `name`, with background `background`.
fn convert<V: Copy, W: Copy>(
    g: &Grid<V>,
    name: &str,
    background: W,
    f: impl Fn(V) -> W,
) -> Grid<W> {
    Grid {
        name: name.to_string(),
        transform: g.transform,
        background,
        leaves: g
            .leaves
            .iter()
            .map(|l| Leaf {
                origin: l.origin,
                active: l.active,
                values: Box::new(l.values.map(&f)),
            })
            .collect(),
        tiles: vec![],
    }
}

/// `g` rounded to single precision, as a `Vec3s` grid and as its exact `Vec3d` copy.
fn single_and_double(g: &Grid<[f64; 3]>) -> (AnyGrid, AnyGrid) {
    let single = convert(g, &g.name, g.background.map(|c| c as f32), |v| {
        v.map(|c| c as f32)
    });
    let double = convert(&single, &g.name, single.background.map(f64::from), |v| {
        v.map(f64::from)
    });
    (AnyGrid::Vec3s(single), AnyGrid::Vec3d(double))
}

/// Sets the `k`-th active value of the first leaf of a vec3d grid, for each `(k, value)`.
fn spoil(grid: &mut AnyGrid, values: &[(usize, [f64; 3])]) {
    let AnyGrid::Vec3d(g) = grid else {
        unreachable!("a vec3d grid")
    };
    let leaf = &mut g.leaves[0];
    let active: Vec<usize> = (0..LEAF_VOXELS).filter(|&n| leaf.is_active(n)).collect();
    for &(k, v) in values {
        leaf.values[active[k]] = v;
    }
}

/// The bake keeps single-precision values as they came (half the memory of widening them,
/// see `cells::values`), widening them where it reads them: every file is the one the same
/// values in double precision make, including where values are computed rather than read
/// (non-finite values repaired, a staggered grid's centres), with an extra scalar field.
#[test]
fn single_precision_grids_bake_as_their_exact_double_copies() {
    let mut grids = two_level(8, &abc);
    // Two non-finite values in the fine grid (the extra field is made from the coarse one).
    spoil(
        &mut grids[1],
        &[(0, [f64::NAN, 0.0, 0.0]), (9, [0.0, f64::INFINITY, 0.0])],
    );
    let (mut singles, mut doubles) = (Vec::new(), Vec::new());
    for g in &grids {
        let AnyGrid::Vec3d(g) = g else {
            unreachable!("two_level makes vec3d grids")
        };
        let (s, d) = single_and_double(g);
        singles.push(s);
        doubles.push(d);
    }
    // An extra field: the x component of the coarse grid, as a float grid.
    let AnyGrid::Vec3s(coarse) = &singles[0] else {
        unreachable!()
    };
    let density = convert(coarse, "density", 0.0f32, |v| v[0]);
    singles.push(AnyGrid::Float(density.clone()));
    doubles.push(AnyGrid::Float(density));
    let cases = [
        opts(Stencil::Central),
        opts(Stencil::CrossLevel),
        BakeOptions {
            staggered: vec!["vel".to_string()],
            ..opts(Stencil::Central)
        },
        BakeOptions {
            fields: Some(vec![
                FieldKind::Q,
                FieldKind::Speed,
                FieldKind::Lambda2,
                FieldKind::Velocity,
                FieldKind::Scalar("density".to_string()),
            ]),
            ..opts(Stencil::CrossLevel)
        },
    ];
    for o in &cases {
        let bytes = |grids: &[AnyGrid]| {
            let (file, s) = bake(grids.to_vec(), o).expect("bake");
            assert_eq!(s.nonfinite, 2, "{o:?}");
            format::writer::to_bytes(&file).expect("serialise")
        };
        assert!(bytes(&singles) == bytes(&doubles), "{o:?}");
    }
}

/// Two levels of single-precision velocity (one value non-finite, repaired by the bake)
/// and a scalar grid `density` on the coarse level's voxels: the input of the bakes from
/// a file below.
fn two_level_with_density() -> Vec<AnyGrid> {
    let mut doubles = two_level(8, &abc);
    spoil(&mut doubles[1], &[(3, [f64::NAN, 0.0, 0.0])]);
    let mut grids: Vec<AnyGrid> = doubles
        .iter()
        .map(|g| match g {
            AnyGrid::Vec3d(g) => single_and_double(g).0,
            _ => unreachable!("two_level makes vec3d grids"),
        })
        .collect();
    let AnyGrid::Vec3s(coarse) = &grids[0] else {
        unreachable!()
    };
    grids.push(AnyGrid::Float(convert(coarse, "density", 0.0f32, |v| v[2])));
    grids
}

/// A bake from a file decodes each grid's leaves a batch at a time, straight into its cells
/// (`vdb::located`), and keeps the cells' values on disk past `Spill::above` as it does the
/// fields: the file is the one a bake of the decoded grids held in memory makes, byte for
/// byte, on two levels whose boundary runs through blocks, with non-finite values
/// repaired, a staggered grid, an extra scalar field, leaves decoded in the file's order or
/// in reverse, and on a grid of more than one batch of leaves.
#[test]
fn located_grids_with_cells_on_disk_give_the_same_file() {
    use qbricks_preprocess::bake::{bake_kept, Spill};
    use qbricks_preprocess::inputs::{read_inputs, ReadOptions};
    use qbricks_preprocess::vdb::write::{write_vdb, Compression};
    use qbricks_preprocess::vdb::{AnyLocated, VdbFile};

    let grids = two_level_with_density();
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("two_level.vdb");
    write_vdb(&vdb, &grids, Compression::Zip).expect("write vdb");
    let on_disk = |o: &BakeOptions| BakeOptions {
        spill: Spill {
            dir: Some(dir.path().to_path_buf()),
            above: 0,
            chunk: 700,
            window: 4096,
            structure: 0,
        },
        ..o.clone()
    };
    let written = |baked: qbricks_preprocess::bake::Baked| {
        let path = dir.path().join("out.qbk");
        baked.write(&path).expect("write");
        std::fs::read(&path).expect("read")
    };
    let cases = [
        opts(Stencil::CrossLevel),
        BakeOptions {
            staggered: vec!["vel".to_string()],
            ..opts(Stencil::Central)
        },
        BakeOptions {
            fields: Some(vec![
                FieldKind::Q,
                FieldKind::Lambda2,
                FieldKind::Velocity,
                FieldKind::Scalar("density".to_string()),
            ]),
            ..opts(Stencil::CrossLevel)
        },
    ];
    let file = VdbFile::open(&vdb).expect("open");
    for o in &cases {
        let (held, summary) = bake(grids.clone(), o).expect("bake");
        let held = format::writer::to_bytes(&held).expect("serialise");
        let read = ReadOptions {
            extra: vec!["density".to_string()],
            ..ReadOptions::default()
        };
        let (located, _) = read_inputs(&file, &read).expect("locate");
        assert!(located.iter().all(BakeGrid::is_located));
        let (baked, s) = bake_kept(located, &on_disk(o), &|_| {}).expect("bake located");
        assert_eq!(s, summary, "{o:?}");
        assert!(written(baked) == held, "{o:?}");
        // Leaves decoded out of the file's order make the same cells.
        let (mut located, _) = read_inputs(&file, &read).expect("locate");
        for g in &mut located {
            match g {
                BakeGrid::Located(AnyLocated::Vec3s(g)) => g.grid.leaves.reverse(),
                BakeGrid::Located(AnyLocated::Float(g)) => g.grid.leaves.reverse(),
                other => panic!("{other:?}"),
            }
        }
        let (baked, _) = bake_kept(located, o, &|_| {}).expect("bake reversed");
        assert!(written(baked) == held, "{o:?}");
    }
    // One grid of 17³ leaves: more than one batch of leaves decoded.
    let big = sample("vel", L / 136.0, L / 272.0, [0; 3], [136; 3], &abc);
    let big = vec![single_and_double(&big).0];
    let path = dir.path().join("big.vdb");
    write_vdb(&path, &big, Compression::Zip).expect("write vdb");
    let o = opts(Stencil::Central);
    let held = format::writer::to_bytes(&bake(big, &o).expect("bake").0).expect("serialise");
    let file = VdbFile::open(&path).expect("open");
    let (located, _) = read_inputs(&file, &ReadOptions::default()).expect("locate");
    let (baked, _) = bake_kept(located, &on_disk(&o), &|_| {}).expect("bake located");
    assert!(written(baked) == held);
}

/// One bake shared between 2, 3 and 5 ranks (`bake_kept_among`; threads standing in for
/// MPI ranks, each reading the VDB file itself as `mpirun` ranks do): rank 0's file is
/// the one a single process bakes, byte for byte, with the same summary, and the other
/// ranks end with nothing; on two levels whose boundary runs through blocks, with a
/// repaired non-finite value, a staggered grid and an extra scalar field (whose coverage
/// counts are summed over the ranks), with the fields held in memory and kept on disk in
/// chunks of a few bricks (so that the ranks take several rounds, the last one partly
/// empty).
#[test]
fn a_bake_shared_between_ranks_gives_the_same_file() {
    use qbricks_preprocess::bake::{bake_kept_among, Spill};
    use qbricks_preprocess::inputs::{read_inputs, ReadOptions};
    use qbricks_preprocess::vdb::write::{write_vdb, Compression};
    use qbricks_preprocess::vdb::VdbFile;

    let grids = two_level_with_density();
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("two_level.vdb");
    write_vdb(&vdb, &grids, Compression::Zip).expect("write vdb");
    let read = ReadOptions {
        extra: vec!["density".to_string()],
        ..ReadOptions::default()
    };
    let with_density = BakeOptions {
        fields: Some(vec![
            FieldKind::Q,
            FieldKind::Lambda2,
            FieldKind::Velocity,
            FieldKind::Scalar("density".to_string()),
        ]),
        ..opts(Stencil::CrossLevel)
    };
    let cases = [
        (opts(Stencil::CrossLevel), ReadOptions::default()),
        (
            BakeOptions {
                staggered: vec!["vel".to_string()],
                ..opts(Stencil::Central)
            },
            ReadOptions::default(),
        ),
        (with_density, read),
    ];
    let on_disk = |o: &BakeOptions| BakeOptions {
        spill: Spill {
            dir: Some(dir.path().to_path_buf()),
            above: 0,
            chunk: 200,
            window: 4096,
            structure: 0,
        },
        ..o.clone()
    };
    let written = |baked: qbricks_preprocess::bake::Baked, name: &str| {
        let path = dir.path().join(name);
        baked.write(&path).expect("write");
        std::fs::read(&path).expect("read")
    };
    for (o, read) in &cases {
        // Small bricks: dozens to share.
        let o = &BakeOptions {
            max_brick: 3,
            ..o.clone()
        };
        let (one, summary) = bake(grids.clone(), o).expect("bake");
        assert!(
            summary.bricks > 20,
            "{}: too few bricks to share",
            summary.bricks
        );
        let one = format::writer::to_bytes(&one).expect("serialise");
        for o in [o.clone(), on_disk(o)] {
            for n in [2, 3, 5] {
                let results: Vec<_> = std::thread::scope(|s| {
                    let handles: Vec<_> = ranks::local_ranks(n)
                        .into_iter()
                        .map(|peers| {
                            let o = o.clone();
                            let vdb = vdb.clone();
                            s.spawn(move || {
                                let file = VdbFile::open(&vdb).expect("open");
                                let (grids, _) = read_inputs(&file, read).expect("locate");
                                bake_kept_among(grids, &o, &|_| {}, &peers).expect("bake")
                            })
                        })
                        .collect();
                    handles
                        .into_iter()
                        .map(|h| h.join().expect("rank"))
                        .collect()
                });
                let mut results = results.into_iter();
                let (baked, s) = results.next().flatten().expect("rank 0 bakes");
                assert!(results.all(|r| r.is_none()), "another rank baked");
                assert_eq!(s, summary, "{n} ranks, {o:?}");
                assert!(written(baked, "shared.qbk") == one, "{n} ranks, {o:?}");
            }
        }
    }
}

/// Fields kept on disk (`Spill`), chunk after chunk of bricks, read back as they were
/// written, in memory or streamed from their scratch files into the written file: the
/// same file as a bake that holds them, on two levels with five fields, chunks of one
/// brick or a few; no scratch file is left behind; a directory that cannot hold them is
/// named in the error.
#[test]
fn fields_kept_on_disk_give_the_same_file() {
    use qbricks_preprocess::bake::Spill;
    let grids = two_level(8, &abc);
    let o = BakeOptions {
        fields: Some(vec![
            FieldKind::Q,
            FieldKind::Speed,
            FieldKind::Lambda2,
            FieldKind::Velocity,
        ]),
        ..opts(Stencil::CrossLevel)
    };
    let held = bake(grids.clone(), &o).expect("bake");
    let dir = tempfile::tempdir().expect("tempdir");
    for chunk in [1, 700, 1 << 22] {
        let spilled = BakeOptions {
            spill: Spill {
                dir: Some(dir.path().to_path_buf()),
                above: 0,
                chunk,
                window: 4096,
                structure: 0,
            },
            ..o.clone()
        };
        let held_bytes = format::writer::to_bytes(&held.0).expect("serialise");
        let (file, summary) = bake(grids.clone(), &spilled).expect("bake");
        assert_eq!(summary, held.1, "chunk {chunk}");
        assert!(
            format::writer::to_bytes(&file).expect("serialise") == held_bytes,
            "chunk {chunk}"
        );
        // Written as `qbricks-bake` writes it: the values streamed from their scratch
        // files into the archive.
        let (baked, summary) =
            qbricks_preprocess::bake::bake_kept(kept(&grids), &spilled, &|_| {}).expect("kept");
        assert_eq!(summary, held.1, "chunk {chunk}");
        let out = tempfile::tempdir().expect("tempdir");
        let path = out.path().join("kept.qbk");
        baked.write(&path).expect("write");
        drop(baked);
        assert!(
            std::fs::read(&path).expect("read") == held_bytes,
            "chunk {chunk}"
        );
        let left: Vec<_> = std::fs::read_dir(dir.path()).expect("dir").collect();
        assert!(left.is_empty(), "{left:?}");
    }
    let gone = dir.path().join("gone");
    let e = bake(
        grids,
        &BakeOptions {
            spill: Spill {
                dir: Some(gone.clone()),
                above: 0,
                chunk: 1,
                window: 4096,
                structure: 0,
            },
            ..o
        },
    )
    .expect_err("no such directory");
    assert!(matches!(e, BakeError::Scratch { .. }), "{e:?}");
    assert!(e.to_string().contains(&gone.display().to_string()), "{e}");
}

#[test]
fn scalar_grid_is_its_own_field_and_bad_inputs_are_refused() {
    let g = sample("density", 1.0, 0.0, [0; 3], [5, 4, 3], &|p| {
        [p[0] + 2.0 * p[1], 0.0, 0.0]
    });
    let scalar = convert(&g, &g.name, 0.0f32, |v| v[0] as f32);
    let (file, s) = bake(
        vec![AnyGrid::Float(scalar.clone())],
        &BakeOptions::default(),
    )
    .expect("bake");
    assert_eq!(file.fields.len(), 1);
    assert_eq!(file.fields[0].name, "density");
    assert_eq!((s.fields[0].min, s.fields[0].max), (0.0, 4.0 + 6.0));

    let mut odd = scalar.clone();
    odd.transform.voxel_size = [3.0; 3];
    let r = bake(
        vec![AnyGrid::Float(scalar.clone()), AnyGrid::Float(odd)],
        &BakeOptions::default(),
    );
    assert!(matches!(r, Err(BakeError::NonPowerOfTwo { .. })));
    let r = bake(
        vec![AnyGrid::Float(scalar.clone())],
        &BakeOptions {
            grids: vec!["vel".into()],
            ..BakeOptions::default()
        },
    );
    assert!(matches!(r, Err(BakeError::GridNotFound { .. })));

    // A 4096³ root tile is refused before anything is expanded.
    let mut huge = scalar;
    huge.tiles.push(qbricks_preprocess::grid::Tile {
        origin: [0, 0, 4096],
        size: 4096,
        value: 1.0,
    });
    let r = bake(vec![AnyGrid::Float(huge)], &BakeOptions::default());
    assert!(matches!(r, Err(BakeError::Memory(_))));
}

/// Ratio-4 levels, a misaligned fine lattice and overlapping grids of one level: the file
/// still partitions the supports, regions bound the reconstruction, and only fully covered
/// cells are dropped.
#[test]
fn odd_layouts_keep_regions_and_bounds_exact() {
    let coarse = sample("vel", 1.0, 0.5, [0; 3], [10, 9, 8], &abc);
    // Width 0.25 (ratio 4), lattice shifted by 0.1: no coarse cell is exactly covered
    // along x, but cells are still covered where the fine box spans them fully.
    let fine = sample("vel", 0.25, 0.125 + 0.1, [8, 8, 8], [24, 20, 22], &abc);
    // A second grid of the fine level overlapping the first.
    let fine2 = sample("vel", 0.25, 0.125, [20, 4, 4], [30, 14, 12], &abc);
    let grids = vec![
        AnyGrid::Vec3d(coarse),
        AnyGrid::Vec3d(fine),
        AnyGrid::Vec3d(fine2),
    ];
    let (file, s) = bake(grids, &opts(Stencil::CrossLevel)).expect("bake");
    assert_eq!(file.levels.len(), 2);
    assert!(s.dropped_cells > 0 && s.dropped_cells < 10 * 9 * 8);
    // Brute-force coverage: a coarse cell is dropped iff every point of it is inside one
    // of the fine boxes (their active cells are boxes here).
    let fine_boxes = [
        ([2.1, 2.1, 2.1], [6.1, 5.1, 5.6]),
        ([5.0, 1.0, 1.0], [7.5, 3.5, 3.0]),
    ];
    let covered = |lo: [f64; 3], hi: [f64; 3]| {
        // Cut at fine-box faces; every piece must be inside some box.
        let mut cuts: Vec<Vec<f64>> = (0..3).map(|a| vec![lo[a], hi[a]]).collect();
        for (bl, bh) in &fine_boxes {
            for a in 0..3 {
                for x in [bl[a], bh[a]] {
                    if x > lo[a] && x < hi[a] {
                        cuts[a].push(x);
                    }
                }
            }
        }
        for c in &mut cuts {
            c.sort_by(f64::total_cmp);
        }
        let mid = |c: &Vec<f64>, i: usize| 0.5 * (c[i] + c[i + 1]);
        (0..cuts[0].len() - 1).all(|i| {
            (0..cuts[1].len() - 1).all(|j| {
                (0..cuts[2].len() - 1).all(|k| {
                    let p = [mid(&cuts[0], i), mid(&cuts[1], j), mid(&cuts[2], k)];
                    fine_boxes
                        .iter()
                        .any(|(bl, bh)| (0..3).all(|a| p[a] > bl[a] && p[a] < bh[a]))
                })
            })
        })
    };
    let mut dropped = 0;
    for z in 0..8 {
        for y in 0..9 {
            for x in 0..10 {
                let lo = [x as f64, y as f64, z as f64];
                if covered(lo, lo.map(|v| v + 1.0)) {
                    dropped += 1;
                }
            }
        }
    }
    assert_eq!(s.dropped_cells, dropped);

    let mut rng = Rng(7);
    let nf = file.fields.len();
    let boxes = region_boxes(&file);
    let all: Vec<u32> = (0..file.bricks.len() as u32).collect();
    for _ in 0..300 {
        let p = [0, 1, 2]
            .map(|a| file.bounds.min[a] + rng.next() * (file.bounds.max[a] - file.bounds.min[a]));
        let brute = boxes
            .iter()
            .position(|r| (0..3).all(|a| p[a] >= r.min[a] && p[a] < r.max[a]));
        assert_eq!(file.region_at(p), brute.map(|r| r as u32));
        let Some(r) = brute else { continue };
        let ids = file.bricks_of(r as u32);
        for f in 0..nf {
            let v_all = reconstruct(&file, &all, f, p);
            let v = reconstruct(&file, ids, f, p);
            assert_eq!(v.is_some(), v_all.is_some());
            if let (Some(v), Some(va)) = (v, v_all) {
                assert!((v - va).abs() <= 1e-9 * (1.0 + v.abs()));
                let range = file.region_ranges[r * nf + f];
                assert!(v >= range.min as f64 - 1e-6 && v <= range.max as f64 + 1e-6);
            }
        }
    }
}
