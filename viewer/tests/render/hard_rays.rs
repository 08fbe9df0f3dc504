//! Hard cases for the ray caster, ray by ray, for every sampling strategy: rays along cell
//! faces and exactly on level boundaries, grazing rays, a camera inside the volume, zero
//! gradient at the hit, iso values outside the data range, empty space between data, a
//! one-voxel-thick grid and coordinates offset by 1e6 (whole images: `hard_images`).
//!
//! Every case compares against analytic truth where the reconstruction reproduces the
//! field exactly (linear fields inside one grid), and otherwise against the reference
//! strategy (`uniform` at step 0.01 cell).

use qbricks_viewer::accel::Accel;
use qbricks_viewer::sampling::{Params, Strategy, Tracer};
use qbricks_viewer::testvol::{self, FieldFn, GridSpec};
use qbricks_viewer::transfer::Mode;
use qbricks_viewer::volume::Volume;

const STRATEGIES: [Strategy; 4] = [
    Strategy::Uniform,
    Strategy::Paper,
    Strategy::Bisect,
    Strategy::Exact,
];
/// First-sample offsets (interleaved sampling) tried for each ray.
pub(crate) const JITTERS: [f64; 3] = [0.0, 0.37, 0.999];
/// Step of the strategies under test, in cells (the seed report's 0.5·dx).
pub(crate) const STEP: f64 = 0.5;
/// Step of the reference.
pub(crate) const REF_STEP: f64 = 0.01;

pub(crate) use testvol::params;

/// As [`params`], with rays clipped to the box of regions that can contribute (what
/// the renderer does).
fn params_clipped(vol: &Volume, strategy: Strategy, step: f64, mode: Mode, iso: f64) -> Params {
    let mut p = params(vol, strategy, step, mode, iso);
    p.clip_to_active(vol);
    p
}

/// First iso hit along the world ray `o + t d` (`d` normalised here), as `t`.
fn iso_hit(
    vol: &Volume,
    strategy: Strategy,
    step: f64,
    iso: f64,
    o: [f64; 3],
    d: [f64; 3],
    jitter: f64,
) -> Option<f64> {
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let d = d.map(|x| x / n);
    // Without and with clipping to the active box: both must give the same hit.
    let p = params(vol, strategy, step, Mode::Iso, iso);
    let accel = Accel::new(p.accel_key());
    let mut tr = Tracer::new(vol, &accel, p);
    let plain = tr
        .iso(vol.to_local(o), d, 0.0, f64::INFINITY, jitter)
        .map(|h| h.t);
    let mut tr = Tracer::new(
        vol,
        &accel,
        params_clipped(vol, strategy, step, Mode::Iso, iso),
    );
    let clipped = tr
        .iso(vol.to_local(o), d, 0.0, f64::INFINITY, jitter)
        .map(|h| h.t);
    let same = match (plain, clipped) {
        (None, None) => true,
        (Some(a), Some(b)) => (a - b).abs() <= 1e-9 * (1.0 + a.abs()),
        _ => false,
    };
    assert!(
        same,
        "{strategy} jitter {jitter}: {plain:?} unclipped, {clipped:?} clipped to the active box (ray {o:?} {d:?} iso {iso})"
    );
    clipped
}

pub(crate) fn unit(d: [f64; 3]) -> [f64; 3] {
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    d.map(|x| x / n)
}

/// Open a test volume and run `f` on it.
pub(crate) fn with_volume<R>(
    grids: &[GridSpec],
    fields: &[FieldFn],
    max_brick: u32,
    f: impl FnOnce(&Volume) -> R,
) -> R {
    let file = testvol::build(grids, fields, max_brick);
    let view = testvol::open(&file).expect("open test volume");
    let vol = Volume::new(&view).expect("volume");
    f(&vol)
}

/// Tolerance on `t` (in cells) of a strategy against analytic truth on a field the
/// reconstruction reproduces exactly.
fn tol(strategy: Strategy) -> f64 {
    match strategy {
        Strategy::Exact => 1e-6,
        _ => 1e-3,
    }
}

