//! Damaged files: every truncation and random byte flips give an error or a valid view,
//! never a panic. Uses `from_bytes` only, so it also runs under miri.

mod common;

use std::path::Path;

use proptest::prelude::*;
use qbricks_format::header::{checksum, Header, HEADER_LEN};
use qbricks_format::validate::ValidationError;
use qbricks_format::{query, writer, BrickFileView, FormatErrorKind, OpenOptions, Structure};

const NO_CHECKSUM: OpenOptions = OpenOptions {
    verify_checksum: false,
    structure: Structure::AtOpen,
};

fn small_file() -> Vec<u8> {
    // Seed chosen for a file with bricks, regions and a KD tree of several nodes.
    let file = (0..200)
        .map(common::random_file)
        .find(|f| f.bricks.len() >= 2 && f.kd_nodes.len() >= 3 && f.regions.len() >= 2)
        .expect("some seed gives a non-trivial file");
    writer::to_bytes(&file).expect("to_bytes")
}

/// Rewrites the header so that length and checksum match `bytes` again: what a buggy
/// writer could produce; only rkyv validation and the schema checks stand in the way.
fn reseal(bytes: &mut [u8]) {
    if bytes.len() < HEADER_LEN {
        return;
    }
    let payload_len = (bytes.len() - HEADER_LEN) as u64;
    let sum = checksum(&bytes[HEADER_LEN..]);
    bytes[16..24].copy_from_slice(&payload_len.to_le_bytes());
    bytes[24..32].copy_from_slice(&sum.to_le_bytes());
}

/// Everything a program might do with an open view; must not panic on a view that
/// passed validation, whatever its numbers are.
fn exercise(view: &BrickFileView) {
    let file = view.file();
    let _ = view.to_brick_file();
    qbricks_format::validate::check(file).expect("a view is valid");
    let b = query::bounds(file);
    let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * (b.min[a] + b.max[a]));
    let _ = query::region_at(file, centre);
    let segs = query::ray_regions(file, b.min, [1.0, 0.7, 0.3], 0.0, f64::INFINITY);
    for s in segs {
        for &id in query::region_bricks(file, s.region) {
            let _ = query::brick_values(file, id.to_native(), 0).expect("validated brick");
        }
    }
}

#[test]
fn every_truncation_is_an_error() {
    let bytes = small_file();
    for len in 0..bytes.len() {
        let cut = &bytes[..len];
        let err = BrickFileView::from_bytes_with(Path::new("t.qbk"), cut, &NO_CHECKSUM)
            .expect_err("truncated file must not open");
        let ok_kind = matches!(
            err.kind,
            FormatErrorKind::TooShort { .. } | FormatErrorKind::LengthMismatch { .. }
        );
        assert!(ok_kind, "len {len}: {err}");
    }
}

#[test]
fn every_resealed_truncation_is_an_error_or_valid() {
    // With the header patched to the short length, validation is what must catch it.
    let bytes = small_file();
    let mut opened = 0;
    let step = if cfg!(miri) { 37 } else { 1 };
    for len in (HEADER_LEN..bytes.len()).step_by(step) {
        let mut cut = bytes[..len].to_vec();
        reseal(&mut cut);
        if let Ok(view) = BrickFileView::from_bytes(Path::new("t.qbk"), &cut) {
            exercise(&view);
            opened += 1;
        }
    }
    // The root is at the end of an rkyv archive: cutting it off can never validate
    // (a prefix might in principle, so this is a count, not a rule).
    assert!(opened < 4, "{opened} truncations opened");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]

    #[test]
    fn byte_flips_give_error_or_valid_view(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), 1u8..=255), 1..4),
    ) {
        let mut bytes = small_file();
        let n = bytes.len();
        for (at, x) in &flips {
            bytes[at.index(n)] ^= x;
        }
        // With the checksum the damage is always caught.
        let checked = BrickFileView::from_bytes(Path::new("f.qbk"), &bytes);
        prop_assert!(checked.is_err());
        // Without it (and with a resealed header) it is caught or harmless.
        if let Ok(view) = BrickFileView::from_bytes_with(Path::new("f.qbk"), &bytes, &NO_CHECKSUM) {
            exercise(&view);
        }
        reseal(&mut bytes);
        if let Ok(view) = BrickFileView::from_bytes(Path::new("f.qbk"), &bytes) {
            exercise(&view);
        }
    }
}

#[test]
fn intact_file_opens_and_is_exercisable() {
    let bytes = small_file();
    let view = BrickFileView::from_bytes(Path::new("ok.qbk"), &bytes).expect("open");
    exercise(&view);
    let header = Header::parse(&bytes).expect("header");
    assert_eq!(header.payload_len as usize + HEADER_LEN, bytes.len());
}

#[test]
fn appended_bytes_are_an_error() {
    let mut bytes = small_file();
    bytes.extend_from_slice(&[0; 16]);
    let err = BrickFileView::from_bytes(Path::new("long.qbk"), &bytes).expect_err("too long");
    assert!(
        matches!(err.kind, FormatErrorKind::LengthMismatch { .. }),
        "{err}"
    );
}

