//! Reconstruction, gradient, traversal and `exact` iso search against analytic truth.

use qbricks_viewer::accel::Accel;
use qbricks_viewer::sampling::{Params, Strategy, Tracer};
use qbricks_viewer::testvol::{self, GridSpec};
use qbricks_viewer::transfer::{Mode, Transfer};
use qbricks_viewer::volume::Volume;

/// Deterministic pseudo-random numbers in [0, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn smooth(p: [f64; 3]) -> f64 {
    (p[0] / 5.0).sin() + (p[1] / 7.0).cos() * (p[2] / 6.0 + 0.3).sin() + 0.01 * p[0]
}

fn rough(p: [f64; 3]) -> f64 {
    // Unrelated values at neighbouring cells: trilinear must reproduce them exactly.
    let h = (p[0] * 12.9898 + p[1] * 78.233 + p[2] * 37.719).sin() * 43758.5453;
    h - h.floor()
}

#[test]
fn one_grid_is_trilinear() {
    let g = GridSpec {
        cell_width: 0.5,
        origin: [1.0, -2.0, 3.0],
        dims: [13, 9, 11],
    };
    let file = testvol::build(&[g], &[("f", &rough)], 4);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    let mut rng = Rng(1);
    for _ in 0..2000 {
        // Continuous index strictly inside the cell-centre hull.
        let u: [f64; 3] = std::array::from_fn(|a| rng.next() * (g.dims[a] - 1) as f64);
        let p: [f64; 3] = std::array::from_fn(|a| g.origin[a] + u[a] * g.cell_width);
        let i: [f64; 3] = u.map(f64::floor);
        let mut tri = 0.0;
        for c in 0..8 {
            let off = [c & 1, (c >> 1) & 1, (c >> 2) & 1];
            let mut w = 1.0;
            let mut q = [0.0; 3];
            for a in 0..3 {
                let k = i[a] + off[a] as f64;
                let fr = u[a] - i[a];
                w *= if off[a] == 1 { fr } else { 1.0 - fr };
                q[a] = g.origin[a] + k * g.cell_width;
            }
            if w > 0.0 {
                tri += w * rough(q) as f32 as f64;
            }
        }
        let s = vol.sample(p, 0).expect("inside");
        assert!(
            (s.values[0] as f64 - tri).abs() < 1e-5,
            "at {p:?}: {} vs trilinear {tri}",
            s.values[0]
        );
    }
}

fn nested_volume(offset: [f64; 3]) -> format::BrickFileView {
    let f = move |p: [f64; 3]| smooth(std::array::from_fn(|a| p[a] - offset[a]));
    let file = testvol::nested(
        16,
        offset,
        &[("f", &f), ("speed", &|p| p[0] - offset[0])],
        8,
    );
    testvol::open(&file).expect("open")
}

#[test]
fn continuous_across_level_boundary() {
    let view = nested_volume([0.0; 3]);
    let vol = Volume::new(&view).expect("volume");
    let widths: Vec<f64> = (0..vol.brick_count() as u32)
        .map(|b| vol.brick(b).w)
        .collect();
    assert!(widths.contains(&1.0) && widths.contains(&2.0));
    // Lines crossing the fine box face x = 8 (and the edge/corner regions) at several heights.
    let h = 1e-3;
    let mut rng = Rng(7);
    for line in 0..12 {
        let y = 4.0 + rng.next() * 24.0;
        let z = 4.0 + rng.next() * 24.0;
        let (mut prev_v, mut prev_g) = (None::<f64>, 0.0f64);
        let mut x = 5.0;
        while x < 11.0 {
            let s = vol.sample([x, y, z], 0).expect("inside the data");
            let v = s.values[0] as f64;
            let g = s.gradient.iter().map(|c| c * c).sum::<f64>().sqrt();
            if let Some(pv) = prev_v {
                let bound = 2.0 * g.max(prev_g) * h + 1e-5;
                assert!(
                    (v - pv).abs() <= bound,
                    "line {line} at x={x}: jump {} > {bound}",
                    (v - pv).abs()
                );
            }
            prev_v = Some(v);
            prev_g = g;
            x += h;
        }
    }
}