/// Checks every strategy and jitter against an analytic hit distance (`None` = miss).
fn check_analytic(
    vol: &Volume,
    what: &str,
    iso: f64,
    o: [f64; 3],
    d: [f64; 3],
    want: Option<f64>,
    w: f64,
) {
    for s in STRATEGIES {
        for j in JITTERS {
            let got = iso_hit(vol, s, STEP, iso, o, d, j);
            match (got, want) {
                (None, None) => {}
                (Some(g), Some(t)) => assert!(
                    (g - t).abs() <= tol(s) * w,
                    "{what}: {s} jitter {j}: hit at t={g}, want {t} (ray {o:?} {d:?}, iso {iso})"
                ),
                _ => panic!("{what}: {s} jitter {j}: got {got:?}, want {want:?} (ray {o:?} {d:?}, iso {iso})"),
            }
        }
    }
}

/// Checks every strategy against the reference: same hit/miss, `t` within a step (the
/// sampled strategies may place the crossing anywhere their samples bracket it), and for
/// `exact` the reconstructed value at the hit equals the iso value (1e-4 of the range).
fn check_against_reference(
    vol: &Volume,
    what: &str,
    iso: f64,
    o: [f64; 3],
    d: [f64; 3],
    range: f64,
) {
    let reference = iso_hit(vol, Strategy::Uniform, REF_STEP, iso, o, d, 0.5);
    let du = unit(d);
    for s in STRATEGIES {
        for j in JITTERS {
            let got = iso_hit(vol, s, STEP, iso, o, d, j);
            assert_eq!(
                got.is_some(),
                reference.is_some(),
                "{what}: {s} jitter {j}: got {got:?}, reference {reference:?} (ray {o:?} {d:?})"
            );
            if let (Some(g), Some(r)) = (got, reference) {
                let p = vol.to_local(std::array::from_fn(|a| o[a] + g * du[a]));
                let w = vol
                    .region_at(p)
                    .map_or(vol.finest_w, |r| vol.region(r as usize).finest_w);
                assert!(
                    (g - r).abs() <= STEP * w + REF_STEP * w,
                    "{what}: {s} jitter {j}: t={g}, reference {r}"
                );
                // The sampled strategies place the crossing by linear interpolation
                // between samples, so only `exact` is held to the value.
                if s == Strategy::Exact {
                    let v = vol.value_at(p, 0).expect("hit inside the data");
                    assert!(
                        (v - iso).abs() <= 1e-4 * range,
                        "{what}: {s} jitter {j}: B(hit) = {v}, iso {iso}"
                    );
                }
            }
        }
    }
}

pub(crate) fn grid16() -> GridSpec {
    GridSpec::covering([0.0; 3], [16.0; 3], 1.0)
}

#[test]
fn rays_along_cell_faces_and_centre_lines() {
    let f = |p: [f64; 3]| p[0] + 0.25 * p[1] - 0.5 * p[2];
    with_volume(&[grid16()], &[("f", &f)], 4, |vol| {
        let iso = 6.0;
        // Faces are at integer coordinates, cell centres (dual-cell faces) at k + 0.5;
        // brick boundaries (4 cells) at multiples of 4.
        for y in [4.0, 7.0, 8.0, 6.5, 7.5] {
            for z in [4.0, 8.0, 5.5, 12.0] {
                // Along +x from outside the data.
                let o = [-3.0, y, z];
                let want = iso - 0.25 * y + 0.5 * z - o[0];
                check_analytic(vol, "along +x", iso, o, [1.0, 0.0, 0.0], Some(want), 1.0);
                // Along +y inside a face plane x = const (value changes only through y).
                let x = 5.0;
                let o = [x, -2.0, z];
                let want = (iso - x + 0.5 * z) / 0.25 - o[1];
                let hit = (want + o[1] <= 16.0).then_some(want);
                check_analytic(vol, "along +y", iso, o, [0.0, 1.0, 0.0], hit, 1.0);
            }
        }
        // Diagonal inside the face plane z = 8 through cell corners.
        let o = [0.0, 0.0, 8.0];
        let d = unit([1.0, 1.0, 0.0]);
        // f = 1.25 s / sqrt2 - 4 along the ray => s = (iso + 4) sqrt2 / 1.25.
        let want = (iso + 4.0) * 2f64.sqrt() / 1.25;
        check_analytic(vol, "diagonal in a face", iso, o, d, Some(want), 1.0);
    });
}

