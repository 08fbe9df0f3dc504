//! Cutting into the flow (issue 27): clip planes, slice planes and several iso-surfaces
//! in one view, checked ray by ray through `--pixel`'s events against the planes'
//! geometry, against `probe` and against closed forms, on two nested levels (so planes and
//! rays cross level boundaries) with rays along cell faces and planes parallel to them.

use qbricks_viewer::camera::{Camera, Projection};
use qbricks_viewer::mesh::Meshes;
use qbricks_viewer::planes::{Plane, Slice};
use qbricks_viewer::render::{Frame, Renderer, Scene};
use qbricks_viewer::sampling::Event;
use qbricks_viewer::testvol;
use qbricks_viewer::view_state::{IsoSurface, ViewState};
use qbricks_viewer::volume::Volume;

/// Distance from the centre of `nested(16)`'s data (16, 16, 16): its iso-surfaces are
/// spheres, the inner ones in the fine level, the outer ones across the level boundary
/// (the fine grid covers [8, 24]³).
fn dist(p: [f64; 3]) -> f64 {
    ((p[0] - 16.0).powi(2) + (p[1] - 16.0).powi(2) + (p[2] - 16.0).powi(2)).sqrt()
}

/// A linear field: reconstructed exactly everywhere, on both levels and across their
/// boundary, so a slice's values can be checked against it to round-off.
fn linear(p: [f64; 3]) -> f64 {
    0.5 * p[0] - 0.25 * p[1] + 0.125 * p[2] + 3.0
}

fn file() -> format::BrickFile {
    testvol::nested(16, [0.0; 3], &[("d", &dist), ("lin", &linear)], 8)
}

/// An orthographic view of the whole data along `dir`, 40 × 40 pixels of width 1 (rays
/// on pixel centres fall on cell faces of both levels when `dir` is an axis).
fn state(vol: &Volume, dir: [f64; 3]) -> ViewState {
    let mut st = ViewState::default_for_volume(vol);
    st.iso_field = "d".into();
    st.colormap.field = "lin".into();
    st.iso = 6.0;
    st.width = 40;
    st.height = 40;
    st.overlays = "none".parse().unwrap();
    let look = [16.0; 3];
    let up = if dir[1].abs() > 0.9 {
        [0.0, 0.0, 1.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    st.camera = Camera {
        eye: std::array::from_fn(|a| look[a] - 50.0 * dir[a]),
        look_at: look,
        up,
        projection: Projection::Orthographic { width: 40.0 },
    };
    st
}

/// Every event of every pixel's first ray, with the ray.
fn events(vol: &Volume, st: &ViewState) -> Vec<([f64; 3], [f64; 3], Vec<Event>)> {
    let meshes = Meshes::empty();
    let scene = Scene::new(vol, st, &meshes).unwrap();
    let renderer = Renderer::new(Some(1)).unwrap();
    let mut out = Vec::new();
    for y in (0..st.height).step_by(3) {
        for x in (0..st.width).step_by(3) {
            let trace = renderer.trace_pixel(&scene, x, y);
            let r = &trace.rays[0];
            out.push((r.origin, r.dir, r.events.clone()));
        }
    }
    out
}

fn render(vol: &Volume, st: &ViewState) -> Frame {
    let meshes = Meshes::empty();
    let scene = Scene::new(vol, st, &meshes).unwrap();
    Renderer::new(Some(2)).unwrap().render(&scene)
}

fn at(o: [f64; 3], d: [f64; 3], t: f64) -> [f64; 3] {
    std::array::from_fn(|a| o[a] + t * d[a])
}

/// Signed distance of `p` from `plane`, positive on the side its normal points to.
fn side(plane: &Plane, p: [f64; 3]) -> f64 {
    let n = plane.unit_normal();
    (0..3).map(|a| n[a] * (p[a] - plane.origin[a])).sum()
}

/// A small deterministic random generator (xorshift64*).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn unit(&mut self) -> [f64; 3] {
        loop {
            let v = [0; 3].map(|_| 2.0 * self.next() - 1.0);
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if l > 0.2 && l <= 1.0 {
                return v.map(|x| x / l);
            }
        }
    }
}

