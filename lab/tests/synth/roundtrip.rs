//! Writer → our reader: everything `vdb::write` writes comes back unchanged through
//! `vdb::VdbFile` (voxels, inactive values, tiles, transforms, metadata), for every
//! compression, on synth scenes and on randomised sparse grids.

use std::collections::BTreeMap;

use crate::common::Rng;

use lab::synth::{scene_grids, speed_grid, write_scene, SynthOptions};
use qbricks_preprocess::grid::{AnyGrid, Grid, Leaf, Tile, Transform, LEAF_VOXELS};
use qbricks_preprocess::vdb::write::{write_vdb, Compression};
use qbricks_preprocess::vdb::VdbFile;

const COMPRESSIONS: [Compression; 3] =
    [Compression::None, Compression::ActiveMask, Compression::Zip];

/// Leaves and tiles sorted by origin: the file stores them in tree order.
fn normalized<V: Clone>(g: &Grid<V>) -> Grid<V> {
    let mut g = g.clone();
    g.leaves.sort_by_key(|l| l.origin);
    g.tiles.sort_by_key(|t| t.origin);
    g
}

fn normalized_any(g: &AnyGrid) -> AnyGrid {
    match g {
        AnyGrid::Float(g) => AnyGrid::Float(normalized(g)),
        AnyGrid::Double(g) => AnyGrid::Double(normalized(g)),
        AnyGrid::Vec3s(g) => AnyGrid::Vec3s(normalized(g)),
        AnyGrid::Vec3d(g) => AnyGrid::Vec3d(normalized(g)),
    }
}

fn round_trip(grids: &[AnyGrid], compression: Compression) -> Vec<AnyGrid> {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("rt.vdb");
    write_vdb(&path, grids, compression).expect("write");
    VdbFile::open(&path)
        .expect("open")
        .read_all()
        .expect("read")
}

fn assert_same(written: &[AnyGrid], read: &[AnyGrid], what: &str) {
    assert_eq!(written.len(), read.len(), "{what}");
    for (w, r) in written.iter().zip(read) {
        assert!(
            normalized_any(w) == normalized_any(r),
            "{what}: grid differs after the round trip"
        );
    }
}

#[test]
fn synth_scenes_round_trip() {
    for scene in ["wake", "wake-single", "lamb-oseen", "burgers", "abc"] {
        let vel = scene_grids(scene, 16, 2).expect("grids");
        let mut grids: Vec<AnyGrid> = vel.iter().map(|g| AnyGrid::Float(speed_grid(g))).collect();
        grids.extend(vel.into_iter().map(AnyGrid::Vec3s));
        for c in COMPRESSIONS {
            assert_same(&grids, &round_trip(&grids, c), &format!("{scene} {c:?}"));
        }
    }
}

#[test]
fn write_scene_metadata_reads_back() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("wake.vdb");
    let opts = SynthOptions {
        scene: "wake".into(),
        n0: 16,
        levels: 3,
        compression: Compression::Zip,
        speed_grids: true,
        staggered: false,
        frame: 1,
        boxes: None,
    };
    let (summary, _) = write_scene(&path, &opts).expect("write");
    let file = VdbFile::open(&path).expect("open");
    let names: Vec<&str> = file.grids().iter().map(|g| g.name.as_str()).collect();
    let want: Vec<&str> = summary.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, want);
    for (g, s) in file.grids().iter().zip(&summary) {
        assert_eq!(g.value_type.name(), s.value_type);
    }
    let grids = file.read_all().expect("read");
    for (g, s) in grids.iter().zip(&summary) {
        let count = match g {
            AnyGrid::Vec3s(g) => g.active_voxel_count(),
            AnyGrid::Float(g) => g.active_voxel_count(),
            _ => panic!("unexpected grid type"),
        };
        assert_eq!(count, s.active_voxels);
    }
}

/// A random sparse grid: leaves with random masks whose inactive voxels hold a random
/// mix of background, −background and up to three other values (so every node-compression
/// case occurs), plus random active tiles at each level; negative coordinates included.
fn random_grid<V: Copy>(
    rng: &mut Rng,
    name: &str,
    value: impl Fn(&mut Rng) -> V,
    neg: impl Fn(V) -> V,
) -> Grid<V> {
    let background = value(rng);
    let mut leaves: BTreeMap<[i32; 3], Leaf<V>> = BTreeMap::new();
    let n_leaves = 1 + rng.below(40);
    for _ in 0..n_leaves {
        // Leaves in a 512³ block around the origin, avoiding the tile area (x ≥ 1024).
        let origin = [0, 1, 2].map(|_| (rng.below(64) as i32 - 32) * 8);
        let mut active = [0u64; 8];
        match rng.below(4) {
            0 => active = [u64::MAX; 8],
            1 => {}
            _ => active
                .iter_mut()
                .for_each(|w| *w = rng.next_u64() & rng.next_u64()),
        }
        let others: Vec<V> = (0..rng.below(4)).map(|_| value(rng)).collect();
        let mode = rng.below(6);
        let values = Box::new(std::array::from_fn(|_| match mode {
            0 => background,
            1 => neg(background),
            _ => match rng.below(2 + others.len() as u64) {
                0 => background,
                1 if mode.is_multiple_of(2) => neg(background),
                k => (k as usize)
                    .checked_sub(2)
                    .and_then(|i| others.get(i).copied())
                    .unwrap_or(background),
            },
        }));
        let mut leaf = Leaf {
            origin,
            active,
            values,
        };
        // Active voxels get fresh values.
        for n in 0..LEAF_VOXELS {
            if leaf.is_active(n) {
                leaf.values[n] = value(rng);
            }
        }
        leaves.insert(origin, leaf);
    }
    let mut tiles = Vec::new();
    for k in 0..rng.below(4) {
        let (size, origin) = match k {
            0 => (8, [1024 + 8 * rng.below(16) as i32, 0, 0]),
            1 => (128, [2048, -128 * (1 + rng.below(8) as i32), 0]),
            2 => (4096, [-8192, 4096, 0]),
            _ => (8, [1024, 8 * 20, -8]),
        };
        tiles.push(Tile {
            origin,
            size,
            value: value(rng),
        });
    }
    let h = 0.01 * (1 + rng.below(100)) as f64;
    Grid {
        name: name.to_string(),
        transform: Transform {
            voxel_size: [h; 3],
            translation: [0, 1, 2].map(|_| rng.below(2001) as f64 * 1e-3 - 1.0),
        },
        background,
        leaves: leaves.into_values().collect(),
        tiles,
    }
}

#[test]
fn random_sparse_grids_round_trip() {
    let mut rng = Rng(0x1234_5678_9ABC_DEF1);
    let small = |r: &mut Rng| (r.below(9) as f64 - 4.0) * 0.5;
    for case in 0..12 {
        let grids = vec![
            AnyGrid::Float(random_grid(&mut rng, "f", |r| small(r) as f32, |v| -v)),
            AnyGrid::Double(random_grid(&mut rng, "d", small, |v| -v)),
            AnyGrid::Vec3s(random_grid(
                &mut rng,
                "v",
                |r| [small(r) as f32, small(r) as f32, small(r) as f32],
                |v| v.map(|c| -c),
            )),
            AnyGrid::Vec3d(random_grid(
                &mut rng,
                "w",
                |r| [small(r), small(r), small(r)],
                |v| v.map(|c| -c),
            )),
        ];
        for c in COMPRESSIONS {
            assert_same(
                &grids,
                &round_trip(&grids, c),
                &format!("case {case} {c:?}"),
            );
        }
    }
}