#[test]
fn gradient_matches_finite_differences() {
    for offset in [[0.0; 3], [1e6, -1e6, 1e6]] {
        let view = nested_volume(offset);
        let vol = Volume::new(&view).expect("volume");
        let mut rng = Rng(3);
        let e = 1e-5;
        for _ in 0..1000 {
            let p: [f64; 3] = std::array::from_fn(|a| offset[a] + 0.5 + rng.next() * 31.0);
            let s = vol.sample(p, 0).expect("inside");
            for a in 0..3 {
                let mut p1 = p;
                let mut p0 = p;
                p1[a] += e;
                p0[a] -= e;
                let (Some(v1), Some(v0)) = (vol.sample(p1, 0), vol.sample(p0, 0)) else {
                    continue;
                };
                // Values are f32; differences of reconstructions in f64 weights stay exact enough.
                let fd = (v1.values[0] as f64 - v0.values[0] as f64) / (2.0 * e);
                let lp = vol.to_local(p);
                let r = vol.region_at(lp).expect("region") as usize;
                let g = vol.eval(r, lp, 0, None).expect("eval").grad[a];
                let fd64 = (vol
                    .eval(r, vol.to_local(p1), 0, None)
                    .map_or(fd, |x| x.value)
                    - vol
                        .eval(r, vol.to_local(p0), 0, None)
                        .map_or(fd, |x| x.value))
                    / (2.0 * e);
                assert!((s.gradient[a] - g).abs() < 1e-12);
                assert!(
                    (g - fd64).abs() <= 1e-4 * (1.0 + g.abs()),
                    "offset {offset:?} at {p:?} axis {a}: analytic {g} vs fd {fd64}"
                );
            }
        }
    }
}

fn params(strategy: Strategy, step: f64, iso: f64) -> Params {
    Params {
        strategy,
        step,
        tf: Transfer {
            mode: Mode::Iso,
            iso,
            ..Transfer::default()
        },
        field: 0,
        colour_field: Some(1),
        delta0: 1.0,
        clip: None,
        preintegrated: None,
    }
}

/// Rays through the nested volume: oblique ones, axis-aligned ones along cell faces and on
/// level-boundary planes, grazing ones, and ones starting inside.
fn rays(n: usize) -> Vec<([f64; 3], [f64; 3])> {
    let mut rng = Rng(11);
    let mut out = Vec::new();
    for _ in 0..n {
        let target: [f64; 3] = std::array::from_fn(|_| 2.0 + rng.next() * 28.0);
        let dir: [f64; 3] = std::array::from_fn(|_| rng.next() - 0.5);
        let len = dir.iter().map(|x| x * x).sum::<f64>().sqrt();
        let d = dir.map(|x| x / len);
        let o = std::array::from_fn(|a| target[a] - 40.0 * d[a]);
        out.push((o, d));
    }
    for i in 0..32 {
        // Along x, on cell faces / centres / level boundaries (fine box faces at 8 and 24).
        let y = [8.0, 24.0, 9.0, 9.5, 16.0, 2.0, 3.0][i % 7];
        let z = 0.5 + i as f64;
        out.push(([-5.0, y, z], [1.0, 0.0, 0.0]));
        out.push(([16.0, y, z], [1.0, 0.0, 0.0])); // camera inside the volume
        out.push(([y, z, 40.0], [0.0, 0.0, -1.0]));
    }
    // Grazing: almost parallel to a face of the data.
    for i in 0..16 {
        let d = [1.0, 1e-4 * i as f64, 0.0];
        let l = (1.0 + d[1] * d[1]).sqrt();
        out.push(([-5.0, 0.01 + i as f64, 7.3], [d[0] / l, d[1] / l, 0.0]));
    }
    out
}

#[test]
fn exact_hits_are_on_the_surface_and_miss_nothing_uniform_finds() {
    for offset in [[0.0; 3], [1e6, 1e6, -1e6]] {
        let view = nested_volume(offset);
        let vol = Volume::new(&view).expect("volume");
        let range = (vol.fields[0].max - vol.fields[0].min) as f64;
        for iso in [0.3, -0.5, 1.1] {
            let accel = Accel::new(params(Strategy::Exact, 1.0, iso).accel_key());
            let mut exact = Tracer::new(&vol, &accel, params(Strategy::Exact, 1.0, iso));
            let mut reference = Tracer::new(&vol, &accel, params(Strategy::Uniform, 0.01, iso));
            // The same, with rays clipped to the box of regions that can hold the surface.
            let clipped = |s, step| {
                let mut p = params(s, step, iso);
                p.clip_to_active(&vol);
                p
            };
            let mut exact_c = Tracer::new(&vol, &accel, clipped(Strategy::Exact, 1.0));
            let mut uniform = Tracer::new(&vol, &accel, params(Strategy::Uniform, 0.5, iso));
            let mut uniform_c = Tracer::new(&vol, &accel, clipped(Strategy::Uniform, 0.5));
            let (mut hits, mut ref_hits) = (0, 0);
            for (o, d) in rays(300) {
                let o = vol.to_local(std::array::from_fn(|a| o[a] + offset[a]));
                let he = exact.iso(o, d, 0.0, 1e3, 0.5);
                let hr = reference.iso(o, d, 0.0, 1e3, 0.5);
                assert_eq!(
                    exact_c.iso(o, d, 0.0, 1e3, 0.5).map(|h| h.t),
                    he.map(|h| h.t)
                );
                if uniform.iso(o, d, 0.0, 1e3, 0.5).is_some() {
                    assert!(
                        uniform_c.iso(o, d, 0.0, 1e3, 0.5).is_some(),
                        "clipping lost a hit"
                    );
                }
                if let Some(h) = he {
                    hits += 1;
                    let v = vol.value_at(h.p, 0).unwrap_or_else(|| {
                        panic!(
                            "hit outside data: {h:?} o {o:?} d {d:?} region {:?} bounds {:?} {:?}",
                            vol.region_at(h.p),
                            vol.bounds_min,
                            vol.bounds_max
                        )
                    });
                    assert!(
                        (v - iso).abs() <= 1e-4 * range,
                        "iso {iso}: B(hit) = {v} at t = {}",
                        h.t
                    );
                }
                if let Some(hr) = hr {
                    ref_hits += 1;
                    let he = he.unwrap_or_else(|| {
                        panic!(
                            "exact missed a hit of the reference: o {o:?} d {d:?} t {}",
                            hr.t
                        )
                    });
                    assert!(
                        he.t <= hr.t + 0.02,
                        "exact hit later ({}) than the reference ({})",
                        he.t,
                        hr.t
                    );
                }
            }
            assert!(
                ref_hits > 50 && hits >= ref_hits,
                "iso {iso}: {hits} exact, {ref_hits} reference hits"
            );
        }
    }
}