/// Clip planes through the level boundary (x = 8, z = 24), on cell faces of both
/// levels (y = 16), parallel to cell faces and oblique at random: no iso-surface hit and
/// no slice lies on the removed side of any plane, and the kept interval the ray reports
/// is where the planes say.
#[test]
fn nothing_is_hit_behind_a_clip_plane() {
    let file = file();
    let view = testvol::open(&file).unwrap();
    let vol = Volume::new(&view).unwrap();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let mut planes: Vec<Vec<Plane>> = vec![
        vec!["x>8".parse().unwrap()],
        vec!["z<24".parse().unwrap(), "y>16".parse().unwrap()],
        vec!["16,16,16:1,1,0".parse().unwrap()],
    ];
    for _ in 0..6 {
        let k = 1 + (rng.next() * 3.0) as usize;
        planes.push(
            (0..k)
                .map(|_| Plane {
                    origin: [0; 3].map(|_| 10.0 + 12.0 * rng.next()),
                    normal: rng.unit(),
                })
                .collect(),
        );
    }
    let dirs: [[f64; 3]; 3] = [[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.3, -0.5, 0.8]];
    let mut hits = 0;
    let mut clipped_away = 0;
    for (i, clip) in planes.iter().enumerate() {
        for dir in dirs {
            let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
            let mut st = state(&vol, dir.map(|x| x / n));
            st.clip = clip.clone();
            st.slices = vec![Slice::new("16.5,16,16:1,0.2,0".parse().unwrap())];
            st.slices[0].opacity = 0.5;
            st.iso_opacity = 0.5;
            for (o, d, ev) in events(&vol, &st) {
                let kept = ev.iter().find_map(|e| match e {
                    Event::Clip { t0, t1 } => Some((*t0, *t1)),
                    _ => None,
                });
                let (t0, t1) = kept.expect("a clipped ray reports its interval");
                if t0.is_infinite() {
                    clipped_away += 1;
                }
                for e in &ev {
                    let t = match e {
                        Event::Hit { t, .. } | Event::Slice { t, .. } => *t,
                        _ => continue,
                    };
                    hits += 1;
                    assert!(
                        t >= t0 - 1e-9 && t <= t1 + 1e-9,
                        "planes {i}: {t} outside {t0}..{t1}"
                    );
                    let p = at(o, d, t);
                    for plane in clip {
                        let s = side(plane, p);
                        assert!(
                            s > -1e-9,
                            "planes {i}: {e:?} at {p:?} is {s} behind {plane:?}"
                        );
                    }
                }
            }
        }
    }
    assert!(hits > 300, "{hits} hits: the views must see surfaces");
    assert!(clipped_away > 0, "some rays must miss the kept space");
}

/// A plane that removes nothing (the whole data on its kept side) leaves the picture as
/// it was, pixel for pixel, whatever it faces.
#[test]
fn a_plane_that_removes_nothing_changes_nothing() {
    let file = file();
    let view = testvol::open(&file).unwrap();
    let vol = Volume::new(&view).unwrap();
    let st = state(&vol, [0.3, -0.5, 0.8].map(|x| x / 0.989_949_493_661_166_5));
    let plain = render(&vol, &st);
    assert!(plain.hits > 100);
    for clip in ["x>-1", "z<33", "-5,-5,-5:1,1,1", "x<1e6"] {
        let mut cut = st.clone();
        cut.clip = vec![clip.parse().unwrap()];
        let f = render(&vol, &cut);
        assert_eq!(f.rgb, plain.rgb, "{clip}");
        assert_eq!(f.pixel_hits, plain.pixel_hits, "{clip}");
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&f.depth), bits(&plain.depth), "{clip}");
    }
    // And one that removes half of it does change it.
    let mut cut = st.clone();
    cut.clip = vec!["x>16".parse().unwrap()];
    assert_ne!(render(&vol, &cut).rgb, plain.rgb);
}

