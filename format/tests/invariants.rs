//! Archives that pass rkyv's validation but break a schema invariant are refused with a
//! typed error of the right kind, whose message names the element.

mod common;

use std::path::Path;

use qbricks_format::validate::ValidationError as V;
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

/// Opens `f`, expects a schema error whose one-line message names the file and contains
/// `needle`, and returns the error for the caller to match by kind.
fn refused(f: &BrickFile, needle: &str) -> V {
    let bytes = writer::to_bytes(f).expect("serialisable");
    let err = BrickFileView::from_bytes(Path::new("bad.qbk"), &bytes).expect_err(needle);
    let msg = err.to_string();
    assert!(msg.contains(needle), "expected {needle:?} in {msg}");
    assert!(msg.starts_with("bad.qbk: ") && !msg.contains('\n'), "{msg}");
    match err.kind {
        FormatErrorKind::Invalid(e) => e,
        other => panic!("expected a schema error, found {other:?}"),
    }
}

/// Asserts that `refused(f, needle)` is of the given kind.
macro_rules! refused {
    ($f:expr, $needle:expr, $pat:pat) => {{
        let e = refused(&$f, $needle);
        assert!(matches!(e, $pat), "{e:?}");
    }};
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
    refused!(f, "bricks[1]: values", V::BrickOutOfRange { brick: 1, .. });

    let mut f = base();
    f.bricks[0].level = f.levels.len() as u32;
    refused!(
        f,
        "bricks[0].level",
        V::BrickLevelOutOfRange { brick: 0, .. }
    );

    let mut f = base();
    f.bricks[0].dims[2] = 0;
    refused!(f, "bricks[0].dims", V::BrickEmptyDims { brick: 0, .. });

    let mut f = base();
    f.fields[0].values.pop();
    // With one field, the last brick's values run past the shortened array; with more,
    // the fields differ in length.
    refused!(
        f,
        "values",
        V::FieldLength { .. } | V::BrickOutOfRange { .. }
    );

    let mut f = base();
    let start = f.regions[1].bricks_start as usize;
    f.region_bricks[start] = f.bricks.len() as u32 + 7;
    refused!(
        f,
        "regions[1].bricks[0]: brick",
        V::BrickIdOutOfRange {
            in_region: Some((1, 0)),
            ..
        }
    );

    let mut f = base();
    f.regions[0].bricks_len = f.region_bricks.len() as u32 + 1;
    refused!(
        f,
        "regions[0]: bricks",
        V::RegionBricksOutOfRange { region: 0, .. }
    );

    let mut f = base();
    f.regions[1].bounds.min[2] = f64::NAN;
    refused!(
        f,
        "regions[1].bounds",
        V::BadBox {
            region: Some(1),
            axis: 2,
            ..
        }
    );

    let mut f = base();
    f.region_ranges.pop();
    refused!(f, "region_ranges", V::RegionRangesLength { .. });

    let mut f = base();
    f.levels[0].cell_width = 0.0;
    refused!(
        f,
        "levels[0].cell_width",
        V::LevelCellWidth { level: 0, .. }
    );

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
    refused!(
        f,
        "kd_nodes[0]: child",
        V::KdChildOutOfRange { node: 0, .. }
    );
    let mut f = base();
    set_root(&mut f, Some(0), None);
    refused!(f, "reached twice", V::KdNotATree { child: 0, .. });
    // Both children the same node: reached twice.
    let mut f = base();
    if let KdNode::Inner { right, .. } = f.kd_nodes[0] {
        set_root(&mut f, Some(right), None);
    }
    refused!(f, "reached twice", V::KdNotATree { node: 0, .. });
    // The same tree with nodes 1.. stored in reverse (the root stays at 0): every node
    // below the root now comes after its children. It is still a tree, but refused:
    // validation relies on the parent-first order.
    let mut f = base();
    let n = f.kd_nodes.len();
    assert!(
        f.kd_nodes[1..]
            .iter()
            .any(|k| matches!(k, KdNode::Inner { .. })),
        "the base has an inner node below the root"
    );
    let moved = |i: u32| if i == 0 { 0 } else { n as u32 - i };
    let mut reordered = f.kd_nodes.clone();
    for (i, node) in f.kd_nodes.iter().enumerate() {
        let mut node = *node;
        if let KdNode::Inner { left, right, .. } = &mut node {
            *left = moved(*left);
            *right = moved(*right);
        }
        reordered[moved(i as u32) as usize] = node;
    }
    f.kd_nodes = reordered;
    f.derive_kd_tables();
    refused!(f, "stored before its parent", V::KdNotATree { .. });
    let mut f = base();
    set_root(&mut f, None, Some(3));
    refused!(f, "kd_nodes[0].axis", V::KdAxis { node: 0, axis: 3 });
    let mut f = base();
    for node in &mut f.kd_nodes {
        if let KdNode::Leaf { region: Some(0) } = node {
            *node = KdNode::Leaf { region: None };
        }
    }
    f.derive_kd_tables();
    refused!(
        f,
        "regions[0]: in no KD-tree leaf",
        V::RegionNotInTree { region: 0 }
    );

    // The skipping tables: a node whose range misses its child's, a full flag on a node
    // with an empty leaf below, an empty leaf flagged full, missing entries.
    let mut f = base();
    let nf = f.fields.len();
    f.kd_ranges[0].max = f.kd_ranges[0].min - 1.0;
    assert!(nf > 0);
    refused!(f, "kd_ranges of node 0", V::KdRangeNotHeld { node: 0, .. });
    let mut f = base();
    if let Some(empty) = f
        .kd_nodes
        .iter()
        .position(|n| matches!(n, KdNode::Leaf { region: None }))
    {
        f.kd_full[empty] = true;
        let e = refused(
            &f,
            &format!("kd_full of node {empty}: set on an empty leaf"),
        );
        assert!(
            matches!(e, V::KdFullEmptyLeaf { node } if node as usize == empty),
            "{e:?}"
        );
    }
    let mut f = base();
    if let Some(leaf) = f
        .kd_nodes
        .iter()
        .position(|n| matches!(n, KdNode::Leaf { region: Some(_) }))
    {
        f.kd_ranges[leaf * nf].min = f32::NAN;
        // Caught at the leaf, or first at its parent (whose range holds no NaN).
        refused!(
            f,
            "kd_ranges of",
            V::KdLeafRangeNotHeld { .. } | V::KdRangeNotHeld { .. }
        );
    }
    let mut f = base();
    f.kd_full.pop();
    refused!(f, "kd_full: expected", V::KdFullLength { .. });
    let mut f = base();
    f.kd_ranges.pop();
    refused!(f, "kd_ranges: expected", V::KdRangesLength { .. });
    let mut f = base();
    f.kd_nodes.clear();
    refused!(f, "kd_nodes: empty", V::KdNodesEmpty { .. });
}
