//! Tests of the active tree: its walk against the file's, and group starts.

use super::*;
use crate::lattice::Lattices;
use crate::testvol;
use crate::volume::Volume;
use format::kd::{Skip, SKIPPED};

/// `(region, t0 bits, t1 bits)` of every region the file's walk gives `exact` (the
/// regions whose range holds `iso`), and the same from the active tree.
type Seg = (u32, u64, u64);

fn both(vol: &Volume, iso: f64, o: [f64; 3], d: [f64; 3], t: (f64, f64)) -> [Vec<Seg>; 2] {
    let mut stack = Vec::new();
    let mut file = Vec::new();
    let skip = Skip {
        field: 0,
        keep: |a: f32, b: f32| range_holds(a, b, iso),
        across_gaps: true,
    };
    let packed = vol.packed(0);
    crate::traverse::segments_skipping(
        vol,
        packed.as_deref(),
        o,
        d,
        t.0,
        t.1,
        &mut stack,
        &skip,
        |s| {
            if s.region != SKIPPED && range_holds(s.min, s.max, iso) {
                file.push((s.region, s.t0.to_bits(), s.t1.to_bits()));
            }
            true
        },
    );
    let tree = ActiveTree::uncut(vol, 0, iso).expect("a valid tree");
    let mut active = Vec::new();
    tree.segments(
        vol,
        Start::Root,
        o,
        d,
        t.0,
        t.1,
        None,
        &mut stack,
        |s, leaf| {
            let (l, inexact) = (leaf.lattices, leaf.inexact);
            let want = Lattices::of(vol, s.region as usize);
            assert_eq!(l, want.as_slice(), "lattices of region {}", s.region);
            assert_eq!(inexact, want.inexact);
            active.push((s.region, s.t0.to_bits(), s.t1.to_bits()));
            true
        },
    );
    [file, active]
}

/// Deterministic numbers in `[0, 1)`.
fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

/// Rays from anywhere in every direction, rays along cell faces and level boundaries
/// (axis-parallel, on whole coordinates), rays starting inside or far away, negative
/// `t` ranges, and data placed at 1e6: the active walk lists exactly the regions the file's walk
/// lets `exact` search, in the same order, with bit-identical `t`.
#[test]
fn the_active_walk_gives_the_file_walks_segments_bit_for_bit() {
    for offset in [[0.0; 3], [1e6, -1e6, 1e6]] {
        let shell = move |p: [f64; 3]| {
            let r2: f64 = (0..3).map(|a| (p[a] - offset[a] - 8.3).powi(2)).sum();
            r2.sqrt()
        };
        let file = testvol::nested(8, offset, &[("r", &shell)], 3);
        let view = testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let c = vol.to_local(offset.map(|x| x + 8.0));
        let mut seed = 7;
        let mut checked = 0;
        for iso in [2.5, 4.0, 6.0] {
            let mut rays = Vec::new();
            for _ in 0..400 {
                let o: [f64; 3] = std::array::from_fn(|a| c[a] + 24.0 * (lcg(&mut seed) - 0.5));
                let d: [f64; 3] = std::array::from_fn(|_| lcg(&mut seed) - 0.5);
                rays.push((o, d, (-30.0, 30.0)));
                rays.push((o, d, (0.0, f64::INFINITY)));
            }
            for a in 0..3 {
                for k in 0..=16 {
                    let mut o = [c[0] - 8.0, c[1] - 8.0, c[2] - 8.0];
                    o[(a + 1) % 3] += k as f64;
                    o[(a + 2) % 3] += (k % 5) as f64 * 2.0;
                    let mut d = [0.0; 3];
                    d[a] = if k % 2 == 0 { 1.0 } else { -1.0 };
                    o[a] -= 20.0 * d[a];
                    rays.push((o, d, (0.0, f64::INFINITY)));
                    let mut d2 = d;
                    d2[(a + 1) % 3] = 0.5;
                    rays.push((o, d2, (0.0, 100.0)));
                }
            }
            // Rays from far away (the walk's `f32` boxes are tested on the ray
            // moved to the data's box) aimed at whole and half coordinates, where
            // region faces and level boundaries lie.
            for k in 0..200 {
                let target: [f64; 3] = std::array::from_fn(|a| {
                    c[a] + ((24.0 * (lcg(&mut seed) - 0.5)) * 2.0).round() / 2.0
                });
                let d: [f64; 3] = std::array::from_fn(|_| lcg(&mut seed) - 0.5);
                let far = [1e2, 1e4, 1e6][k % 3];
                let o: [f64; 3] = std::array::from_fn(|a| target[a] - far * d[a]);
                rays.push((o, d, (0.0, f64::INFINITY)));
            }
            for (o, d, t) in rays {
                let [file, active] = both(&vol, iso, o, d, t);
                assert_eq!(file, active, "iso {iso}, ray {o:?} + t {d:?}, t in {t:?}");
                checked += usize::from(!file.is_empty());
            }
        }
        assert!(
            checked > 500,
            "only {checked} rays met a region of the shell"
        );
    }
}

