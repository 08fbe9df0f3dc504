//! The hostile VDB inputs of issue 32, written at test time with the project's own VDB
//! writer (no OpenVDB needed, nothing binary committed): each is a few kilobytes that once
//! made `qbricks-bake` abort, bake nonsense, or stay silent about a wrong answer.

use std::path::Path;

use preprocess::grid::{AnyGrid, Grid, Leaf, Tile, Transform, LEAF_VOXELS};
use preprocess::vdb::write::{write_vdb, Compression};

/// The inputs [`write`] knows, by file name.
pub const NAMES: &[&str] = &[
    "tile640.vdb",
    "far.vdb",
    "huge_q.vdb",
    "dup_component.vdb",
    "vec3_field.vdb",
    "overlap.vdb",
    "overlap_equal.vdb",
    "nan_two.vdb",
    "density_elsewhere.vdb",
    "density_half.vdb",
];

/// Writes the input `name` (one of [`NAMES`]) into `dir`.
pub fn write(dir: &Path, name: &str) {
    let grids = match name {
        // One active tile-filled box of 640³ voxels (5³ tiles of 128³): 262 M voxels in
        // a file of a few kilobytes.
        "tile640.vdb" => vec![AnyGrid::Vec3s(tiles("vel", 640, [1.0, 0.0, 0.0]))],
        // A small rotating flow placed at 1e300 with voxels of 0.1.
        "far.vdb" => {
            let mut g = box_grid("vel", [0; 3], [8; 3], |i| {
                [i[1] as f32, -(i[0] as f32), 0.0]
            });
            g.transform = Transform {
                voxel_size: [0.1; 3],
                translation: [1e300; 3],
            };
            vec![AnyGrid::Vec3s(g)]
        }
        // Velocities of 1e30: finite, but Q is about ±1e60, beyond f32.
        "huge_q.vdb" => huge_q(),
        // Split components with `vel.x` twice.
        "dup_component.vdb" => ["vel.x", "vel.x", "vel.y", "vel.z"]
            .iter()
            .enumerate()
            .map(|(k, n)| AnyGrid::Float(scalar(n, [0; 3], [8; 3], k as f32)))
            .collect(),
        // Two vec3 grids; `--fields q,vel2` asks for one of them as a field.
        "vec3_field.vdb" => vec![
            AnyGrid::Vec3s(box_grid("vel", [0; 3], [8; 3], |_| [1.0, 0.0, 0.0])),
            AnyGrid::Vec3s(box_grid("vel2", [0; 3], [8; 3], |_| [0.0, 1.0, 0.0])),
        ],
        // Two grids of one voxel size over 8 common cells along x, different values there.
        "overlap.vdb" => vec![
            AnyGrid::Vec3s(box_grid("a", [0; 3], [16; 3], |_| [1.0, 0.0, 0.0])),
            AnyGrid::Vec3s(box_grid("b", [8, 0, 0], [24, 16, 16], |_| [2.0, 0.0, 0.0])),
        ],
        // One field split into two overlapping grids: the same values where they meet.
        "overlap_equal.vdb" => {
            let f = |i: [i32; 3]| [i[1] as f32 * 0.5, -(i[0] as f32) * 0.5, 0.25];
            vec![
                AnyGrid::Vec3s(box_grid("a", [0; 3], [16; 3], f)),
                AnyGrid::Vec3s(box_grid("b", [8, 0, 0], [24, 16, 16], f)),
            ]
        }
        // Non-finite velocities in two grids (levels): 2 in "fine", 1 in "coarse".
        "nan_two.vdb" => {
            let mut fine = box_grid("fine", [0; 3], [8; 3], |_| [1.0, 0.0, 0.0]);
            fine.leaves[0].values[1] = [f32::NAN, 0.0, 0.0];
            fine.leaves[0].values[2] = [0.0, f32::INFINITY, 0.0];
            let mut coarse = box_grid("coarse", [0; 3], [8; 3], |_| [1.0, 0.0, 0.0]);
            coarse.transform.voxel_size = [2.0; 3];
            coarse.leaves[0].values[511] = [0.0, 0.0, f32::NAN];
            vec![AnyGrid::Vec3s(fine), AnyGrid::Vec3s(coarse)]
        }
        // A density grid nowhere near the velocity.
        "density_elsewhere.vdb" => vec![
            AnyGrid::Vec3s(box_grid("vel", [0; 3], [16; 3], |_| [1.0, 0.0, 0.0])),
            AnyGrid::Float(scalar("density", [96; 3], [104; 3], 1.0)),
        ],
        // A density grid over half of the velocity.
        "density_half.vdb" => vec![
            AnyGrid::Vec3s(box_grid("vel", [0; 3], [16; 3], |_| [1.0, 0.0, 0.0])),
            AnyGrid::Float(scalar("density", [0; 3], [8, 16, 16], 1.0)),
        ],
        other => panic!("no hostile input named {other}"),
    };
    write_vdb(&dir.join(name), &grids, Compression::Zip).expect("write hostile input");
}

/// Velocities of 1e30, rotating for x < 4 (Q about +1e60) and straining beyond (Q about
/// -1e60): every Q overflows f32, of both signs.
fn huge_q() -> Vec<AnyGrid> {
    vec![AnyGrid::Vec3s(box_grid("vel", [0; 3], [8; 3], |i| {
        let s = if i[0] < 4 { -1.0 } else { 1.0 };
        [1e30 * i[1] as f32, s * 1e30 * i[0] as f32, 0.0]
    }))]
}

