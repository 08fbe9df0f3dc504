//! Layouts, sampling and memory limits of the synthetic scenes.
use super::*;

#[test]
fn wake_layout_nests_and_refines_by_two() {
    let l = scene_layout("wake", 64, 3).expect("layout");
    assert_eq!(l.len(), 3);
    assert_eq!(
        l.iter().map(|g| g.name.as_str()).collect::<Vec<_>>(),
        ["vel_l0", "vel_l1", "vel_l2"]
    );
    let coarse = &l[2];
    assert!((coarse.voxel_size - 0.125).abs() < 1e-15);
    assert_eq!(coarse.hi[0] - coarse.lo[0], 64);
    assert_eq!(coarse.lo, [-16, -16, -16]);
    for w in l.windows(2) {
        let (fine, parent) = (&w[0], &w[1]);
        assert!((parent.voxel_size - 2.0 * fine.voxel_size).abs() < 1e-15);
        for a in 0..3 {
            // Fine box on the parent's cell boundaries, and inside the parent box.
            assert_eq!(fine.lo[a] % 2, 0);
            assert_eq!(fine.hi[a] % 2, 0);
            assert!(fine.lo[a] >= 2 * parent.lo[a] && fine.hi[a] <= 2 * parent.hi[a]);
            assert!(fine.hi[a] - fine.lo[a] < 2 * (parent.hi[a] - parent.lo[a]));
        }
    }
    // The finest box holds the sphere and the rings.
    let f = &l[0];
    for a in 0..3 {
        assert!(f.lo[a] as f64 * f.voxel_size <= WAKE_CORE.min[a]);
        assert!(f.hi[a] as f64 * f.voxel_size >= WAKE_CORE.max[a]);
    }
}

#[test]
fn layouts_nest_for_any_n0_and_level_count() {
    for n0 in [2, 5, 15, 30, 48, 64, 161] {
        for levels in 1..=5 {
            let l = match scene_layout("wake", n0, levels) {
                Ok(l) => l,
                // 161 with 5 levels needs 8 GB of leaves: past the memory limit.
                Err(SynthError::TooLarge { .. }) if (n0, levels) == (161, 5) => continue,
                Err(e) => panic!("n0 {n0}, {levels} levels: {e}"),
            };
            assert_eq!(l.len(), levels as usize);
            let coarse = &l[l.len() - 1];
            let nx = coarse.hi[0] - coarse.lo[0];
            assert!(nx == i64::from(n0) || nx == i64::from(n0) + 1, "{n0}: {nx}");
            for a in 0..3 {
                assert!(coarse.lo[a] as f64 * coarse.voxel_size <= WAKE_DOMAIN.min[a] + 1e-12);
                assert!(coarse.hi[a] as f64 * coarse.voxel_size >= WAKE_DOMAIN.max[a] - 1e-12);
            }
            for w in l.windows(2) {
                let (fine, parent) = (&w[0], &w[1]);
                for a in 0..3 {
                    assert!(fine.lo[a] >= 2 * parent.lo[a] && fine.hi[a] <= 2 * parent.hi[a]);
                    assert!(fine.lo[a] % 2 == 0 && fine.hi[a] % 2 == 0);
                    assert!(fine.hi[a] > fine.lo[a]);
                }
            }
            if levels > 1 {
                let f = &l[0];
                for a in 0..3 {
                    assert!(f.lo[a] as f64 * f.voxel_size <= WAKE_CORE.min[a] + 1e-12);
                    assert!(f.hi[a] as f64 * f.voxel_size >= WAKE_CORE.max[a] - 1e-12);
                }
            }
        }
    }
}

#[test]
fn nested_unit_scenes_shrink_to_the_middle_half() {
    for scene in ["lamb-oseen-nested", "burgers-nested", "abc-nested"] {
        let l = scene_layout(scene, 16, 2).expect("layout");
        assert_eq!(
            l.iter().map(|g| g.name.as_str()).collect::<Vec<_>>(),
            ["vel_l0", "vel_l1"]
        );
        // Coarse: [-1, 1]³ in 16 cells; fine: [-0.5, 0.5]³ in 16 cells of half the width.
        assert_eq!((l[1].lo, l[1].hi), ([-8; 3], [8; 3]));
        assert!((l[0].voxel_size - 0.0625).abs() < 1e-15);
        assert_eq!((l[0].lo, l[0].hi), ([-8; 3], [8; 3]));
        assert_eq!(scene_layout(scene, 16, 3).expect("layout").len(), 3);
        assert_eq!(scene_grids(scene, 8, 2).expect("grids").len(), 2);
    }
    // The plain scenes stay one grid whatever the level count.
    assert_eq!(scene_layout("abc", 16, 3).expect("layout").len(), 1);
}