/// An iso value no region holds gives an empty tree (no walk at all), and a cache of
/// accelerations keeps one per key: asking again returns the same tree.
#[test]
fn no_region_holds_the_value_so_the_tree_is_empty_and_trees_are_kept() {
    use crate::accel::{AccelCache, AccelKey, KEEP};
    let f = |p: [f64; 3]| p[0] + 0.5 * p[1];
    let file = testvol::nested(4, [0.0; 3], &[("f", &f)], 2);
    let view = testvol::open(&file).expect("opens");
    let vol = Volume::new(&view).expect("volume");
    let mut stack = Vec::new();
    for iso in [-1e3, 1e3, f64::NAN] {
        let tree = ActiveTree::of(&vol, 0, iso).expect("a valid tree");
        assert!(tree.walk.root.is_none(), "iso {iso}");
        let mut n = 0;
        tree.segments(
            &vol,
            Start::Root,
            [-50.0; 3],
            [1.0, 1.0, 1.0],
            0.0,
            1e3,
            None,
            &mut stack,
            |_, _| {
                n += 1;
                true
            },
        );
        assert_eq!(n, 0);
    }
    let mut cache = AccelCache::default();
    let mut accel = |field: usize, iso: f64| {
        let band = (iso, iso);
        cache.get(AccelKey { field, iso, band })
    };
    let a = accel(0, 3.0);
    assert!(a.active_tree(&vol).expect("field 0").walk.root.is_some());
    assert!(std::sync::Arc::ptr_eq(&a, &accel(0, 3.0)));
    for i in 0..KEEP {
        accel(0, 10.0 + i as f64);
    }
    // As many newer values as the cache keeps pushed the first one out: it is built anew.
    assert!(!std::sync::Arc::ptr_eq(&a, &accel(0, 3.0)));
    assert!(accel(1, 3.0).active_tree(&vol).is_none(), "no field 1");
}

/// The segments of one ray walked from `start`.
fn from(vol: &Volume, tree: &ActiveTree, start: Start, o: [f64; 3], d: [f64; 3]) -> Vec<Seg> {
    let mut stack = Vec::new();
    let mut out = Vec::new();
    tree.segments(
        vol,
        start,
        o,
        d,
        0.0,
        f64::INFINITY,
        None,
        &mut stack,
        |s, _| {
            out.push((s.region, s.t0.to_bits(), s.t1.to_bits()));
            true
        },
    );
    out
}