/// Regression (found by the `qbk_open` fuzz target): a brick's cell count is the product
/// of three u32 dims, up to 2^96. Validation computed it in u64 unchecked, so in release
/// builds 2^22 x 2^21 x 2^21 = 2^64 wrapped to 0 cells, the brick passed the range check
/// against the value arrays, and the viewer indexed far past them. Now such a brick is an
/// error naming it, with fields or without (a file without fields has no values to bound
/// its bricks, but the count must still fit).
#[test]
fn brick_cell_count_overflowing_u64_is_an_error() {
    let base = (0..200)
        .map(common::random_file)
        .find(|f| !f.bricks.is_empty())
        .expect("some seed gives bricks");
    for (dims, no_fields) in [
        ([1 << 22, 1 << 21, 1 << 21], false),
        ([u32::MAX; 3], false),
        ([1 << 22, 1 << 21, 1 << 21], true),
    ] {
        let mut file = base.clone();
        let last = file.bricks.len() - 1;
        file.bricks[last].dims = dims;
        if no_fields {
            file.fields.clear();
            file.region_ranges.clear();
        }
        let bytes = writer::to_bytes(&file).expect("to_bytes");
        let err = BrickFileView::from_bytes(Path::new("huge_brick.qbk"), &bytes)
            .expect_err("a brick with more than 2^64 cells must not open");
        let msg = err.to_string();
        assert!(
            matches!(
                err.kind,
                FormatErrorKind::Invalid(ValidationError::BrickTooManyCells { brick, .. })
                    if brick == last
            ) && msg.contains("huge_brick.qbk")
                && msg.contains(&format!("bricks[{last}].dims")),
            "{dims:?} (no fields: {no_fields}): {msg}"
        );
    }
}

/// Regression (a timeout found by the `qbk_open` fuzz target): a level's cell width of
/// 1.1e-12 under bricks of width 1. The viewer steps through a region in units of its
/// finest level's width, so every ray took a million samples per region. Now a brick
/// whose width is not its level's is an error naming it (and format 3 derives a region's
/// finest level from its bricks instead of storing it).
#[test]
fn level_widths_must_match_the_bricks() {
    let base = (0..500)
        .map(common::random_file)
        .find(|f| f.levels.len() >= 2 && f.regions.iter().any(|r| r.bricks_len > 0))
        .expect("some seed gives two levels and a region with bricks");
    let open = |file: &qbricks_format::BrickFile| {
        let bytes = writer::to_bytes(file).expect("to_bytes");
        BrickFileView::from_bytes(Path::new("levels.qbk"), &bytes)
    };
    open(&base).expect("the base file opens");

    let r = base
        .regions
        .iter()
        .position(|r| r.bricks_len > 0)
        .expect("a region with bricks");
    let b = base.region_bricks[base.regions[r].bricks_start as usize] as usize;
    let level = base.bricks[b].level as usize;

    let mut tiny_level = base.clone();
    tiny_level.levels[level].cell_width = 1.1368683772161603e-12;
    let err = open(&tiny_level).expect_err("level width");
    let msg = err.to_string();
    assert!(
        matches!(
            err.kind,
            FormatErrorKind::Invalid(ValidationError::BrickWidthNotLevels { .. })
        ) && msg.contains("levels.qbk")
            && msg.contains(".cell_width")
            && msg.contains("differs"),
        "{msg}"
    );
}

