//! Hard cases for whole images: meshes, shadows, the camera inside the data, offsets by
//! 1e6, dvr clipping and level boundaries, thread counts.

use crate::common;
use crate::hard_rays::{grid16, params, unit, with_volume, JITTERS, REF_STEP, STEP};
use qbricks_viewer::camera::{Camera, Projection};
use qbricks_viewer::mesh::{icosphere, DVec3, Meshes};
use qbricks_viewer::render::{render, Frame, Scene};
use qbricks_viewer::sampling::{Params, Strategy, Tracer};
use qbricks_viewer::shading::{Light, Material};
use qbricks_viewer::testvol;
use qbricks_viewer::transfer::Mode;
use qbricks_viewer::view_state::ViewState;
use qbricks_viewer::volume::Volume;

const ALL_MODES: [(Mode, Strategy); 6] = [
    (Mode::Iso, Strategy::Uniform),
    (Mode::Iso, Strategy::Paper),
    (Mode::Iso, Strategy::Bisect),
    (Mode::Iso, Strategy::Exact),
    (Mode::Dvr, Strategy::Paper),
    (Mode::Dvr, Strategy::Bisect),
];

fn state(vol: &Volume, mode: Mode, strategy: Strategy, iso: f64, camera: Camera) -> ViewState {
    let mut s = ViewState::default_for_volume(vol);
    s.iso_field = "f".into();
    s.mode = mode;
    s.strategy = strategy;
    s.iso = iso;
    s.transfer.sigma = 0.25;
    s.camera = camera;
    s.width = 48;
    s.height = 48;
    s
}

fn frame(vol: &Volume, st: &ViewState, meshes: &Meshes) -> Frame {
    let scene = Scene::new(vol, st, meshes).expect("scene");
    let f = render(&scene);
    assert!(
        f.rgb.iter().flatten().all(|c| c.is_finite()),
        "non-finite pixel"
    );
    f
}

fn ortho_down(centre: [f64; 3], width: f64) -> Camera {
    Camera {
        eye: [centre[0], centre[1], centre[2] + 40.0],
        look_at: centre,
        up: [0.0, 1.0, 0.0],
        projection: Projection::Orthographic { width },
    }
}

#[test]
fn volume_samples_stop_at_the_first_mesh_hit() {
    // Iso plane z = 6 seen from above through a big sphere mesh that covers the view.
    let f = |p: [f64; 3]| p[2];
    with_volume(&[grid16()], &[("f", &f)], 4, |vol| {
        let cam = ortho_down([8.0, 8.0, 6.0], 4.0);
        let sphere = icosphere(DVec3::new(8.0, 8.0, 12.0), 5.0, 3);
        let meshes = Meshes::from_meshes(&[sphere]);
        for (mode, s) in ALL_MODES {
            let st = state(vol, mode, s, 6.0, cam);
            let with = frame(vol, &st, &meshes);
            let without = frame(vol, &st, &Meshes::empty());
            assert_eq!(
                with.hits, 0,
                "{mode} {s}: the volume behind the mesh was hit"
            );
            assert_eq!(
                without.hits, without.rays,
                "{mode} {s}: the plane is not hit everywhere"
            );
            assert_ne!(with.rgb, without.rgb);
            // The mesh is not the background.
            let bg = st.background;
            assert!(
                with.rgb.iter().all(|c| *c != bg),
                "{mode} {s}: background through the mesh"
            );
        }
        // A mesh *behind* the iso plane changes nothing in iso mode.
        let below = Meshes::from_meshes(&[icosphere(DVec3::new(8.0, 8.0, 2.0), 1.5, 2)]);
        let st = state(vol, Mode::Iso, Strategy::Exact, 6.0, cam);
        assert_eq!(
            frame(vol, &st, &below).rgb,
            frame(vol, &st, &Meshes::empty()).rgb
        );
    });
}