/// The `.qbk` inputs [`write_qbk`] knows.
pub const QBK_NAMES: &[&str] = &["far.qbk", "huge_q.qbk"];

/// Writes the `.qbk` input `name` (one of [`QBK_NAMES`]) into `dir`, baked in process:
/// - `far.qbk`: a small bake moved to 1e300 afterwards (the baker refuses to make it; a
///   file can still be made by hand, and it is valid as a file);
/// - `huge_q.qbk`: [`huge_q`] baked with the field `q` alone, stored as ±f32::MAX.
pub fn write_qbk(dir: &Path, name: &str) {
    use preprocess::bake::{bake, BakeOptions};
    use preprocess::fields::FieldKind;
    let file = match name {
        "far.qbk" => {
            let mut g = box_grid("vel", [0; 3], [8; 3], |i| {
                [i[1] as f32, -(i[0] as f32), 0.0]
            });
            g.transform.voxel_size = [0.1; 3];
            let (mut file, _) =
                bake(vec![AnyGrid::Vec3s(g)], &BakeOptions::default()).expect("bake");
            let far = 1e300;
            for b in &mut file.bricks {
                b.origin = b.origin.map(|x| x + far);
            }
            file.bounds.min = file.bounds.min.map(|x| x + far);
            file.bounds.max = file.bounds.max.map(|x| x + far);
            for n in &mut file.kd_nodes {
                n.split += far;
            }
            file
        }
        "huge_q.qbk" => {
            let opts = BakeOptions {
                fields: Some(vec![FieldKind::Q]),
                ..BakeOptions::default()
            };
            bake(huge_q(), &opts).expect("bake").0
        }
        other => panic!("no hostile .qbk named {other}"),
    };
    let bytes = format::writer::to_bytes(&file).expect("serialise");
    std::fs::write(dir.join(name), bytes).expect("write hostile .qbk");
}

fn unit() -> Transform {
    Transform {
        voxel_size: [1.0; 3],
        translation: [0.0; 3],
    }
}

/// A grid of full leaves over `lo..hi` (multiples of 8), value `f(ijk)` per voxel.
fn box_grid(
    name: &str,
    lo: [i32; 3],
    hi: [i32; 3],
    f: impl Fn([i32; 3]) -> [f32; 3],
) -> Grid<[f32; 3]> {
    let mut leaves = Vec::new();
    for x in (lo[0]..hi[0]).step_by(8) {
        for y in (lo[1]..hi[1]).step_by(8) {
            for z in (lo[2]..hi[2]).step_by(8) {
                let values = Box::new(std::array::from_fn::<_, LEAF_VOXELS, _>(|n| {
                    f([
                        x + (n >> 6) as i32,
                        y + ((n >> 3) & 7) as i32,
                        z + (n & 7) as i32,
                    ])
                }));
                leaves.push(Leaf {
                    origin: [x, y, z],
                    active: [u64::MAX; 8],
                    values,
                });
            }
        }
    }
    Grid {
        name: name.into(),
        transform: unit(),
        background: [0.0; 3],
        leaves,
        tiles: vec![],
    }
}

/// A float grid of full leaves over `lo..hi` (multiples of 8) holding `value`.
fn scalar(name: &str, lo: [i32; 3], hi: [i32; 3], value: f32) -> Grid<f32> {
    let mut leaves = Vec::new();
    for x in (lo[0]..hi[0]).step_by(8) {
        for y in (lo[1]..hi[1]).step_by(8) {
            for z in (lo[2]..hi[2]).step_by(8) {
                leaves.push(Leaf {
                    origin: [x, y, z],
                    active: [u64::MAX; 8],
                    values: Box::new([value; LEAF_VOXELS]),
                });
            }
        }
    }
    Grid {
        name: name.into(),
        transform: unit(),
        background: 0.0,
        leaves,
        tiles: vec![],
    }
}

/// A cube of `n`³ voxels (`n` a multiple of 128) made of 128³ tiles holding `value`.
fn tiles(name: &str, n: i32, value: [f32; 3]) -> Grid<[f32; 3]> {
    let mut tiles = Vec::new();
    for x in (0..n).step_by(128) {
        for y in (0..n).step_by(128) {
            for z in (0..n).step_by(128) {
                tiles.push(Tile {
                    origin: [x, y, z],
                    size: 128,
                    value,
                });
            }
        }
    }
    Grid {
        name: name.into(),
        transform: unit(),
        background: [0.0; 3],
        leaves: vec![],
        tiles,
    }
}

/// Each input is small (the point of the tile: its size says nothing about its cells).
#[test]
fn every_hostile_input_is_a_small_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    for name in NAMES {
        write(dir.path(), name);
        let len = std::fs::metadata(dir.path().join(name))
            .expect("written")
            .len();
        assert!(len < 64 << 10, "{name}: {len} bytes");
    }
    // The hand-made far file is valid as a file: only the viewer's reach refuses it.
    write_qbk(dir.path(), "far.qbk");
    format::BrickFileView::open(&dir.path().join("far.qbk")).expect("valid as a file");
}
