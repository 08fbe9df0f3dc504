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
    check_memory("abc", 656, &layouts, false).expect("fits");
    assert!(matches!(
        check_memory("abc", 656, &layouts, true),
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