/// A slice's events lie on its plane and carry the value `probe` gives there; along a
/// line of pixels across the level boundary the values follow the linear field to
/// round-off (no crack where the resolution changes).
#[test]
fn slices_show_the_probed_value_without_a_crack() {
    let file = file();
    let view = testvol::open(&file).unwrap();
    let vol = Volume::new(&view).unwrap();
    let lin = vol.field_index("lin").unwrap();
    let cases: [(&str, [f64; 3]); 3] = [
        ("16,16,16:0,0,1", [0.0, 0.0, -1.0]),
        ("16,16,16:0.3,0.2,1", [0.2, -0.3, -0.93]),
        ("16,24,16:0,1,0", [0.0, -1.0, 0.0]),
    ];
    for (plane, dir) in cases {
        let plane: Plane = plane.parse().unwrap();
        let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
        let mut st = state(&vol, dir.map(|x: f64| x / n));
        st.iso = 100.0; // no iso-surface in the data: only the slice
        st.slices = vec![Slice::new(plane)];
        let mut seen = 0;
        for (o, d, ev) in events(&vol, &st) {
            for e in &ev {
                let Event::Slice { t, value, .. } = e else {
                    continue;
                };
                seen += 1;
                let p = at(o, d, *t);
                assert!(side(&plane, p).abs() < 1e-9, "{p:?} off the plane");
                let probed = qbricks_viewer::probe::probe(&vol, &[p], lin);
                // `probe` reports values at the file's precision (f32).
                assert_eq!(*value as f32, probed[0].values[lin] as f32, "at {p:?}");
                // Inside one level, away from its edges, the linear field is
                // reproduced (near a level boundary the levels are blended, and beyond
                // the outer cell centres the edge cells' values hold).
                let fine = p.iter().all(|&x| (9.5..=22.5).contains(&x));
                let coarse = p.iter().all(|&x| (1.0..=31.0).contains(&x))
                    && p.iter().any(|&x| !(5.0..=27.0).contains(&x));
                if fine || coarse {
                    let want = linear(p);
                    assert!(
                        (value - want).abs() < 1e-5 * want.abs(),
                        "at {p:?}: {value} vs {want}"
                    );
                }
            }
        }
        assert!(seen > 100, "{seen} slice events");
    }
    // Every pixel of a row across the level boundary x = 8, 1/256 of a coarse cell
    // apart: neighbouring values differ by what the field's slope allows over that
    // distance, nothing more (a crack would be a jump that does not shrink with the
    // spacing).
    let mut st = state(&vol, [0.0, 0.0, -1.0]);
    st.iso = 100.0;
    st.slices = vec![Slice::new("16,16,16:0,0,1".parse().unwrap())];
    st.width = 1024;
    st.height = 4;
    st.camera.look_at = [8.0, 16.3, 16.0];
    st.camera.eye = [8.0, 16.3, 60.0];
    st.camera.projection = Projection::Orthographic { width: 8.0 };
    let meshes = Meshes::empty();
    let scene = Scene::new(&vol, &st, &meshes).unwrap();
    let renderer = Renderer::new(Some(1)).unwrap();
    let mut last: Option<([f64; 3], f64)> = None;
    let mut steepest = 0.0f64;
    for x in 0..st.width {
        let trace = renderer.trace_pixel(&scene, x, 2);
        let r = &trace.rays[0];
        let (t, v) = r
            .events
            .iter()
            .find_map(|e| match e {
                Event::Slice { t, value, .. } => Some((*t, *value)),
                _ => None,
            })
            .expect("every pixel sees the slice");
        let p = at(r.origin, r.dir, t);
        if let Some((q, w)) = last {
            let dx = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
            steepest = steepest.max((v - w).abs() / dx);
        }
        last = Some((p, v));
    }
    // The field's slope along x is 0.5; the blend between the levels may steepen it a
    // little, a crack would make it thousands.
    assert!(
        steepest < 2.0,
        "steepest slope {steepest} across the level boundary"
    );
}