/// Every camera ray through a group of pixels (at the group's corners and edges, at
/// pixel centres and at random sub-pixel offsets) gets from the group's start exactly
/// the segments it gets from the root: perspective cameras outside, inside and far
/// from the data, looking along an axis (rays on cell faces and level boundaries) and
/// obliquely, orthographic ones, images whose last groups are cut, data at 1e6. Groups
/// that see nothing and groups that start below the root both occur.
#[test]
fn a_group_of_camera_rays_gets_the_same_segments_from_its_start_as_from_the_root() {
    use crate::camera::{Camera, Projection};
    use glam::DVec3;
    let mut seed = 11;
    let (mut nothing, mut below_root, mut rays_met) = (0, 0, 0);
    for offset in [[0.0; 3], [1e6, -1e6, 1e6]] {
        let shell = move |p: [f64; 3]| {
            let r2: f64 = (0..3).map(|a| (p[a] - offset[a] - 8.3).powi(2)).sum();
            r2.sqrt()
        };
        let file = testvol::nested(8, offset, &[("r", &shell)], 3);
        let view = testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let frame = DVec3::from_array(vol.frame);
        let at = |p: [f64; 3]| std::array::from_fn(|a| p[a] + offset[a]);
        let persp = |fov_deg| Projection::Perspective { fov_deg };
        let cameras = [
            // Outside, oblique.
            (at([30.0, -20.0, 14.0]), at([8.0, 8.0, 8.0]), persp(30.0)),
            // Inside the data, near the shell.
            (at([8.2, 8.1, 8.4]), at([14.0, 9.0, 7.0]), persp(70.0)),
            // Along the z axis through whole coordinates: rays on cell faces.
            (at([8.0, 8.0, 40.0]), at([8.0, 8.0, 0.0]), persp(20.0)),
            // Far away.
            (at([8e4, 3e4, -5e4]), at([8.0, 8.0, 8.0]), persp(0.02)),
            // Orthographic, along x, one pixel per cell.
            (
                at([-20.0, 8.0, 8.0]),
                at([8.0, 8.0, 8.0]),
                Projection::Orthographic { width: 22.0 },
            ),
            // Orthographic, oblique.
            (
                at([20.0, 25.0, 30.0]),
                at([8.0, 8.0, 8.0]),
                Projection::Orthographic { width: 13.0 },
            ),
        ];
        for iso in [2.5, 4.5] {
            let tree = ActiveTree::of(&vol, 0, iso).expect("a valid tree");
            for (eye, look_at, projection) in cameras {
                let cam = Camera {
                    eye,
                    look_at,
                    up: [0.0, 0.0, 1.0],
                    projection,
                };
                let (w, h) = (22u32, 19u32);
                let rays = cam.ray_generator(w, h);
                for (x0, y0, x1, y1) in crate::tiles::Tile::image(w, h).groups(4) {
                    let start = tree.start_in(&rays.frustum(x0, y0, x1, y1, frame));
                    match start {
                        Start::Nothing => nothing += 1,
                        Start::At(r) if Some(r) != tree.walk.root => below_root += 1,
                        _ => {}
                    }
                    let mut points = vec![
                        (x0, y0),
                        (x1, y0),
                        (x0, y1),
                        (x1, y1),
                        (0.5 * (x0 + x1), y0),
                        (x0, 0.5 * (y0 + y1)),
                    ];
                    for _ in 0..12 {
                        points.push((
                            x0 + (x1 - x0) * lcg(&mut seed),
                            y0 + (y1 - y0) * lcg(&mut seed),
                        ));
                    }
                    for (x, y) in points {
                        let ray = rays.ray(x, y);
                        let o = vol.to_local(ray.origin.to_array());
                        let d = ray.dir.to_array();
                        let want = from(&vol, &tree, Start::Root, o, d);
                        let got = from(&vol, &tree, start, o, d);
                        assert_eq!(
                            got, want,
                            "camera {cam:?}, iso {iso}, pixel ({x}, {y}), start {start:?}"
                        );
                        rays_met += usize::from(!want.is_empty());
                    }
                }
            }
        }
    }
    assert!(nothing > 50, "only {nothing} groups saw nothing");
    assert!(
        below_root > 50,
        "only {below_root} groups started below the root"
    );
    assert!(rays_met > 1000, "only {rays_met} rays met a region");
}

/// A file of one region, whose KD root is a leaf (the packed tree lists no inner node):
/// the region's tree holds it, and its segments are the file walk's, with the surface
/// found along the rays that cross it.
#[test]
fn a_file_of_one_region_has_its_tree() {
    let f = |p: [f64; 3]| (0..3).map(|a| (p[a] - 2.0).powi(2)).sum::<f64>().sqrt();
    let grid = testvol::GridSpec::covering([0.0; 3], [4.0; 3], 0.5);
    let file = testvol::build(&[grid], &[("d", &f)], 64);
    let view = testvol::open(&file).expect("opens");
    let vol = Volume::new(&view).expect("volume");
    assert_eq!(vol.region_count(), 1, "one brick, one region");
    let tree = ActiveTree::uncut(&vol, 0, 1.0).expect("a valid tree");
    assert_eq!(tree.leaf_count(), (1, 1));
    let mut crossed = 0;
    for (o, d) in [
        ([-1.0, 2.1, 1.9], [1.0, 0.0, 0.0]),
        ([2.05, -3.0, 2.2], [0.0, 1.0, 0.0]),
        ([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]),
    ] {
        let [file_segs, tree_segs] = both(&vol, 1.0, o, d, (0.0, 100.0));
        assert_eq!(file_segs, tree_segs, "{o:?} {d:?}");
        crossed += tree_segs.len();
    }
    assert_eq!(crossed, 3);
}