#[test]
fn rays_exactly_on_level_boundaries() {
    // Coarse w=2 over [0,16]^3, fine w=1 over [4,12]^3; boundaries at 4 and 12.
    let f = |p: [f64; 3]| 0.2 * p[0] + 0.05 * p[1] - 0.03 * p[2];
    let file = testvol::nested(8, [0.0; 3], &[("f", &f)], 4);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    let range = 4.0;
    for y in [4.0, 12.0, 3.0, 5.0] {
        for z in [4.0, 12.0, 8.0] {
            // Crossings inside the fine grid, at the boundary x = 4, and in the coarse grid.
            for x_cross in [2.0, 4.0, 6.0, 12.0, 13.0] {
                let iso = f([x_cross, y, z]);
                check_against_reference(
                    &vol,
                    "on a level boundary",
                    iso,
                    [-1.0, y, z],
                    [1.0, 0.0, 0.0],
                    range,
                );
            }
        }
    }
    // Oblique rays through the corner edges of the fine grid.
    for (o, d) in [
        ([-1.0, -1.0, 4.0], [1.0, 1.0, 0.0]),
        ([4.0, -1.0, -1.0], [0.0, 1.0, 1.0]),
        ([-1.0, 4.0, 4.0], [1.0, 0.0, 0.0]),
    ] {
        for iso in [0.5, 1.0, 2.0, 2.5] {
            check_against_reference(&vol, "fine-grid edge", iso, o, d, range);
        }
    }
}

#[test]
fn grazing_rays() {
    // Nearly parallel to a planar iso-surface: the value changes by 0.002 per unit
    // length, so a crossing is a long way off and every strategy must still find it
    // where it is.
    let f = |p: [f64; 3]| p[0];
    with_volume(&[grid16()], &[("f", &f)], 4, |vol| {
        let d = unit([0.002, 0.3, 1.0]);
        for (x0, iso) in [(5.5, 5.51), (7.0, 7.005), (8.0, 8.002)] {
            let o = [x0, 1.0, -1.0];
            let want = (iso - x0) / d[0];
            check_analytic(vol, "grazing plane", iso, o, d, Some(want), 1.0);
        }
    });
    // Tangent rays past a sphere |p - c| = R: `exact` must hit whenever the reference
    // does (thin crossings); no strategy may hit where the ray clearly misses.
    let c = [8.0, 8.0, 8.0];
    let r = 4.0;
    let sphere = move |p: [f64; 3]| {
        ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt()
    };
    with_volume(&[grid16()], &[("f", &sphere)], 4, |vol| {
        for gap in [-0.3, -0.05, -0.01, 0.01, 0.3] {
            let o = [-2.0, c[1] + r + gap, c[2] + 0.3];
            let d = [1.0, 0.0, 0.0];
            let reference = iso_hit(vol, Strategy::Uniform, REF_STEP, r, o, d, 0.5);
            let exact = iso_hit(vol, Strategy::Exact, STEP, r, o, d, 0.5);
            if reference.is_some() {
                let (e, rf) = (
                    exact.expect("exact misses a grazing hit the reference finds"),
                    reference.unwrap_or_default(),
                );
                assert!(
                    (e - rf).abs() < 2.0 * REF_STEP + 0.05,
                    "gap {gap}: exact {e}, reference {rf}"
                );
            }
            if gap >= 0.3 {
                for s in STRATEGIES {
                    assert_eq!(
                        iso_hit(vol, s, STEP, r, o, d, 0.37),
                        None,
                        "{s} hits a ray that passes {gap} outside"
                    );
                }
            }
            if gap <= -0.3 {
                assert!(
                    reference.is_some(),
                    "reference misses a ray 0.3 inside the sphere"
                );
                check_against_reference(vol, "through the sphere's rim", r, o, d, 8.0);
            }
        }
    });
}

