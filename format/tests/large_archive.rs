//! Format 4 reaches past 2 GiB: an archive whose field values alone take 2.4 GB (beyond
//! format 3's 32-bit relative pointers, where rkyv panicked while writing) is written,
//! opened, validated and read back at its last value. The 1-billion-cell bakes of the
//! larger-than-memory work write such files; this is their smallest witness (about 10 s
//! and 2.4 GB of memory and disk in release mode).

mod common;

use qbricks_format::writer;
use qbricks_format::BrickFileView;

/// Cells of the one large brick: 1000 × 1000 × 600, 2.4 GB of `f32`.
const DIMS: [u32; 3] = [1000, 1000, 600];

#[test]
fn an_archive_past_2_gib_is_written_opened_and_read() {
    // A valid small file (one field), its first brick made large.
    let mut file = (0..)
        .map(common::random_file)
        .find(|f| !f.bricks.is_empty() && f.fields.len() == 1)
        .expect("a small file with a brick and one field");
    let cells: u64 = DIMS.iter().map(|&d| u64::from(d)).product();
    file.bricks.truncate(1);
    file.bricks[0].dims = DIMS;
    file.bricks[0].first_value = 0;
    let level = file.bricks[0].level as usize;
    for (l, lv) in file.levels.iter_mut().enumerate() {
        (lv.cells, lv.bricks) = if l == level { (cells, 1) } else { (0, 0) };
    }
    for id in &mut file.region_bricks {
        *id = 0;
    }
    let mut values = vec![0.25f32; cells as usize];
    if let Some(last) = values.last_mut() {
        *last = 0.75;
    }
    file.fields[0].values = values;
    assert!(cells * 4 > 1 << 31, "the values pass 2 GiB");

    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("large.qbk");
    let n = writer::write(&path, &file).expect("write past 2 GiB");
    drop(file);
    assert!(n > 1 << 31, "{n} bytes");
    let view = BrickFileView::open(&path).expect("open and validate");
    let values = &view.file().fields[0].values;
    assert_eq!(values.len() as u64, cells);
    assert_eq!(values[values.len() - 1].to_native(), 0.75);
    assert_eq!(values[0].to_native(), 0.25);
}
