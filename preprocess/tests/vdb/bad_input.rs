//! Bad input gives an error, never a panic or an absurd allocation: truncation, bit flips,
//! garbage, empty files, unsupported grid types and transforms, absurd sizes. The CLI exits
//! with code 2 and prints one line.

use crate::common::{fixtures, qbricks_bake};
use qbricks_preprocess::vdb::{ErrorKind, VdbError, VdbFile};

fn read(name: &str, bytes: Vec<u8>) -> Result<usize, VdbError> {
    let file = VdbFile::from_bytes(name, bytes)?;
    let grids = file.read_all()?;
    Ok(grids.len())
}

fn fixture(name: &str) -> Vec<u8> {
    std::fs::read(fixtures().join(name)).unwrap()
}

/// Deterministic pseudo-random numbers (xorshift).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

fn check_message(e: &VdbError, file: &str) {
    let msg = e.to_string();
    assert!(!msg.contains('\n'), "multi-line message: {msg}");
    assert!(
        msg.starts_with(file),
        "message does not name the file: {msg}"
    );
    assert!(msg.contains(" at byte "), "message has no offset: {msg}");
}

#[test]
fn every_truncation_is_an_error() {
    for name in [
        "float_blosc.vdb",
        "masks_zip.vdb",
        "double_half_zip.vdb",
        "float_stream.vdb",
    ] {
        let bytes = fixture(name);
        assert!(read(name, bytes.clone()).is_ok());
        // Every length near the start and the end, and a stride through the middle.
        let n = bytes.len();
        let lens = (0..600).chain((600..n - 600).step_by(7)).chain(n - 600..n);
        for len in lens {
            let e = read(name, bytes[..len].to_vec())
                .expect_err(&format!("{name} truncated to {len} bytes was accepted"));
            check_message(&e, name);
        }
    }
}

#[test]
fn truncation_inside_a_leaf_buffer_names_grid_and_counts() {
    // Cut the uncompressed file 1000 bytes before the end of its last grid, inside the
    // 2048 value bytes of the last leaf buffer, and move that grid's end offset in its
    // descriptor to the cut: the file then opens, and the leaf reader must name the grid,
    // the item, the values it expected and the bytes it found.
    let name = "float_none.vdb";
    let bytes = fixture(name);
    let file = VdbFile::from_bytes(name, bytes.clone()).unwrap();
    let last = file.grids().len() - 1;
    let g = &file.grids()[last];
    let (grid, end) = (g.name.clone(), g.end_pos);
    assert_eq!(end as usize, bytes.len(), "the last grid ends the file");
    let cut = end - 1000;
    let mut b = bytes[..cut as usize].to_vec();
    let at = find(&bytes, &end.to_le_bytes());
    assert!(
        at < g.grid_pos as usize,
        "end offset found in the descriptor"
    );
    b[at..at + 8].copy_from_slice(&cut.to_le_bytes());

    let file = VdbFile::from_bytes(name, b).expect("the patched descriptor opens");
    let e = file.read_grid(last).expect_err("truncated leaf buffer");
    check_message(&e, name);
    assert_eq!(e.grid.as_deref(), Some(grid.as_str()), "{e}");
    assert_eq!(e.what, "leaf buffer", "{e}");
    match &e.kind {
        ErrorKind::Truncated { expected, left } => {
            assert_eq!(expected, "512 values", "{e}");
            assert!(*left > 0 && *left < 2048, "{e}");
        }
        other => panic!("expected a truncation, found {other:?}: {e}"),
    }
}

#[test]
fn bit_flips_never_panic() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for name in [
        "float_blosc.vdb",
        "masks_zip.vdb",
        "half_mask_only.vdb",
        "double_blosc.vdb",
    ] {
        let bytes = fixture(name);
        for _ in 0..400 {
            let mut b = bytes.clone();
            for _ in 0..1 + rng.next() % 4 {
                let at = (rng.next() % b.len() as u64) as usize;
                b[at] ^= 1 << (rng.next() % 8);
            }
            if let Err(e) = read(name, b) {
                check_message(&e, name);
            }
        }
    }
}

#[test]
fn garbage_and_empty_files_are_errors() {
    let e = read("empty.vdb", Vec::new()).unwrap_err();
    assert!(
        matches!(e.kind, ErrorKind::Truncated { left: 0, .. }),
        "{e}"
    );
    check_message(&e, "empty.vdb");

    let mut rng = Rng(12345);
    for len in [1usize, 7, 8, 100, 5000] {
        let junk: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
        let e = read("junk.vdb", junk).unwrap_err();
        check_message(&e, "junk.vdb");
    }
    // Valid magic and version followed by garbage.
    let good = fixture("float_blosc.vdb");
    for seed in 1..50u64 {
        let mut rng = Rng(seed);
        let mut b = good[..12].to_vec();
        b.extend((0..200 + seed as usize * 37).map(|_| rng.next() as u8));
        let e = read("junk.vdb", b).unwrap_err();
        check_message(&e, "junk.vdb");
    }
}

#[test]
fn wrong_magic_and_versions_are_named() {
    let good = fixture("float_blosc.vdb");
    let mut b = good.clone();
    b[0] = b'X';
    assert!(matches!(
        read("x.vdb", b).unwrap_err().kind,
        ErrorKind::BadMagic(_)
    ));
    for v in [221u32, 226, 0, u32::MAX] {
        let mut b = good.clone();
        b[8..12].copy_from_slice(&v.to_le_bytes());
        let e = read("v.vdb", b).unwrap_err();
        assert_eq!(e.kind, ErrorKind::UnsupportedVersion(v));
        assert!(e.to_string().contains(&v.to_string()));
    }
}