#[test]
fn camera_inside_the_volume() {
    let f = |p: [f64; 3]| p[0] - 0.5 * p[2];
    with_volume(&[grid16()], &[("f", &f)], 4, |vol| {
        // Origins inside: in a cell, on a cell face, on a brick boundary, at a cell centre.
        for o in [
            [3.3, 6.2, 7.1],
            [3.0, 6.0, 8.0],
            [4.0, 4.0, 4.0],
            [2.5, 2.5, 2.5],
        ] {
            let v0 = f(o);
            // Looking towards larger values: iso above the start value.
            let iso = v0 + 1.75;
            check_analytic(
                vol,
                "inside, forwards",
                iso,
                o,
                [1.0, 0.0, 0.0],
                Some(1.75),
                1.0,
            );
            // Looking back towards smaller values.
            let iso = v0 - 1.25;
            check_analytic(
                vol,
                "inside, backwards",
                iso,
                o,
                [-1.0, 0.0, 0.0],
                Some(1.25),
                1.0,
            );
            // Oblique.
            let d = unit([1.0, 0.4, -0.7]);
            let slope = d[0] - 0.5 * d[2];
            check_analytic(
                vol,
                "inside, oblique",
                v0 + 1.0,
                o,
                d,
                Some(1.0 / slope),
                1.0,
            );
            // A surface closer than the first (jittered) sample, either way.
            for (dist, dir) in [(0.1, 1.0), (0.02, 1.0), (0.1, -1.0)] {
                let iso = v0 + dir * dist;
                let d = [dir, 0.0, 0.0];
                check_analytic(vol, "inside, just in front", iso, o, d, Some(dist), 1.0);
            }
        }
    });
}

#[test]
fn zero_gradient_at_the_hit() {
    // f = min(x - 8, 0): the iso value 0 is a plateau for x >= 8. The reconstruction
    // first reaches 0 at the cell centre x = 8.5 and is flat beyond it.
    let f = |p: [f64; 3]| (p[0] - 8.0).min(0.0);
    with_volume(&[grid16()], &[("f", &f)], 4, |vol| {
        for (y, z) in [(5.3, 6.1), (8.0, 8.0), (4.5, 4.5)] {
            let o = [-1.0, y, z];
            // The sampled strategies interpolate linearly between samples that bracket
            // the kink, so they are only held to the reference; exact is held to truth.
            check_against_reference(vol, "plateau", 0.0, o, [1.0, 0.0, 0.0], 8.0);
            let reference = iso_hit(
                vol,
                Strategy::Uniform,
                REF_STEP,
                0.0,
                o,
                [1.0, 0.0, 0.0],
                0.5,
            );
            assert!(
                reference.is_some_and(|t| (t - (8.5 - o[0])).abs() <= REF_STEP),
                "{reference:?}"
            );
            for j in JITTERS {
                let t = iso_hit(vol, Strategy::Exact, STEP, 0.0, o, [1.0, 0.0, 0.0], j);
                assert!(
                    t.is_some_and(|t| (t - (8.5 - o[0])).abs() <= 1e-6),
                    "exact: {t:?}"
                );
            }
            // The gradient there is zero from the right: the hit's reconstruction must
            // still be finite.
            let p = params(vol, Strategy::Exact, STEP, Mode::Iso, 0.0);
            let accel = Accel::new(p.accel_key());
            let mut tr = Tracer::new(vol, &accel, p);
            let h = tr
                .iso(vol.to_local(o), [1.0, 0.0, 0.0], 0.0, f64::INFINITY, 0.0)
                .expect("hit");
            let e = h.eval.expect("reconstruction at the hit");
            assert!(
                e.value.is_finite() && e.grad.iter().all(|g| g.is_finite()),
                "{e:?}"
            );
        }
    });
    // A maximum touching the iso value: f = -(x - 8.5)^2, iso 0 is reached only at one
    // point with zero gradient. Whatever a strategy reports must be where B = 0.
    let g = |p: [f64; 3]| -(p[0] - 8.5).powi(2);
    with_volume(&[grid16()], &[("f", &g)], 4, |vol| {
        let o = [-1.0, 5.3, 6.1];
        for s in STRATEGIES {
            if let Some(t) = iso_hit(vol, s, STEP, 0.0, o, [1.0, 0.0, 0.0], 0.37) {
                let v = vol
                    .value_at(vol.to_local([o[0] + t, o[1], o[2]]), 0)
                    .expect("inside");
                assert!(v.abs() <= 1e-4 * 72.0, "{s}: B(hit) = {v}");
            }
        }
    });
}