#[test]
fn exact_finds_thin_shells_that_coarse_steps_miss() {
    // A thin spherical shell of values: the iso surfaces are 0.2 cell apart.
    let shell = |p: [f64; 3]| {
        let r = ((p[0] - 16.0).powi(2) + (p[1] - 16.0).powi(2) + (p[2] - 16.0).powi(2)).sqrt();
        (-((r - 9.0) / 0.6).powi(2)).exp()
    };
    let file = testvol::nested(16, [0.0; 3], &[("f", &shell), ("c", &|_| 0.0)], 8);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    let iso = 0.9;
    let accel = Accel::new(params(Strategy::Exact, 1.0, iso).accel_key());
    let mut exact = Tracer::new(&vol, &accel, params(Strategy::Exact, 1.0, iso));
    let mut coarse = Tracer::new(&vol, &accel, params(Strategy::Uniform, 1.0, iso));
    let mut reference = Tracer::new(&vol, &accel, params(Strategy::Uniform, 0.01, iso));
    let (mut e, mut c, mut r) = (0, 0, 0);
    for (o, d) in rays(200) {
        let o = vol.to_local(o);
        let he = exact.iso(o, d, 0.0, 1e3, 0.37);
        let hr = reference.iso(o, d, 0.0, 1e3, 0.37);
        e += he.is_some() as u32;
        c += coarse.iso(o, d, 0.0, 1e3, 0.37).is_some() as u32;
        r += hr.is_some() as u32;
        if hr.is_some() {
            assert!(he.is_some(), "exact missed the shell: o {o:?} d {d:?}");
        }
    }
    assert!(e >= r && r > 20, "exact {e}, reference {r}");
    assert!(
        c < e,
        "the coarse uniform step should miss some of the thin shell ({c} vs {e})"
    );
}

#[test]
fn traversal_matches_brute_force() {
    let view = nested_volume([0.0; 3]);
    let vol = Volume::new(&view).expect("volume");
    let file = view.file();
    let mut stack = Vec::new();
    for (o, d) in rays(200) {
        let o = vol.to_local(o);
        let mut got = Vec::new();
        vol.segments(o, d, 0.0, 1e3, &mut stack, |s| {
            got.push(s);
            true
        });
        // Brute force over all regions (half-open boxes, as the KD descent).
        let inv = qbricks_viewer::traverse::inverse(&d);
        let mut want: Vec<format::query::RegionSegment> = vol
            .regions()
            .enumerate()
            .filter_map(|(i, r)| {
                qbricks_viewer::traverse::ray_box(&r.min, &r.max, &o, &inv, 0.0, 1e3).map(
                    |(a, b)| format::query::RegionSegment {
                        region: i as u32,
                        t_enter: a,
                        t_exit: b,
                    },
                )
            })
            .filter(|s| s.t_exit - s.t_enter > 1e-9)
            .collect();
        want.sort_by(|a, b| a.t_enter.total_cmp(&b.t_enter));
        assert_eq!(file.regions.len(), vol.region_count());
        let got: Vec<_> = got.into_iter().filter(|s| s.t1 - s.t0 > 1e-9).collect();
        assert_eq!(got.len(), want.len(), "o {o:?} d {d:?}");
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.region, w.region);
            assert!((g.t0 - w.t_enter).abs() < 1e-9 && (g.t1 - w.t_exit).abs() < 1e-9);
        }
        // Front to back, no overlaps.
        for p in got.windows(2) {
            assert!(p[1].t0 >= p[0].t1 - 1e-9);
        }
    }
}