/// Two surfaces of the distance field, spheres of radius 6 (across the level boundary)
/// and 3 (in the fine level). A ray through the centre meets them in ray order: with the
/// outer surface translucent, `exact` reports the outer and the inner one; with both
/// translucent, all four crossings; with both opaque, the picture is the outer sphere's
/// alone.
#[test]
fn several_surfaces_are_met_in_ray_order() {
    let file = file();
    let view = testvol::open(&file).unwrap();
    let vol = Volume::new(&view).unwrap();
    let mut st = state(&vol, [0.0, 0.0, -1.0]);
    st.width = 41;
    st.height = 41;
    st.camera.projection = Projection::Orthographic { width: 41.0 };
    let meshes = Meshes::empty();
    let renderer = Renderer::new(Some(1)).unwrap();
    let hits_of = |st: &ViewState| -> Vec<(f64, f64, u32)> {
        let scene = Scene::new(&vol, st, &meshes).unwrap();
        // The centre pixel's ray runs along z through (16.0, 16.0), a cell corner.
        let trace = renderer.trace_pixel(&scene, 20, 20);
        trace.rays[0]
            .events
            .iter()
            .filter_map(|e| match e {
                Event::Hit {
                    t, value, surface, ..
                } => Some((*t, value.unwrap(), surface.unwrap_or(0))),
                _ => None,
            })
            .collect()
    };
    let z = |t: f64| 66.0 - t; // the eye is at z = 66
    st.set_surfaces(&[
        IsoSurface {
            value: 3.0,
            opacity: 1.0,
            colour: None,
        },
        IsoSurface {
            value: 6.0,
            opacity: 0.4,
            colour: Some([1.0, 1.0, 1.0]),
        },
    ]);
    let h = hits_of(&st);
    // The reconstruction of a distance field is not exact (the positions are within a
    // tenth of a cell); the values at the hits are, to round-off.
    let near = |h: &[(f64, f64, u32)], want: &[(f64, u32)]| {
        h.len() == want.len()
            && h.iter()
                .zip(want)
                .all(|(&(t, _, s), &(wz, ws))| s == ws && (z(t) - wz).abs() < 0.1)
    };
    assert!(near(&h, &[(22.0, 1), (19.0, 0)]), "{h:?}");
    for &(_, v, s) in &h {
        assert!((v - [3.0, 6.0][s as usize]).abs() < 1e-9, "{h:?}");
    }
    // Both translucent: in at 6, in at 3, out at 3, out at 6.
    st.iso_opacity = 0.5;
    let h = hits_of(&st);
    assert!(
        near(&h, &[(22.0, 1), (19.0, 0), (13.0, 0), (10.0, 1)]),
        "four crossings in ray order: {h:?}"
    );
    for &(_, v, s) in &h {
        assert!((v - [3.0, 6.0][s as usize]).abs() < 1e-9, "{h:?}");
    }

    // Both opaque: the picture of the nearer (outer) surface alone, pixel for pixel.
    let mut both = st.clone();
    both.iso_opacity = 1.0;
    both.more_isos[0].opacity = 1.0;
    both.more_isos[0].colour = None;
    let mut outer = st.clone();
    outer.set_surfaces(&[IsoSurface {
        value: 6.0,
        opacity: 1.0,
        colour: None,
    }]);
    let (a, b) = (render(&vol, &both), render(&vol, &outer));
    assert!(b.hits > 50);
    assert_eq!(a.rgb, b.rgb);
    assert_eq!(a.pixel_hits, b.pixel_hits);
    // Translucent: the inner surface shows through, so the picture differs there.
    assert_ne!(render(&vol, &st).rgb, b.rgb);
}

/// `slice.clip` removes what lies between the camera and the slice, whichever side the
/// camera is on; the slice itself stays, at the start of what is kept.
#[test]
fn a_clipping_slice_removes_what_is_in_front() {
    let file = file();
    let view = testvol::open(&file).unwrap();
    let vol = Volume::new(&view).unwrap();
    for (dir, normal) in [
        ([0.0, 0.0, -1.0], "0,0,1"),
        ([0.0, 0.0, 1.0], "0,0,1"),
        ([0.0, 0.0, -1.0], "0,0,-1"),
    ] {
        let mut st = state(&vol, dir);
        let mut slice = Slice::new(format!("16,16,16:{normal}").parse().unwrap());
        slice.clip = true;
        st.slices = vec![slice];
        for (o, d, ev) in events(&vol, &st) {
            let slice_t = ev.iter().find_map(|e| match e {
                Event::Slice { t, .. } => Some(*t),
                _ => None,
            });
            for e in &ev {
                if let Event::Hit { t, .. } = e {
                    let st = slice_t.expect("a hit behind the slice means the ray met it");
                    assert!(
                        *t >= st - 1e-9,
                        "hit at z = {} in front of the slice",
                        at(o, d, *t)[2]
                    );
                }
            }
        }
    }
}