#[test]
fn iso_outside_the_data_range_hits_nothing_and_samples_nothing() {
    let f = |p: [f64; 3]| p[0] + p[1];
    with_volume(&[grid16()], &[("f", &f)], 4, |vol| {
        for iso in [-5.0, 40.0, 1e30, -1e30] {
            for s in STRATEGIES {
                let p = params(vol, s, STEP, Mode::Iso, iso);
                let accel = Accel::new(p.accel_key());
                let mut tr = Tracer::new(vol, &accel, p);
                let d = unit([1.0, 0.8, 0.3]);
                let hit = tr.iso(vol.to_local([-1.0, -1.0, 2.0]), d, 0.0, f64::INFINITY, 0.37);
                assert!(hit.is_none(), "{s}: hit at iso {iso}");
                assert_eq!(
                    tr.stats.samples, 0,
                    "{s}: sampled regions whose bounds exclude iso {iso}"
                );
                assert!(tr.stats.skipped > 0, "{s}: the ray crossed no region");
                // Clipped to the (empty) active box: nothing at all.
                let mut tr = Tracer::new(vol, &accel, params_clipped(vol, s, STEP, Mode::Iso, iso));
                let hit = tr.iso(vol.to_local([-1.0, -1.0, 2.0]), d, 0.0, f64::INFINITY, 0.37);
                assert!(hit.is_none(), "{s}: hit at iso {iso} (clipped)");
                assert_eq!(tr.stats.samples, 0, "{s}: samples at iso {iso} (clipped)");
                // Same in dvr: nothing is composited.
                for p in [
                    params(vol, s, STEP, Mode::Dvr, iso),
                    params_clipped(vol, s, STEP, Mode::Dvr, iso),
                ] {
                    let accel = Accel::new(p.accel_key());
                    let mut tr = Tracer::new(vol, &accel, p);
                    let acc = tr.dvr(
                        vol.to_local([-1.0, -1.0, 2.0]),
                        d,
                        0.0,
                        f64::INFINITY,
                        0.37,
                        &mut |_, _| [1.0; 3],
                    );
                    assert_eq!(acc.alpha(), 0.0, "{s}: dvr opacity at iso {iso}");
                    assert_eq!(tr.stats.samples, 0, "{s}: dvr samples at iso {iso}");
                }
            }
        }
    });
}

#[test]
fn empty_space_between_data() {
    // Two blocks of one grid with a gap x in (4.5, 7.5) between their supports.
    let a = GridSpec::covering([0.0, 0.0, 0.0], [4.0, 4.0, 4.0], 1.0);
    let b = GridSpec::covering([8.0, 0.0, 0.0], [12.0, 4.0, 4.0], 1.0);
    let f = |p: [f64; 3]| p[0];
    with_volume(&[a, b], &[("f", &f)], 4, |vol| {
        for (y, z) in [(2.0, 2.0), (1.5, 2.5), (0.0, 0.0)] {
            let o = [-3.0, y, z];
            let d = [1.0, 0.0, 0.0];
            // Inside either block: exact position. Across the gap the value jumps from
            // 3.5 to 8.5 without taking the values in between: no hit.
            check_analytic(vol, "first block", 2.0, o, d, Some(5.0), 1.0);
            check_analytic(vol, "second block", 10.0, o, d, Some(13.0), 1.0);
            for iso in [6.0, 4.0, 8.0] {
                check_analytic(vol, "across the gap", iso, o, d, None, 1.0);
            }
            // Coming back the other way.
            let o2 = [15.0, y, z];
            check_analytic(
                vol,
                "second block, backwards",
                9.0,
                o2,
                [-1.0, 0.0, 0.0],
                Some(6.0),
                1.0,
            );
            check_analytic(
                vol,
                "across the gap, backwards",
                6.0,
                o2,
                [-1.0, 0.0, 0.0],
                None,
                1.0,
            );
        }
        // A ray entirely in the gap meets no data: nothing is sampled.
        let p = params(vol, Strategy::Exact, STEP, Mode::Iso, 6.0);
        let accel = Accel::new(p.accel_key());
        let mut tr = Tracer::new(vol, &accel, p);
        assert!(tr
            .iso(
                vol.to_local([6.0, -1.0, 2.0]),
                [0.0, 1.0, 0.0],
                0.0,
                f64::INFINITY,
                0.0
            )
            .is_none());
        assert_eq!(tr.stats.samples, 0, "samples taken in empty space");
    });
}

