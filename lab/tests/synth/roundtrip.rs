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

/// The writer asks for leaf values a batch at a time: a grid of more leaves than one batch,
/// written from a function, is the same file as the grid written from memory, reads back
/// as that grid, and the progress it reports counts every leaf once.
#[test]
fn grids_written_from_a_function_in_batches_equal_grids_in_memory() {
    use qbricks_preprocess::vdb::write::source::{AnySource, GridSource, LeafShape};
    use qbricks_preprocess::vdb::write::{write_sources, WriteOptions, BATCH_LEAVES};
    use std::borrow::Cow;

    // 24 × 16 × 14 leaves (5376 > one batch), two of them in another root node, with
    // partial masks along one edge; plus a scalar grid sharing the shapes.
    let mut shapes = Vec::new();
    for x in 0..24 {
        for y in 0..16 {
            for z in 0..14 {
                let far = if x == 23 && y < 2 && z == 0 { 4096 } else { 0 };
                let active = if z == 13 {
                    [0x00FF_00FF_00FF_00FF; 8]
                } else {
                    [u64::MAX; 8]
                };
                shapes.push(LeafShape {
                    origin: [8 * x - 64 + far, 8 * y, 8 * z - 40],
                    active,
                });
            }
        }
    }
    assert!(shapes.len() > BATCH_LEAVES);
    let velocity = |i: usize| -> [[f32; 3]; LEAF_VOXELS] {
        std::array::from_fn(|n| {
            let active = (shapes[i].active[n >> 6] >> (n & 63)) & 1 == 1;
            let v = (i * 512 + n) as f32;
            if active {
                [v.sin(), v * 1e-3, -v]
            } else {
                [0.0; 3]
            }
        })
    };
    let speed = |i: usize| -> [f32; LEAF_VOXELS] {
        velocity(i).map(|[a, b, c]| (a * a + b * b + c * c).sqrt())
    };
    let transform = Transform {
        voxel_size: [0.25; 3],
        translation: [0.125; 3],
    };
    let in_memory: Vec<AnyGrid> = vec![
        AnyGrid::Vec3s(Grid {
            name: "vel".into(),
            transform,
            background: [0.0; 3],
            leaves: (0..shapes.len())
                .map(|i| Leaf {
                    origin: shapes[i].origin,
                    active: shapes[i].active,
                    values: Box::new(velocity(i)),
                })
                .collect(),
            tiles: Vec::new(),
        }),
        AnyGrid::Float(Grid {
            name: "speed".into(),
            transform,
            background: 0.0,
            leaves: (0..shapes.len())
                .map(|i| Leaf {
                    origin: shapes[i].origin,
                    active: shapes[i].active,
                    values: Box::new(speed(i)),
                })
                .collect(),
            tiles: vec![Tile {
                origin: [-4096, 0, 0],
                size: 128,
                value: 2.5,
            }],
        }),
    ];
    let sources = vec![
        AnySource::Vec3s(GridSource {
            name: "vel".into(),
            transform,
            background: [0.0; 3],
            tiles: Cow::Borrowed(&[]),
            leaves: shapes.clone(),
            values: Box::new(|i| Cow::Owned(velocity(i))),
        }),
        AnySource::Float(GridSource {
            name: "speed".into(),
            transform,
            background: 0.0,
            tiles: Cow::Owned(vec![Tile {
                origin: [-4096, 0, 0],
                size: 128,
                value: 2.5,
            }]),
            leaves: shapes.clone(),
            values: Box::new(|i| Cow::Owned(speed(i))),
        }),
    ];
    let dir = tempfile::tempdir().expect("tempdir");
    for compression in COMPRESSIONS {
        let (streamed, whole) = (dir.path().join("s.vdb"), dir.path().join("w.vdb"));
        let mut seen = Vec::new();
        let options = WriteOptions::new(compression);
        let size = write_sources(&streamed, &sources, &options, &mut |done| seen.push(done))
            .expect("streamed");
        write_vdb(&whole, &in_memory, compression).expect("whole");
        let bytes = std::fs::read(&streamed).expect("read");
        assert_eq!(bytes.len() as u64, size);
        assert!(
            bytes == std::fs::read(&whole).expect("read"),
            "{compression:?}"
        );
        // Batches of each grid, then the next grid's: counted up to both grids' leaves.
        assert_eq!(seen.last().copied(), Some(2 * shapes.len() as u64));
        assert!(seen.windows(2).all(|w| w[0] < w[1]), "{seen:?}");
        assert_eq!(seen.len(), 2 * shapes.len().div_ceil(BATCH_LEAVES));
        let read = VdbFile::open(&streamed)
            .expect("open")
            .read_all()
            .expect("read all");
        assert_same(&in_memory, &read, &format!("streamed {compression:?}"));
        assert!(
            qbricks_preprocess::vdb::write::size_bound(&sources) >= size,
            "{compression:?}"
        );
    }
}

/// `write_scene` samples its grids leaf by leaf while it writes: what it writes reads back
/// as the grids sampled into memory (velocity, MAC velocity, the speed grids, a layout
/// with an obstacle).
#[test]
fn written_scenes_read_back_as_the_sampled_grids() {
    use lab::synth::{sample_scene, scene_layout, BoxLayout};
    let layout = BoxLayout::from_json(
        r#"{"boxes": [
            {"cell": 0.5, "min": [-2, -2, -2], "max": [6, 2, 2]},
            {"cell": 0.25, "min": [-1, -1.25, -1.25], "max": [4, 1.25, 1.25]}],
           "obstacles": [{"centre": [0, 0, 0], "radius": 0.6}]}"#,
    )
    .expect("layout");
    let dir = tempfile::tempdir().expect("tempdir");
    for (staggered, boxes) in [(false, None), (true, None), (false, Some(layout))] {
        let opts = SynthOptions {
            scene: "wake".into(),
            n0: 24,
            levels: 2,
            compression: Compression::ActiveMask,
            speed_grids: true,
            staggered,
            frame: 1,
            boxes: boxes.clone(),
        };
        let path = dir.path().join("scene.vdb");
        write_scene(&path, &opts).expect("write");
        let layouts = match &boxes {
            Some(b) => b.grids("wake").expect("grids"),
            None => scene_layout("wake", 24, 2).expect("layout"),
        };
        let velocity = sample_scene("wake", &layouts, staggered, 1).expect("velocity");
        let centred = sample_scene("wake", &layouts, false, 1).expect("centred");
        let mut want: Vec<AnyGrid> = velocity.into_iter().map(AnyGrid::Vec3s).collect();
        want.extend(centred.iter().map(|g| AnyGrid::Float(speed_grid(g))));
        let read = VdbFile::open(&path)
            .expect("open")
            .read_all()
            .expect("read");
        assert_same(
            &want,
            &read,
            &format!("staggered {staggered}, boxes {}", boxes.is_some()),
        );
    }
}
