//! Archives that pass rkyv's validation but break a schema invariant are refused with a
//! message naming the element.

mod common;

use std::path::Path;

use qbricks_format::{writer, BrickFile, BrickFileView, FormatErrorKind, KdNode};

/// A valid base with at least two bricks, two regions and an inner KD node.
fn base() -> BrickFile {
    (0..500)
        .map(common::random_file)
        .find(|f| {
            f.bricks.len() >= 2
                && f.regions.len() >= 2
                && f.regions.iter().all(|r| r.bricks_len > 0)
                && matches!(f.kd_nodes[0], KdNode::Inner { .. })
        })
        .expect("some seed fits")
}

fn refused(f: &BrickFile, needle: &str) {
    let bytes = writer::to_bytes(f).expect("serialisable");
    let err = BrickFileView::from_bytes(Path::new("bad.qbk"), &bytes).expect_err(needle);
    assert!(matches!(err.kind, FormatErrorKind::Invalid(_)), "{err}");
    let msg = err.to_string();
    assert!(msg.contains(needle), "expected {needle:?} in {msg}");
    assert!(msg.starts_with("bad.qbk: ") && !msg.contains('\n'), "{msg}");
}

#[test]
fn base_is_valid() {
    let bytes = writer::to_bytes(&base()).expect("bytes");
    BrickFileView::from_bytes(Path::new("ok.qbk"), &bytes).expect("valid");
}

#[test]
fn each_broken_invariant_is_named() {
    let mut f = base();
    f.bricks[1].first_value = f.fields[0].values.len() as u64;
    refused(&f, "bricks[1]: values");

    let mut f = base();
    f.bricks[0].level = f.levels.len() as u32;
    refused(&f, "bricks[0].level");

    let mut f = base();
    f.bricks[0].dims[2] = 0;
    refused(&f, "bricks[0].dims");

    let mut f = base();
    f.fields[0].values.pop();
    refused(&f, "values");

    let mut f = base();
    let start = f.regions[1].bricks_start as usize;
    f.region_bricks[start] = f.bricks.len() as u32 + 7;
    refused(&f, "regions[1].bricks[0]: brick");

    let mut f = base();
    f.regions[0].bricks_len = f.region_bricks.len() as u32 + 1;
    refused(&f, "regions[0]: bricks");

    let mut f = base();
    f.regions[1].bounds.min[2] = f64::NAN;
    refused(&f, "regions[1].bounds");

    let mut f = base();
    f.region_ranges.pop();
    refused(&f, "region_ranges");

    let mut f = base();
    f.levels[0].cell_width = 0.0;
    refused(&f, "levels[0].cell_width");

    // KD-tree: child out of range, a cycle back to the root, a bad axis, a lost region.
    let n = f.kd_nodes.len() as u32;
    let set_root = |f: &mut BrickFile, left: Option<u32>, axis: Option<u8>| {
        if let KdNode::Inner {
            left: l, axis: a, ..
        } = &mut f.kd_nodes[0]
        {
            if let Some(v) = left {
                *l = v;
            }
            if let Some(v) = axis {
                *a = v;
            }
        }
    };
    let mut f = base();
    set_root(&mut f, Some(n + 3), None);
    refused(&f, "kd_nodes[0]: child");
    let mut f = base();
    set_root(&mut f, Some(0), None);
    refused(&f, "reached twice");
    let mut f = base();
    set_root(&mut f, None, Some(3));
    refused(&f, "kd_nodes[0].axis");
    let mut f = base();
    for node in &mut f.kd_nodes {
        if let KdNode::Leaf { region: Some(0) } = node {
            *node = KdNode::Leaf { region: None };
        }
    }
    f.derive_kd_tables();
    refused(&f, "regions[0]: in no KD-tree leaf");

    // The skipping tables: a node whose range misses its child's, a full flag on a node
    // with an empty leaf below, an empty leaf flagged full, missing entries.
    let mut f = base();
    let nf = f.fields.len();
    f.kd_ranges[0].max = f.kd_ranges[0].min - 1.0;
    assert!(nf > 0);
    refused(&f, "kd_ranges of node 0");
    let mut f = base();
    if let Some(empty) = f
        .kd_nodes
        .iter()
        .position(|n| matches!(n, KdNode::Leaf { region: None }))
    {
        f.kd_full[empty] = true;
        refused(
            &f,
            &format!("kd_full of node {empty}: set on an empty leaf"),
        );
    }
    let mut f = base();
    if let Some(leaf) = f
        .kd_nodes
        .iter()
        .position(|n| matches!(n, KdNode::Leaf { region: Some(_) }))
    {
        f.kd_ranges[leaf * nf].min = f32::NAN;
        refused(&f, "kd_ranges of");
    }
    let mut f = base();
    f.kd_full.pop();
    refused(&f, "kd_full: expected");
    let mut f = base();
    f.kd_ranges.pop();
    refused(&f, "kd_ranges: expected");
    let mut f = base();
    f.kd_nodes.clear();
    refused(&f, "kd_nodes: empty");
}