#[test]
fn mesh_shadows_on_the_iso_surface() {
    // Light travelling along (1, 0, -1); a sphere of radius 2 at height 4 above the iso
    // plane z = 6 throws its shadow centred at x + 4. Looking straight down, the pixel
    // over the shadow centre gets ambient light only with shadows on.
    let f = |p: [f64; 3]| p[2];
    with_volume(&[grid16()], &[("f", &f)], 4, |vol| {
        let centre = [8.0, 8.0, 6.0];
        let cam = ortho_down(centre, 16.0);
        let sphere = Meshes::from_meshes(&[icosphere(DVec3::new(6.0, 8.0, 10.0), 2.0, 3)]);
        // Pixel over world (10, 8): x = 8 + (px + 0.5 - 24) / 48 * 16.
        let (px, py) = (29usize, 23usize);
        let lit_px = (8usize, 23usize); // world x ≈ 2.8: far from sphere and shadow
        for (mode, s) in ALL_MODES.into_iter().filter(|(m, _)| *m == Mode::Iso) {
            let mut st = state(vol, mode, s, 6.0, cam);
            st.lights = vec![Light::Directional {
                direction: [1.0, 0.0, -1.0],
                colour: [1.0; 3],
                intensity: 1.0,
            }];
            st.material = Material::default();
            st.shadows = false;
            let plain = frame(vol, &st, &sphere);
            st.shadows = true;
            let shadowed = frame(vol, &st, &sphere);
            let at = |fr: &Frame, (x, y): (usize, usize)| fr.rgb[y * 48 + x];
            let (a, b) = (at(&plain, (px, py)), at(&shadowed, (px, py)));
            // Unshadowed: ambient + diffuse·cos 45°; shadowed: ambient only.
            let m = st.material;
            for c in 0..3 {
                assert!(b[c] < a[c], "{s}: shadow not darker: {b:?} vs {a:?}");
                let ratio = b[c] / a[c];
                let want = m.ambient / (m.ambient + m.diffuse * std::f32::consts::FRAC_1_SQRT_2);
                assert!(
                    (ratio - want).abs() < 0.02,
                    "{s}: shadow ratio {ratio}, want {want}"
                );
            }
            // Far from the sphere nothing changes.
            assert_eq!(at(&plain, lit_px), at(&shadowed, lit_px), "{s}");
        }
    });
}

#[test]
fn volume_shadows_through_opacity() {
    // A dvr band around the plane z = 8 lit from above: a sample low in the band lies
    // under the rest of the band, so with shadows its light is attenuated by the
    // band's opacity above it, and the picture gets darker (never brighter).
    let f = |p: [f64; 3]| p[2];
    with_volume(&[grid16()], &[("f", &f)], 4, |vol| {
        let cam = Camera {
            eye: [8.0, -30.0, 8.0],
            look_at: [8.0, 8.0, 8.0],
            up: [0.0, 0.0, 1.0],
            projection: Projection::Orthographic { width: 12.0 },
        };
        for s in [Strategy::Paper, Strategy::Bisect] {
            let mut st = state(vol, Mode::Dvr, s, 8.0, cam);
            st.transfer.sigma = 0.5;
            st.transfer.peak_opacity = 0.3;
            st.lights = vec![Light::Directional {
                direction: [0.0, 0.3, -1.0],
                colour: [1.0; 3],
                intensity: 1.0,
            }];
            st.shadows = false;
            let plain = frame(vol, &st, &Meshes::empty());
            st.shadows = true;
            let shadowed = frame(vol, &st, &Meshes::empty());
            let sum = |fr: &Frame| fr.rgb.iter().flatten().map(|c| f64::from(*c)).sum::<f64>();
            assert!(
                sum(&shadowed) < 0.98 * sum(&plain),
                "{s}: volume shadows do not darken"
            );
            assert!(
                shadowed
                    .rgb
                    .iter()
                    .zip(&plain.rgb)
                    .all(|(a, b)| (0..3).all(|c| a[c] <= b[c] + 1e-6)),
                "{s}: a shadow brightened a pixel"
            );
        }
    });
}

#[test]
fn camera_inside_the_volume_renders_like_the_reference() {
    let f =
        |p: [f64; 3]| ((p[0] - 8.0).powi(2) + (p[1] - 8.0).powi(2) + (p[2] - 8.0).powi(2)).sqrt();
    with_volume(&[grid16()], &[("f", &f)], 4, |vol| {
        // Inside a sphere of radius 5, looking at its wall from 2 units off centre.
        let cam = Camera {
            eye: [9.0, 7.0, 8.5],
            look_at: [14.0, 9.0, 8.0],
            up: [0.0, 0.0, 1.0],
            projection: Projection::Perspective { fov_deg: 70.0 },
        };
        let mut reference = state(vol, Mode::Iso, Strategy::Uniform, 5.0, cam);
        reference.step = REF_STEP;
        let want = frame(vol, &reference, &Meshes::empty());
        assert_eq!(want.hits, want.rays, "the wall surrounds the camera");
        for (mode, s) in ALL_MODES.into_iter().filter(|(m, _)| *m == Mode::Iso) {
            let got = frame(vol, &state(vol, mode, s, 5.0, cam), &Meshes::empty());
            assert_eq!(got.hits, got.rays, "{s}: missed the wall around the camera");
            let p = common::psnr(
                &qbricks_viewer::film::to_rgb8(&got.rgb),
                &qbricks_viewer::film::to_rgb8(&want.rgb),
            );
            assert!(p > 30.0, "{s}: PSNR {p:.1} dB against the reference");
        }
        // dvr: a shell around the wall, seen from inside.
        let mut reference = state(vol, Mode::Dvr, Strategy::Uniform, 5.0, cam);
        reference.step = REF_STEP;
        let want = frame(vol, &reference, &Meshes::empty());
        assert_eq!(want.hits, want.rays, "dvr: the shell surrounds the camera");
        for s in [Strategy::Uniform, Strategy::Paper, Strategy::Bisect] {
            let got = frame(vol, &state(vol, Mode::Dvr, s, 5.0, cam), &Meshes::empty());
            assert_eq!(
                got.hits, got.rays,
                "dvr {s}: missed the shell around the camera"
            );
            let p = common::psnr(
                &qbricks_viewer::film::to_rgb8(&got.rgb),
                &qbricks_viewer::film::to_rgb8(&want.rgb),
            );
            // Measured 44-46 dB; opacity correction or a lost first sample costs far more.
            assert!(p > 35.0, "dvr {s}: PSNR {p:.1} dB against the reference");
        }
    });
}