/// What a view opened with [`Structure::OnUse`] checks, part by part: the top at open,
/// then every brick, every region with its list and the KD-tree as a reader would when it
/// first reads them. Every error found, in that order.
fn part_errors(file: &qbricks_format::ArchivedBrickFile) -> Vec<ValidationError> {
    use qbricks_format::validate;
    let mut out = Vec::new();
    if let Err(e) = validate::check_top(file) {
        return vec![e];
    }
    for b in 0..file.bricks.len() {
        out.extend(validate::check_brick(file, b).err());
    }
    for r in 0..file.regions.len() {
        out.extend(validate::check_region(file, r).err());
    }
    out.extend(validate::check_kd(file).err());
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 512 }))]

    /// One number of a file changed as a faulty writer could: a brick's level, cells,
    /// first value, width or origin; a region's list or one of its entries; a KD node's
    /// child, split or axis; the root. Opened to be checked where it is read, the file
    /// either fails at open as an open that checks everything does, or opens, and then
    /// the parts a reader checks fail exactly when that whole check fails, one of them
    /// with its very error: nothing the whole check refuses gets past the parts.
    #[test]
    fn parts_checked_on_use_refuse_what_the_whole_check_refuses(
        seed in 0u64..64,
        what in 0usize..12,
        pick in any::<prop::sample::Index>(),
        big in any::<u32>(),
    ) {
        let mut file = common::random_file(seed);
        let nb = file.bricks.len().max(1);
        let nr = file.regions.len().max(1);
        let nn = file.kd_nodes.len().max(1);
        let ne = file.region_bricks.len().max(1);
        match what {
            0 => if let Some(b) = file.bricks.get_mut(pick.index(nb)) { b.level = big % 4 },
            1 => if let Some(b) = file.bricks.get_mut(pick.index(nb)) { b.dims[big as usize % 3] = big % 5 },
            2 => if let Some(b) = file.bricks.get_mut(pick.index(nb)) { b.first_value = u64::from(big) },
            3 => if let Some(b) = file.bricks.get_mut(pick.index(nb)) { b.cell_width *= 1.0 + f64::from(big % 3) },
            4 => if let Some(b) = file.bricks.get_mut(pick.index(nb)) { b.origin[0] = f64::NAN },
            5 => if let Some(r) = file.regions.get_mut(pick.index(nr)) { r.bricks_start = big % (ne as u32 + 3) },
            6 => if let Some(r) = file.regions.get_mut(pick.index(nr)) { r.bricks_len = big % 9 },
            7 => if let Some(e) = file.region_bricks.get_mut(pick.index(ne)) { *e = big % (nb as u32 + 3) },
            8 => if let Some(n) = file.kd_nodes.get_mut(pick.index(nn)) { n.left = big % (nn as u32 + 2) },
            9 => if let Some(n) = file.kd_nodes.get_mut(pick.index(nn)) { n.split = f64::from(big) - 2e9 },
            10 => if let Some(a) = file.kd_axes.get_mut(pick.index(nn)) { *a = (big % 4) as u8 },
            _ => file.kd_root = big % (nn as u32 + 2),
        }
        let bytes = writer::to_bytes(&file).expect("to_bytes");
        let whole = BrickFileView::from_bytes(Path::new("w.qbk"), &bytes);
        let on_use = BrickFileView::from_bytes_with(
            Path::new("w.qbk"),
            &bytes,
            &OpenOptions { verify_checksum: true, structure: Structure::OnUse },
        );
        match (&whole, &on_use) {
            (_, Err(e)) => {
                // Refused at open: by the top checks, which the whole check runs too.
                prop_assert_eq!(whole.as_ref().err().map(ToString::to_string), Some(e.to_string()));
            }
            (_, Ok(view)) => {
                prop_assert_eq!(view.structure(), Structure::OnUse);
                let parts = part_errors(view.file());
                match whole {
                    Ok(_) => prop_assert!(parts.is_empty(), "{parts:?}"),
                    Err(e) => {
                        let FormatErrorKind::Invalid(want) = &e.kind else {
                            return Err(TestCaseError::fail(format!("not a schema error: {e}")));
                        };
                        prop_assert!(
                            parts.iter().any(|p| p == want || matches!(
                                (p, want),
                                (ValidationError::BrickIdOutOfRange { entry: a, id: x, .. },
                                 ValidationError::BrickIdOutOfRange { entry: b, id: y, .. })
                                    if a == b && x == y
                            )),
                            "{want} not among {parts:?}"
                        );
                    }
                }
                // Whatever was found, the query functions stay safe on the view.
                let b = query::bounds(view.file());
                let _ = query::region_at(view.file(), b.min);
            }
        }
    }
}

/// A view opened without the checksum verifies it later, mapped or in memory, with the
/// error an open with the checksum gives: what a command that hashes the file beside its
/// frames relies on.
#[test]
fn a_checksum_verified_after_open_is_the_opens() {
    let good = small_file();
    // One value's lowest mantissa bit: the archive stays valid, the checksum fails.
    let view = BrickFileView::from_bytes(Path::new("good.qbk"), &good).expect("valid");
    let values = &view.file().fields[0].values;
    let probe = values[values.len() / 2].to_native().to_le_bytes();
    let at = good
        .windows(4)
        .position(|w| w == probe)
        .expect("the value's bytes are in the file");
    let mut flipped = good.clone();
    flipped[at] ^= 1;
    let dir = tempfile::tempdir().expect("dir");
    for (bytes, ok) in [(&good, true), (&flipped, false)] {
        let path = dir.path().join(if ok { "good.qbk" } else { "flipped.qbk" });
        std::fs::write(&path, bytes).expect("write");
        let at_open = BrickFileView::open(&path)
            .map(|_| ())
            .map_err(|e| e.to_string());
        let mapped = BrickFileView::open_with(&path, &NO_CHECKSUM).expect("opens");
        assert!(mapped.is_mapped());
        let owned = BrickFileView::from_bytes_with(&path, bytes, &NO_CHECKSUM).expect("opens");
        for view in [&mapped, &owned] {
            assert!(!view.checksum_verified());
            let later = view.verify_checksum().map_err(|e| e.to_string());
            assert_eq!(later, at_open, "{}", path.display());
            assert_eq!(later.is_ok(), ok);
        }
    }
}