#[test]
fn unsupported_grid_type_and_transform_name_the_grid() {
    let e = VdbFile::open(fixtures().join("unsupported/bool.vdb"))
        .unwrap()
        .read_grid(0)
        .unwrap_err();
    assert!(
        matches!(&e.kind, ErrorKind::UnsupportedGridType(t) if t == "Tree_bool_5_4_3"),
        "{e}"
    );
    assert_eq!(e.grid.as_deref(), Some("mask"));

    let file = VdbFile::open(fixtures().join("unsupported/rotated.vdb")).unwrap();
    let rotated = file
        .grids()
        .iter()
        .position(|g| g.name == "rotated")
        .unwrap();
    let plain = file.grids().iter().position(|g| g.name == "plain").unwrap();
    assert!(file.read_grid(plain).is_ok(), "other grids stay readable");
    let e = file.read_grid(rotated).unwrap_err();
    assert!(
        matches!(&e.kind, ErrorKind::UnsupportedTransform(m) if m == "AffineMap"),
        "{e}"
    );
    assert_eq!(e.grid.as_deref(), Some("rotated"));
    check_message(
        &e,
        &fixtures()
            .join("unsupported/rotated.vdb")
            .display()
            .to_string(),
    );
}

/// Offset of the first occurrence of `needle` in `hay`.
fn find(hay: &[u8], needle: &[u8]) -> usize {
    hay.windows(needle.len())
        .position(|w| w == needle)
        .expect("pattern present")
}

#[test]
fn absurd_sizes_are_refused_before_allocating() {
    let good = fixture("float_none.vdb");
    let file = VdbFile::from_bytes("a.vdb", good.clone()).unwrap();
    let g = &file.grids()[0];

    // Grid count (right after the file metadata): i32 just before the first descriptor,
    // whose name string starts with its length.
    let name = g.unique_name.as_bytes();
    let mut pat = (name.len() as u32).to_le_bytes().to_vec();
    pat.extend(name);
    let desc = find(&good, &pat);
    for count in [i32::MAX, -1, 1 << 20] {
        let mut b = good.clone();
        b[desc - 4..desc].copy_from_slice(&count.to_le_bytes());
        let e = read("a.vdb", b).unwrap_err();
        assert_eq!(e.what, "grid count", "{e}");
    }
    // Name length.
    let mut b = good.clone();
    b[desc..desc + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(
        read("a.vdb", b).unwrap_err().kind,
        ErrorKind::Truncated { .. }
    ));

    // Root tile and child counts: they follow the 4-byte buffer count and the background
    // (1.0f) at the start of the tree, which is right after the transform.
    let mut bg = 1i32.to_le_bytes().to_vec();
    bg.extend(1.0f32.to_le_bytes());
    let tree = g.grid_pos as usize + find(&good[g.grid_pos as usize..], &bg);
    for (at, v) in [(8, u32::MAX), (12, u32::MAX), (12, 1 << 24)] {
        let mut b = good.clone();
        b[tree + at..tree + at + 4].copy_from_slice(&v.to_le_bytes());
        let e = read("a.vdb", b).unwrap_err();
        assert!(
            matches!(e.kind, ErrorKind::Truncated { .. } | ErrorKind::Invalid(_)),
            "{e}"
        );
        assert_eq!(e.grid.as_deref(), Some("temperature"));
    }
}

#[test]
fn absurd_compressed_chunk_sizes_are_refused() {
    // In a zip file, make the first compressed chunk claim 2^62 bytes: the error must come
    // from the bounds check, not from an allocation.
    let good = fixture("masks_zip.vdb");
    let file = VdbFile::from_bytes("z.vdb", good.clone()).unwrap();
    let start = file.grids()[0].grid_pos as usize;
    let mut hits = 0;
    // Chunk headers are i64 sizes followed by a zlib stream (0x78 0x9c or 0x78 0x01/0xda).
    for at in start..good.len() - 10 {
        let size = i64::from_le_bytes(good[at..at + 8].try_into().unwrap());
        if size > 0 && size < 100_000 && good[at + 8] == 0x78 {
            let mut b = good.clone();
            b[at..at + 8].copy_from_slice(&(1i64 << 62).to_le_bytes());
            let e = read("z.vdb", b).unwrap_err();
            check_message(&e, "z.vdb");
            hits += 1;
            if hits == 5 {
                break;
            }
        }
    }
    assert!(hits > 0, "no zip chunk found");
}

fn run_cli(path: &std::path::Path) -> (i32, String) {
    let out = qbricks_bake().arg("inspect").arg(path).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn cli_exits_2_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let good = fixture("multi_zip.vdb");
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("empty.vdb", Vec::new()),
        ("truncated.vdb", good[..good.len() / 2].to_vec()),
        ("garbage.vdb", b"this is not a VDB file at all".to_vec()),
    ];
    for (name, bytes) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let (code, err) = run_cli(&path);
        assert_eq!(code, 2, "{name}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
        assert!(
            err.starts_with("qbricks-bake: ") && err.contains(name),
            "{err}"
        );
    }
    let (code, err) = run_cli(&fixtures().join("unsupported/rotated.vdb"));
    assert_eq!(code, 2);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("grid \"rotated\"") && err.contains("AffineMap"),
        "{err}"
    );
    let (code, err) = run_cli(&dir.path().join("missing.vdb"));
    assert_eq!(code, 2);
    assert!(err.contains("missing.vdb"), "{err}");
}