#[test]
fn images_do_not_change_when_everything_moves_by_a_million() {
    let rel = |p: [f64; 3], o: f64| {
        let (x, y, z) = (p[0] - o - 8.0, p[1] - o - 8.0, p[2] - o - 8.0);
        (x * x + 0.5 * y * y + z * z).sqrt() + 0.2 * (x * 0.9).sin()
    };
    let off = 1e6;
    let f0 = move |p: [f64; 3]| rel(p, 0.0);
    let f1 = move |p: [f64; 3]| rel(p, off);
    let file0 = testvol::nested(8, [0.0; 3], &[("f", &f0)], 4);
    let file1 = testvol::nested(8, [off; 3], &[("f", &f1)], 4);
    let view0 = testvol::open(&file0).expect("open");
    let view1 = testvol::open(&file1).expect("open");
    let vol0 = Volume::new(&view0).expect("volume");
    let vol1 = Volume::new(&view1).expect("volume");
    let cam0 = Camera::frame([0.0; 3], [16.0; 3]);
    let shift = |a: [f64; 3]| a.map(|x| x + off);
    let cam1 = Camera {
        eye: shift(cam0.eye),
        look_at: shift(cam0.look_at),
        ..cam0
    };
    let m0 = Meshes::from_meshes(&[icosphere(DVec3::splat(8.0), 1.5, 2)]);
    let m1 = Meshes::from_meshes(&[icosphere(DVec3::splat(8.0 + off), 1.5, 2)]);
    for (mode, s) in ALL_MODES {
        let mut st0 = state(&vol0, mode, s, 4.0, cam0);
        st0.shadows = true;
        st0.lights = qbricks_viewer::shading::default_lights(&cam0);
        let mut st1 = st0.clone();
        st1.camera = cam1;
        let a = frame(&vol0, &st0, &m0);
        let b = frame(&vol1, &st1, &m1);
        assert!(a.hits > 0, "{mode} {s}");
        let p = common::psnr(
            &qbricks_viewer::film::to_rgb8(&a.rgb),
            &qbricks_viewer::film::to_rgb8(&b.rgb),
        );
        assert!(
            p >= 50.0,
            "{mode} {s}: PSNR {p:.1} dB between the scene and its 1e6 shift"
        );
    }
}

/// Opacity gathered along a world ray in dvr mode.
fn dvr_alpha(vol: &Volume, p: Params, o: [f64; 3], d: [f64; 3], jitter: f64) -> f64 {
    let accel = qbricks_viewer::accel::Accel::new(p.accel_key());
    let mut tr = Tracer::new(vol, &accel, p);
    tr.dvr(
        vol.to_local(o),
        unit(d),
        0.0,
        f64::INFINITY,
        jitter,
        &mut |_, _| [1.0; 3],
    )
    .alpha()
}

