//! A VDB file is mapped, not read whole, and the pages of the leaves already decoded leave
//! the process as decoding goes on: a large file is never held beside its decoded leaves.

use qbricks_preprocess::grid::{AnyGrid, Grid, Leaf, Transform};
use qbricks_preprocess::vdb::write::{write_vdb, Compression};
use qbricks_preprocess::vdb::VdbFile;

/// This process's resident pages of mapped files, in bytes (`RssFile` of /proc/self/status).
fn resident_file_bytes() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("status");
    let kib: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("RssFile:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("RssFile");
    kib * 1024
}

#[test]
fn decoded_leaves_let_their_file_pages_go() {
    // 16384 raw vec3s leaves: 100 MB in the file, 100 MB decoded.
    let leaves: Vec<Leaf<[f32; 3]>> = (0..16384i32)
        .map(|n| Leaf {
            origin: [8 * (n % 32), 8 * ((n / 32) % 32), 8 * (n / 1024)],
            active: [u64::MAX; 8],
            values: Box::new(std::array::from_fn(|i| [n as f32, i as f32, 0.5])),
        })
        .collect();
    let grid = Grid {
        name: "vel".into(),
        transform: Transform {
            voxel_size: [1.0; 3],
            translation: [0.0; 3],
        },
        background: [0.0; 3],
        leaves,
        tiles: vec![],
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("raw.vdb");
    write_vdb(&path, &[AnyGrid::Vec3s(grid.clone())], Compression::None).unwrap();
    let size = std::fs::metadata(&path).unwrap().len();
    assert!(size > 95 << 20, "{size}");

    let before = resident_file_bytes();
    let file = VdbFile::open(&path).unwrap();
    let AnyGrid::Vec3s(read) = file.read_grid(0).unwrap() else {
        panic!("a vec3s grid")
    };
    let after = resident_file_bytes();
    let sorted = |mut l: Vec<Leaf<[f32; 3]>>| {
        l.sort_by_key(|l| l.origin);
        l
    };
    let want = sorted(grid.leaves);
    assert!(sorted(read.leaves) == want, "the leaves as written");
    // Without the release, every page of the file stays resident (100 MB more); with it,
    // about one batch of leaves (24 MB) at most.
    let grew = after.saturating_sub(before);
    assert!(
        grew < 40 << 20,
        "{} MB of the file still resident",
        grew >> 20
    );
    // Read again after its pages went: the same values.
    let AnyGrid::Vec3s(again) = file.read_grid(0).unwrap() else {
        panic!("a vec3s grid")
    };
    assert!(sorted(again.leaves) == want);
}