#[test]
fn one_voxel_thick_grid_hits_at_the_analytic_distance() {
    // 16 x 16 x 1 cells: the support is two cells thick in z (z in [-0.5, 1.5]) and the
    // reconstruction is constant in z there.
    let g = GridSpec {
        cell_width: 1.0,
        origin: [0.5, 0.5, 0.5],
        dims: [16, 16, 1],
    };
    let f = |p: [f64; 3]| p[0] + 0.5 * p[1];
    with_volume(&[g], &[("f", &f)], 4, |vol| {
        for z in [0.5, 0.0, 1.0, 1.4, -0.4] {
            let o = [-2.0, 6.0, z];
            check_analytic(vol, "in the slab", 10.0, o, [1.0, 0.0, 0.0], Some(9.0), 1.0);
        }
        // Oblique through the slab: crossing at the slab's middle plane.
        let d = unit([1.0, 0.0, 1.0]);
        let o = [7.0 - 2.0, 6.0, 0.5 - 2.0];
        check_analytic(
            vol,
            "oblique through the slab",
            10.0,
            o,
            d,
            Some(2.0 * 2f64.sqrt()),
            1.0,
        );
        // Perpendicular to the slab, the value is constant: no crossing, no hit.
        for x in [8.3, 7.7] {
            let o = [x, 4.0, -3.0];
            check_analytic(vol, "perpendicular", 10.0, o, [0.0, 0.0, 1.0], None, 1.0);
        }
        // Just outside the support: nothing.
        check_analytic(
            vol,
            "above the slab",
            10.0,
            [-2.0, 6.0, 1.6],
            [1.0, 0.0, 0.0],
            None,
            1.0,
        );
    });
}

#[test]
fn coordinates_offset_by_a_million() {
    let off = 1e6;
    let rel = |p: [f64; 3], o: f64| {
        0.2 * (p[0] - o) + 0.05 * (p[1] - o) + 0.01 * ((p[2] - o) * 0.7).sin()
    };
    let f0 = move |p: [f64; 3]| rel(p, 0.0);
    let f1 = move |p: [f64; 3]| rel(p, off);
    let file0 = testvol::nested(8, [0.0; 3], &[("f", &f0)], 4);
    let file1 = testvol::nested(8, [off; 3], &[("f", &f1)], 4);
    let view0 = testvol::open(&file0).expect("open");
    let view1 = testvol::open(&file1).expect("open");
    let vol0 = Volume::new(&view0).expect("volume");
    let vol1 = Volume::new(&view1).expect("volume");
    let rays: [([f64; 3], [f64; 3]); 4] = [
        ([-1.0, 4.0, 4.0], [1.0, 0.0, 0.0]),
        ([-1.0, 3.3, 7.7], [1.0, 0.1, 0.05]),
        ([4.5, 9.0, -2.0], [0.3, -0.2, 0.9]),
        ([-2.0, -2.0, -2.0], [1.0, 1.0, 1.0]),
    ];
    for (o, d) in rays {
        for iso in [0.5, 1.0, 2.0] {
            let o1 = o.map(|x| x + off);
            for s in STRATEGIES {
                for j in JITTERS {
                    let t0 = iso_hit(&vol0, s, STEP, iso, o, d, j);
                    let t1 = iso_hit(&vol1, s, STEP, iso, o1, d, j);
                    match (t0, t1) {
                        (None, None) => {}
                        (Some(a), Some(b)) => assert!((a - b).abs() < 1e-6, "{s} {j}: t {a} vs {b} at offset 1e6"),
                        _ => panic!("{s} {j}: {t0:?} at the origin, {t1:?} at offset 1e6 (ray {o:?} {d:?} iso {iso})"),
                    }
                }
            }
            check_against_reference(&vol1, "offset 1e6", iso, o1, d, 4.0);
        }
    }
}