#[test]
fn grids_hold_exact_velocities_at_voxel_centres() {
    let grids = scene_grids("wake", 16, 2).expect("grids");
    let layouts = scene_layout("wake", 16, 2).expect("layout");
    let flow = analytic::scene("wake").expect("wake");
    for (g, l) in grids.iter().zip(&layouts) {
        assert_eq!(g.active_voxel_count(), l.voxel_count());
        assert_eq!(g.transform, l.transform());
        for leaf in &g.leaves {
            for (ijk, v) in leaf.active_voxels() {
                let p = g.transform.index_to_world(ijk.map(f64::from));
                let u = flow.velocity(p);
                for a in 0..3 {
                    assert_eq!(v[a], u[a] as f32);
                }
            }
        }
    }
}

#[test]
fn single_grid_scenes_and_partial_leaves() {
    let grids = scene_grids("lamb-oseen", 20, 3).expect("grids");
    assert_eq!(grids.len(), 1);
    assert_eq!(grids[0].name, "vel");
    assert_eq!(grids[0].active_voxel_count(), 20 * 20 * 20);
    // -10..10 spans leaves -16..-8, -8..0, 0..8, 8..16: partial masks at both ends.
    assert_eq!(grids[0].leaves.len(), 4 * 4 * 4);
    let counts: Vec<u32> = grids[0]
        .leaves
        .iter()
        .map(|l| l.active.iter().map(|w| w.count_ones()).sum())
        .collect();
    assert!(counts.contains(&512) && counts.contains(&8));
}

#[test]
fn bad_parameters_are_refused() {
    assert!(matches!(
        scene_grids("nope", 16, 2),
        Err(SynthError::UnknownScene { .. })
    ));
    assert!(matches!(
        scene_layout("wake", 1, 2),
        Err(SynthError::OutOfRange { what: "n0", .. })
    ));
    assert!(matches!(
        scene_layout("wake", 16, 0),
        Err(SynthError::OutOfRange { what: "levels", .. })
    ));
    assert!(matches!(
        scene_layout("wake", 4096, 10),
        Err(SynthError::TooLarge { .. })
    ));
}