#[test]
fn dvr_clipping_to_the_active_box_changes_nothing() {
    // Thin band (sigma 0.02) around planes of a linear field across two levels, rays
    // along faces and level boundaries: clipping rays to the regions that can contribute
    // must not lose (or add) opacity, for every strategy.
    let f = |p: [f64; 3]| 0.2 * p[0] + 0.05 * p[1] - 0.03 * p[2];
    let file = testvol::nested(8, [0.0; 3], &[("f", &f)], 4);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    for y in [4.0, 12.0, 3.0, 5.5] {
        for z in [4.0, 12.0, 8.0] {
            for x_band in [2.0, 4.0, 6.0, 12.0, 13.0] {
                let iso = f([x_band, y, z]);
                for s in [Strategy::Uniform, Strategy::Paper, Strategy::Bisect] {
                    for j in JITTERS {
                        let mut p = params(&vol, s, STEP, Mode::Dvr, iso);
                        p.tf.band.sigma = 0.02;
                        let mut pc = p;
                        pc.clip_to_active(&vol);
                        let (o, d) = ([-1.0, y, z], [1.0, 0.0, 0.0]);
                        let a = dvr_alpha(&vol, p, o, d, j);
                        let b = dvr_alpha(&vol, pc, o, d, j);
                        assert!(
                            (a - b).abs() < 1e-9,
                            "{s} jitter {j} band at x={x_band} (y {y}, z {z}): alpha {a} unclipped, {b} clipped"
                        );
                        // bisect never misses the band on a monotone ray.
                        if s == Strategy::Bisect {
                            assert!(
                                b > 0.0,
                                "bisect missed the band at x={x_band} (y {y}, z {z}, jitter {j})"
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn dvr_opacity_across_level_boundaries_matches_the_reference() {
    // A smooth band (sigma 0.2, k 4 on a field of slope 0.2 along x, so ±4 units; peak
    // 0.05 so it does not saturate) centred on either side of, and on, the level
    // boundaries x = 4 and x = 12 and near the data's start: the opacity-corrected sum of
    // every strategy at step 0.5 must approximate the reference (uniform, step 0.01).
    //
    // Measured worst relative errors (this commit): paper < 5 %, bisect 9 %, uniform
    // 13 %; uniform and bisect err systematically where the band meets a level boundary
    // or the data's start (uniform low before x = 4 and high at x = 12, bisect the other
    // way), paper does not. Cause: uniform weights a sample by the step after it (left
    // Riemann sum) and bisect by the distance before it (right sum); where the step
    // changes from h1 to h2 both leave an O((h1 - h2)/2 · opacity) term that midpoints
    // (paper) cancel. Uniform also drops [t0, first sample) at the data's entry (the
    // sample exactly on the support boundary has no weight and is skipped).
    // Bounds below: the measured errors plus a margin, so a regression shows.
    let f = |p: [f64; 3]| 0.2 * p[0] + 0.05 * p[1] - 0.03 * p[2];
    let file = testvol::nested(8, [0.0; 3], &[("f", &f)], 4);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    for (y, z) in [(4.0, 4.0), (8.0, 8.0), (5.5, 12.0), (3.0, 8.0)] {
        for x_band in [2.0, 3.5, 4.0, 4.5, 6.0, 8.0, 12.0] {
            let iso = f([x_band, y, z]);
            let (o, d) = ([-1.0, y, z], [1.0, 0.0, 0.0]);
            let mut rp = params(&vol, Strategy::Uniform, REF_STEP, Mode::Dvr, iso);
            rp.tf.band.sigma = 0.2;
            rp.tf.band.k = 4.0;
            rp.tf.band.peak_opacity = 0.05;
            let want = dvr_alpha(&vol, rp, o, d, 0.5);
            assert!(want > 0.05, "reference sees no band at x={x_band}");
            for (s, bound) in [
                (Strategy::Uniform, 0.16),
                (Strategy::Paper, 0.06),
                (Strategy::Bisect, 0.11),
            ] {
                for j in JITTERS {
                    let mut p = rp;
                    p.strategy = s;
                    p.step = STEP;
                    let got = dvr_alpha(&vol, p, o, d, j);
                    let rel = (got - want).abs() / want;
                    assert!(
                        rel < bound,
                        "{s} jitter {j}: alpha {got:.4} vs reference {want:.4}, {:.1} % off (band at x={x_band}, y {y}, z {z})",
                        100.0 * rel
                    );
                }
            }
        }
    }
}

#[test]
fn meshes_and_shadows_render_the_same_on_any_thread_count() {
    let f =
        |p: [f64; 3]| ((p[0] - 8.0).powi(2) + (p[1] - 8.0).powi(2) + (p[2] - 8.0).powi(2)).sqrt();
    with_volume(&[grid16()], &[("f", &f)], 4, |vol| {
        let cam = Camera::frame([0.0; 3], [16.0; 3]);
        let meshes = Meshes::from_meshes(&[icosphere(DVec3::new(8.0, 8.0, 13.5), 1.5, 3)]);
        for (mode, s) in [(Mode::Iso, Strategy::Exact), (Mode::Dvr, Strategy::Bisect)] {
            let mut st = state(vol, mode, s, 4.0, cam);
            st.shadows = true;
            st.spp = 2;
            st.seed = 11;
            st.lights = qbricks_viewer::shading::default_lights(&cam);
            let scene = Scene::new(vol, &st, &meshes).expect("scene");
            let one = qbricks_viewer::render::render_with_threads(&scene, 1).expect("pool");
            let two = qbricks_viewer::render::render_with_threads(&scene, 2).expect("pool");
            assert!(one.hits > 0);
            assert_eq!(one, two, "{mode} {s}: thread count changed the frame");
        }
    });
}