/// `exact` finds every hit of the reference, on the surface, for arbitrary rays.
fn exact_covers_reference(vol: &Volume, iso: f64, rays: &[([f64; 3], [f64; 3])]) -> (u32, u32) {
    let range = (vol.fields[0].max - vol.fields[0].min) as f64;
    let accel = Accel::new(params(Strategy::Exact, 1.0, iso).accel_key());
    let mut exact = Tracer::new(vol, &accel, params(Strategy::Exact, 1.0, iso));
    let mut reference = Tracer::new(vol, &accel, params(Strategy::Uniform, 0.01, iso));
    let (mut e, mut r) = (0, 0);
    for &(o, d) in rays {
        let o = vol.to_local(o);
        let he = exact.iso(o, d, 0.0, 1e3, 0.25);
        if let Some(h) = he {
            e += 1;
            let v = vol.value_at(h.p, 0).expect("hit inside data");
            assert!(
                (v - iso).abs() <= 1e-4 * range.max(1e-30),
                "B(hit) = {v}, iso {iso}"
            );
        }
        if reference.iso(o, d, 0.0, 1e3, 0.25).is_some() {
            r += 1;
            assert!(he.is_some(), "exact missed: o {o:?} d {d:?}");
        }
    }
    (e, r)
}

#[test]
fn one_voxel_thick_grid_is_constant_in_z_and_exact_misses_nothing() {
    let g = GridSpec {
        cell_width: 1.0,
        origin: [0.5, 0.5, 0.5],
        dims: [12, 10, 1],
    };
    let f = |p: [f64; 3]| (p[0] / 2.0).sin() + (p[1] / 3.0).cos();
    let file = testvol::build(&[g], &[("f", &f), ("c", &f)], 8);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    // Rays through the slab (support z in [-0.5, 1.5]) at many angles.
    let mut rays = Vec::new();
    let mut rng = Rng(5);
    for _ in 0..400 {
        let target = [rng.next() * 12.0, rng.next() * 10.0, rng.next() * 2.0 - 0.5];
        let dir: [f64; 3] = std::array::from_fn(|_| rng.next() - 0.5);
        let l = dir.iter().map(|x| x * x).sum::<f64>().sqrt();
        let d = dir.map(|x| x / l);
        rays.push((std::array::from_fn(|a| target[a] - 30.0 * d[a]), d));
    }
    let (e, r) = exact_covers_reference(&vol, 0.5, &rays);
    assert!(r > 20 && e >= r, "exact {e}, reference {r}");
    // In a one-cell-thick grid the field is constant in z: value = 2D bilinear.
    let s = vol.sample([3.3, 4.1, 0.9], 0).expect("inside");
    let s2 = vol.sample([3.3, 4.1, 0.1], 0).expect("inside");
    assert!((s.values[0] - s2.values[0]).abs() < 1e-6 && s.gradient[2].abs() < 1e-9);
}

#[test]
fn zero_gradient_and_flat_fields() {
    // A constant field equal to iso everywhere: every point is "on" the surface; the
    // gradient is zero. Nothing may panic, hits must be on the data.
    let file = testvol::nested(8, [0.0; 3], &[("f", &|_| 0.25), ("c", &|_| 0.0)], 8);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    let accel = Accel::new(params(Strategy::Exact, 1.0, 0.25).accel_key());
    let mut t = Tracer::new(&vol, &accel, params(Strategy::Exact, 1.0, 0.25));
    for (o, d) in rays(50) {
        if let Some(h) = t.iso(vol.to_local(o), d, 0.0, 1e3, 0.5) {
            let e = h.eval.expect("eval at hit");
            assert!(e.grad.iter().all(|g| g.abs() < 1e-9));
        }
    }
    // A saddle (x·y) has zero gradient at its centre; the iso surface through it is hit.
    let sad = |p: [f64; 3]| (p[0] - 16.0) * (p[1] - 16.0);
    let file = testvol::nested(16, [0.0; 3], &[("f", &sad), ("c", &sad)], 8);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    let (e, r) = exact_covers_reference(&vol, 0.0, &rays(200));
    assert!(r > 50 && e >= r);
}

#[test]
fn empty_file_renders_nothing() {
    let file = testvol::build(&[], &[("f", &|_| 0.0)], 8);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    assert_eq!(vol.region_count(), 0);
    let accel = Accel::new(params(Strategy::Exact, 1.0, 0.0).accel_key());
    let mut t = Tracer::new(&vol, &accel, params(Strategy::Exact, 1.0, 0.0));
    assert!(t.iso([0.0; 3], [1.0, 0.0, 0.0], 0.0, 1e3, 0.5).is_none());
    assert!(vol.sample([0.0; 3], 0).is_none());
}