/// The largest allowed parameters overflow a u64 voxel count (2^75 voxels in the finest
/// box): the layout must still be refused with the leaf count saturated, not panic.
#[test]
fn largest_parameters_are_refused_without_overflow() {
    match scene_layout("wake", 1 << 16, 10) {
        Err(SynthError::TooLarge { leaves, bytes, .. }) => {
            assert!(leaves > 1 << 50, "{leaves}");
            assert_eq!(bytes, u64::MAX);
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
    let finest = GridLayout {
        name: "x".into(),
        voxel_size: 1.0,
        lo: [-(1 << 25); 3],
        hi: [1 << 25; 3],
        obstacles: Vec::new(),
    };
    assert_eq!(finest.voxel_count(), u64::MAX);
}

/// `abc --n0 1024` has exactly 2^30 voxels, which the old voxel limit let through while
/// its leaves take 13 GB: the limit counts leaf bytes, so it is refused before sampling.
#[test]
fn limit_counts_leaf_memory_not_voxels() {
    match scene_layout("abc", 1024, 1) {
        Err(SynthError::TooLarge { leaves, bytes, .. }) => {
            assert_eq!(leaves, 128 * 128 * 128);
            assert!(bytes > 12 << 30, "{bytes}");
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
    // The speed grids count too: a scene that fits alone can be refused with them.
    let layouts = scene_layout("abc", 656, 1).expect("fits without speed grids");
    check_memory(&Request::n0("abc", 656), &layouts, false).expect("fits");
    assert!(matches!(
        check_memory(&Request::n0("abc", 656), &layouts, true),
        Err(SynthError::TooLarge { .. })
    ));
}

/// `leaf_count` counts exactly the leaves `sample_grid` allocates, partial ones included.
#[test]
fn leaf_count_matches_sampled_leaves() {
    for (scene, n0, levels) in [("wake", 16, 3), ("wake", 13, 2), ("abc", 20, 1)] {
        let layouts = scene_layout(scene, n0, levels).expect("layout");
        let grids = scene_grids(scene, n0, levels).expect("grids");
        for (l, g) in layouts.iter().zip(&grids) {
            assert_eq!(l.leaf_count(), g.leaves.len() as u64, "{scene} {}", l.name);
        }
    }
}

#[test]
fn deterministic() {
    assert_eq!(
        scene_grids("wake", 16, 2).expect("a"),
        scene_grids("wake", 16, 2).expect("b")
    );
}

/// A layout file of `docs/bench/layouts/`.
fn layout_file(name: &str) -> BoxLayout {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../docs/bench/layouts")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
    BoxLayout::from_json(&text).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn level_box(cell: f64, min: [f64; 3], max: [f64; 3]) -> LevelBox {
    LevelBox { cell, min, max }
}

/// Issue 33's independent layout: the grids asked for, finest first, named as the bake
/// expects, cell-centred (translation h/2).
#[test]
fn independent_layout_makes_the_grids_asked_for() {
    let layout = layout_file("independent.json");
    let grids = layout.grids("wake").expect("valid");
    let cells: Vec<[i64; 3]> = grids
        .iter()
        .map(|g| std::array::from_fn(|a| g.hi[a] - g.lo[a]))
        .collect();
    assert_eq!(cells, [[176, 96, 96], [160, 80, 80], [128, 64, 64]]);
    assert_eq!(
        grids.iter().map(|g| g.name.as_str()).collect::<Vec<_>>(),
        ["vel_l0", "vel_l1", "vel_l2"]
    );
    assert_eq!(
        grids.iter().map(|g| g.voxel_size).collect::<Vec<_>>(),
        [1.0 / 64.0, 1.0 / 32.0, 1.0 / 16.0]
    );
    assert_eq!(grids[2].lo, [-32, -32, -32]);
    assert_eq!(grids[1].lo, [-32, -40, -40]);
    assert_eq!(grids[0].hi, [128, 48, 48]);
    for g in &grids {
        assert_eq!(g.transform().translation, [0.5 * g.voxel_size; 3]);
        // The sphere is solid on every level, as a solver writes it.
        assert_eq!(
            g.obstacles,
            [Obstacle {
                centre: [0.0; 3],
                radius: 0.5
            }]
        );
    }
}

/// Voxels inside an obstacle are inactive, on every level; blocks with no active voxel are
/// not stored, and the leaf count stays an upper bound.
#[test]
fn obstacles_leave_their_voxels_inactive() {
    let layout = BoxLayout {
        description: String::new(),
        boxes: vec![
            level_box(1.0 / 16.0, [-1.0; 3], [1.0; 3]),
            level_box(1.0 / 32.0, [-0.75; 3], [0.75; 3]),
        ],
        obstacles: vec![Obstacle {
            centre: [0.0; 3],
            radius: 0.5,
        }],
    };
    let layouts = layout.grids("abc").expect("valid");
    let grids = sample_scene("abc", &layouts, false, 1).expect("grids");
    let ball = layout.obstacles[0];
    for (g, l) in grids.iter().zip(&layouts) {
        let mut inside = 0u64;
        let [nx, ny, nz] = [0, 1, 2].map(|a| l.hi[a] - l.lo[a]);
        for i in 0..nx * ny * nz {
            let ijk = [
                l.lo[0] + i / (ny * nz),
                l.lo[1] + (i / nz) % ny,
                l.lo[2] + i % nz,
            ];
            inside += u64::from(ball.contains(l.centre(ijk)));
        }
        assert!(inside > 0, "{}", l.name);
        assert_eq!(
            g.active_voxel_count(),
            l.voxel_count() - inside,
            "{}",
            l.name
        );
        for leaf in &g.leaves {
            assert!(leaf.active != [0; 8], "{}: an empty leaf", l.name);
            for (ijk, _) in leaf.active_voxels() {
                assert!(!ball.contains(l.centre(ijk.map(i64::from))));
            }
        }
        assert!(g.leaves.len() as u64 <= l.leaf_count());
    }
    // The finest grid (h = 1/32 here) loses whole blocks to the sphere.
    assert!((grids[0].leaves.len() as u64) < layouts[0].leaf_count());
    // Refused: too many, or not finite, or not positive.
    for (obstacles, kind) in [
        (vec![ball; MAX_OBSTACLES + 1], "obstacles, at most"),
        (
            vec![Obstacle {
                centre: [f64::NAN, 0.0, 0.0],
                radius: 1.0,
            }],
            "obstacles[0]: centre [NaN, 0.0, 0.0] and radius 1 must be finite",
        ),
        (
            vec![
                ball,
                Obstacle {
                    centre: [0.0; 3],
                    radius: 0.0,
                },
            ],
            "obstacles[1]: centre",
        ),
    ] {
        let mut l = layout.clone();
        l.obstacles = obstacles;
        match l.grids("abc") {
            Err(SynthError::Layout(e)) => assert!(e.to_string().contains(kind), "{e}"),
            other => panic!("expected a layout error, got {other:?}"),
        }
    }
}

/// A layout round-trips: file → grids → layout gives the same boxes, JSON → layout → JSON
/// the same layout, and the layout of `wake --n0 128 --levels 3` written as a file is that
/// scene's grids exactly.
#[test]
fn layouts_round_trip() {
    for name in ["independent.json", "wake128.json"] {
        let layout = layout_file(name);
        assert!(!layout.description.is_empty(), "{name}");
        let grids = layout.grids("wake").expect(name);
        let back = BoxLayout::of_grids(&grids);
        assert_eq!(back.boxes, layout.boxes, "{name}");
        assert_eq!(
            BoxLayout::from_json(&layout.to_json()).expect("own JSON"),
            layout
        );
    }
    let wake = scene_layout("wake", 128, 3).expect("wake");
    assert_eq!(
        layout_file("wake128.json").grids("wake").expect("valid"),
        wake
    );
    // And every `--n0`/`--levels` layout is a valid box layout of the same grids.
    for (n0, levels) in [(16, 1), (16, 3), (13, 2), (48, 4)] {
        let grids = scene_layout("wake", n0, levels).expect("wake");
        assert_eq!(
            BoxLayout::of_grids(&grids).grids("wake").expect("valid"),
            grids,
            "n0 {n0}, {levels} levels"
        );
    }
}

/// A finer box whose faces lie between the coarser box's cells is a valid layout (its
/// coarse cells are partly covered, which the bake handles), and faces may touch.
#[test]
fn partly_covered_coarse_cells_and_touching_faces_are_allowed() {
    let layout = BoxLayout {
        description: String::new(),
        boxes: vec![
            level_box(1.0, [0.0; 3], [4.0; 3]),
            level_box(0.5, [0.5, 0.0, 0.0], [4.0, 2.5, 1.5]),
        ],
        obstacles: Vec::new(),
    };
    let grids = layout.grids("abc").expect("valid");
    assert_eq!(grids[0].lo, [1, 0, 0]);
    assert_eq!(grids[0].hi, [8, 5, 3]);
    // Decimal widths: 0.3 / 0.1 is not a whole number in binary, but near enough.
    let decimal = BoxLayout {
        description: String::new(),
        boxes: vec![
            level_box(0.1, [-0.3, 0.0, 0.0], [0.7, 0.5, 0.5]),
            level_box(0.05, [-0.1, 0.1, 0.1], [0.3, 0.3, 0.3]),
        ],
        obstacles: Vec::new(),
    };
    let grids = decimal.grids("abc").expect("valid");
    assert_eq!(grids[1].lo, [-3, 0, 0]);
    assert_eq!(grids[0].hi, [6, 6, 6]);
}

/// A change made to a good layout.
type Edit = Box<dyn Fn(&mut BoxLayout)>;

/// Every way a layout can be wrong is refused with its own kind, naming the box, the axis
/// and the side; the message says what was expected.
#[test]
fn bad_layouts_are_refused() {
    let good = || layout_file("independent.json");
    let with = |edit: &dyn Fn(&mut BoxLayout)| {
        let mut l = good();
        edit(&mut l);
        l.grids("wake")
    };
    let cases: Vec<(Edit, &str)> = vec![
        (Box::new(|l| l.boxes.clear()), "0 boxes, expected 1 to 10"),
        (
            Box::new(|l| {
                for k in 3..11 {
                    let h = 1.0 / f64::from(1u32 << (k + 4));
                    l.boxes.push(level_box(h, [0.0; 3], [h; 3]));
                }
            }),
            "11 boxes, expected 1 to 10",
        ),
        (
            Box::new(|l| l.boxes[0].cell = 0.0),
            "boxes[0]: cell width 0 is not a finite positive number",
        ),
        (
            Box::new(|l| l.boxes[0].cell = f64::NAN),
            "boxes[0]: cell width NaN",
        ),
        (
            Box::new(|l| l.boxes.reverse()),
            "boxes[1]: cell width 0.03125, expected 0.0078125 (half of boxes[0]'s",
        ),
        (
            Box::new(|l| l.boxes[2].cell = 1.0 / 128.0),
            "boxes[2]: cell width 0.0078125, expected 0.015625",
        ),
        (
            Box::new(|l| l.boxes[1].max[0] = 4.01),
            "boxes[1]: x max 4.01 does not lie on the box's cells (a multiple of the cell width 0.03125; the nearest are 4 and 4.03125)",
        ),
        (
            Box::new(|l| l.boxes[2].min[2] = f64::INFINITY),
            "boxes[2]: z min is inf, not a finite number",
        ),
        (
            Box::new(|l| l.boxes[1].max[1] = -1.25),
            "boxes[1]: y from -1.25 to -1.25 holds no cell (max must be above min)",
        ),
        (
            Box::new(|l| l.boxes[0].max[0] = -3.0),
            "boxes[0]: x from -2 to -3 holds no cell",
        ),
        (
            Box::new(|l| {
                l.boxes.truncate(1);
                l.boxes[0].cell = 1e-4;
                l.boxes[0].max[0] = 7.0;
            }),
            "boxes[0]: x from -2 to 7 holds 90000 cells, more than the 65536 a box may hold along an axis",
        ),
        (
            Box::new(|l| l.boxes[2].max[0] = 4.5),
            "boxes[2]: x max 4.5 is outside boxes[1] (x from -1 to 4): every box must lie inside the one before",
        ),
        (
            Box::new(|l| l.boxes[1].min[2] = -2.5),
            "boxes[1]: z min -2.5 is outside boxes[0] (z from -2 to 2)",
        ),
        (
            Box::new(|l| {
                l.boxes[0].min[1] = -1e9;
            }),
            "boxes[0]: reaches 1e9 from the origin, 6.400e10 cells of the finest width 0.015625 out",
        ),
    ];
    for (edit, message) in &cases {
        match with(edit.as_ref()) {
            Err(SynthError::Layout(e)) => {
                let text = e.to_string();
                assert!(text.starts_with(message), "{text}\nexpected: {message}");
            }
            other => panic!("expected a layout error ({message}), got {other:?}"),
        }
    }
    // Kinds, for code that matches on them.
    assert!(matches!(
        with(&|l| l.boxes[2].max[0] = 4.5),
        Err(SynthError::Layout(LayoutError::NotNested {
            index: 2,
            axis: 0,
            side: Side::Max,
            ..
        }))
    ));
    // Within every per-box bound, but more leaves than any scene may take.
    let huge = BoxLayout {
        description: String::new(),
        boxes: vec![level_box(1.0, [0.0; 3], [65536.0, 65536.0, 8.0])],
        obstacles: Vec::new(),
    };
    match huge.grids("wake") {
        Err(e @ SynthError::TooLarge { .. }) => {
            let text = e.to_string();
            assert!(
                text.starts_with(
                    "scene \"wake\" on 1 nested box(es) in 1 grid(s) needs 67108864 leaves"
                ),
                "{text}"
            );
            assert!(
                text.ends_with("use smaller boxes, coarser cells or fewer levels"),
                "{text}"
            );
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
}

#[test]
fn layout_json_errors_say_what_a_layout_is() {
    for (text, says) in [
        ("", "EOF while parsing"),
        ("{\"boxes\": []", "EOF while parsing"),
        ("{\"levels\": []}", "unknown field `levels`"),
        (
            "{\"boxes\": [{\"cell\": 1, \"min\": [0, 0], \"max\": [1, 1, 1]}]}",
            "invalid length 2",
        ),
        (
            "{\"boxes\": [{\"cell\": 1, \"min\": [0, 0, 0]}]}",
            "missing field `max`",
        ),
    ] {
        let e = BoxLayout::from_json(text).expect_err(text);
        let msg = e.to_string();
        assert!(msg.starts_with("not a box layout: "), "{msg}");
        assert!(msg.contains(says), "{text}: {msg}");
        assert!(msg.contains("coarsest first"), "{msg}");
    }
}
