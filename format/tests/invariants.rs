//! Archives that pass rkyv's validation but break a schema invariant are refused with a
//! typed error of the right kind, whose message names the element.

mod common;

use std::path::Path;

use qbricks_format::kd::{self, LEAF};
use qbricks_format::validate::ValidationError as V;
use qbricks_format::{writer, BrickFile, BrickFileView, FormatErrorKind};

/// A valid base with at least two bricks, two regions and an inner KD node.
fn base() -> BrickFile {
    (0..500)
        .map(common::random_file)
        .find(|f| {
            f.bricks.len() >= 2
                && f.regions.len() >= 2
                && f.regions.iter().all(|r| r.bricks_len > 0)
                && f.kd_root == 0
                // An inner node below the root with an inner child (a grandchild of
                // the root), so that reordering can put a child before its parent.
                && f.kd_nodes[1..]
                    .iter()
                    .any(|n| [n.left, n.right].iter().any(|&c| c & LEAF == 0))
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
    f.bounds.min[2] = f64::NAN;
    refused!(f, "bounds", V::BadBox { axis: 2, .. });
    let mut f = base();
    f.bounds.max[0] = f64::INFINITY;
    refused!(f, "bounds", V::BadBox { axis: 0, .. });

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

    // KD-tree: child out of range, a cycle back to the root, a bad axis, a lost region,
    // a region in two leaves, a leaf naming no region, a root that is not node 0.
    let n = f.kd_nodes.len() as u32;
    let mut f = base();
    f.kd_nodes[0].left = n + 3;
    refused!(
        f,
        "kd_nodes[0]: child",
        V::KdChildOutOfRange { node: 0, .. }
    );
    let mut f = base();
    f.kd_nodes[0].left = 0;
    refused!(f, "reached twice", V::KdNotATree { child: 0, .. });
    // Both children the same inner node: reached twice.
    let mut f = base();
    let inner_child = [f.kd_nodes[0].left, f.kd_nodes[0].right]
        .into_iter()
        .find(|&c| c & LEAF == 0)
        .expect("the base's root has an inner child");
    f.kd_nodes[0].left = inner_child;
    f.kd_nodes[0].right = inner_child;
    refused!(f, "reached twice", V::KdNotATree { node: 0, .. });
    // The same tree with nodes 1.. stored in reverse (the root stays at 0): every node
    // below the root now comes after its children. It is still a tree, but refused:
    // validation relies on the parent-first order.
    let mut f = base();
    let n = f.kd_nodes.len();
    let moved = |i: u32| {
        if i & LEAF != 0 || i == 0 {
            i
        } else {
            n as u32 - i
        }
    };
    let mut reordered = f.kd_nodes.clone();
    let mut axes = f.kd_axes.clone();
    for (i, node) in f.kd_nodes.iter().enumerate() {
        let mut node = *node;
        node.left = moved(node.left);
        node.right = moved(node.right);
        reordered[moved(i as u32) as usize] = node;
        axes[moved(i as u32) as usize] = f.kd_axes[i];
    }
    f.kd_nodes = reordered;
    f.kd_axes = axes;
    refused!(f, "stored before its parent", V::KdNotATree { .. });
    let mut f = base();
    f.kd_axes[0] = 3;
    refused!(f, "kd_axes[0]", V::KdAxis { node: 0, axis: 3 });
    let mut f = base();
    f.kd_axes.pop();
    refused!(f, "kd_axes: expected", V::KdAxesLength { .. });
    let mut f = base();
    f.kd_nodes[0].split = f64::NAN;
    refused!(f, "kd_nodes[0].split", V::KdSplitNan { node: 0 });
    // A split far outside the bounds (the `qbk_open` fuzz target's timeout: a region's box
    // reached 1e30 past the data, and `exact` stepped through it cell by cell).
    for split in [1e30, -1e30, f64::INFINITY] {
        let mut f = base();
        let last = f.kd_nodes.len() - 1;
        f.kd_nodes[last].split = split;
        let e = refused(&f, "is outside the bounds");
        assert!(
            matches!(e, V::KdSplitOutsideBounds { node, .. } if node as usize == last),
            "{e:?}"
        );
    }
    let mut f = base();
    for node in &mut f.kd_nodes {
        for c in [&mut node.left, &mut node.right] {
            if *c == kd::leaf_ref(Some(0)) {
                *c = kd::EMPTY;
            }
        }
    }
    refused!(
        f,
        "regions[0]: in no KD-tree leaf",
        V::RegionNotInTree { region: 0 }
    );
    let mut f = base();
    let regions = f.regions.len() as u32;
    let leaf = |f: &BrickFile| {
        f.kd_nodes
            .iter()
            .enumerate()
            .find_map(|(i, node)| (node.right & LEAF != 0).then_some(i))
    };
    if let Some(i) = leaf(&f) {
        f.kd_nodes[i].right = kd::leaf_ref(Some(regions));
        refused!(f, "region", V::KdRegionOutOfRange { .. });
    }
    let mut f = base();
    if let Some(i) = leaf(&f) {
        // Name a region some other leaf holds too.
        let other = (0..regions)
            .find(|&r| f.kd_nodes[i].right != kd::leaf_ref(Some(r)))
            .expect("two regions");
        f.kd_nodes[i].right = kd::leaf_ref(Some(other));
        refused!(f, "in a second leaf", V::KdRegionTwice { .. });
    }
    let mut f = base();
    f.kd_root = 1;
    refused!(f, "kd_root", V::KdRootNotFirst { root: 1 });
}
