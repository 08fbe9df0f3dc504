//! The KD-tree queries agree with brute force over all regions on random configurations.

mod common;

use std::path::Path;

use common::Rng;
use proptest::prelude::*;
use qbricks_format::kd;
use qbricks_format::query::{self, RayRegions, RegionSegment};
use qbricks_format::{writer, Aabb, BrickFileView};

/// A random file, opened, with its regions' boxes as generated.
fn open(seed: u64) -> (BrickFileView, Vec<Aabb>) {
    let (file, boxes) = common::random_file_with_boxes(seed);
    let bytes = writer::to_bytes(&file).expect("to_bytes");
    let view = BrickFileView::from_bytes(Path::new("q.qbk"), &bytes).expect("open");
    (view, boxes)
}

fn inside(b: &Aabb, p: [f64; 3]) -> bool {
    (0..3).all(|a| p[a] >= b.min[a] && p[a] < b.max[a])
}

fn brute_region_at(boxes: &[Aabb], p: [f64; 3]) -> Option<u32> {
    let hits: Vec<u32> = (0..boxes.len() as u32)
        .filter(|&r| inside(&boxes[r as usize], p))
        .collect();
    assert!(hits.len() <= 1, "regions overlap at {p:?}: {hits:?}");
    hits.first().copied()
}

fn brute_ray(boxes: &[Aabb], o: [f64; 3], d: [f64; 3], t0: f64, t1: f64) -> Vec<RegionSegment> {
    let inv = kd::inverse(&d);
    let mut v: Vec<RegionSegment> = boxes
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            kd::ray_box(&r.min, &r.max, &o, &inv, t0, t1).map(|(a, b)| RegionSegment {
                region: i as u32,
                t_enter: a,
                t_exit: b,
            })
        })
        .collect();
    v.sort_by(|a, b| a.t_enter.total_cmp(&b.t_enter));
    v
}

fn close(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()))
}

fn random_point(rng: &mut Rng, b: &Aabb) -> [f64; 3] {
    // A little outside the bounds too.
    std::array::from_fn(|a| {
        let w = b.max[a] - b.min[a];
        rng.range(b.min[a] - 0.2 * w, b.max[a] + 0.2 * w)
    })
}

fn random_dir(rng: &mut Rng) -> [f64; 3] {
    let mut d: [f64; 3] = std::array::from_fn(|_| rng.range(-1.0, 1.0));
    // Sometimes axis-parallel or in an axis plane.
    if rng.chance(0.2) {
        d[rng.below(3) as usize] = 0.0;
    }
    if rng.chance(0.1) {
        let keep = rng.below(3) as usize;
        for (a, c) in d.iter_mut().enumerate() {
            if a != keep {
                *c = 0.0;
            }
        }
    }
    d
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn region_at_matches_brute_force(seed in any::<u64>()) {
        let (view, boxes) = open(seed);
        let file = view.file();
        let b = query::bounds(file);
        let mut rng = Rng::new(seed ^ 0xABCD);
        for _ in 0..200 {
            let p = random_point(&mut rng, &b);
            prop_assert_eq!(query::region_at(file, p), brute_region_at(&boxes, p), "at {:?}", p);
        }
        // Region corners are on faces: the half-open rule must agree there too.
        for r in &boxes {
            prop_assert_eq!(query::region_at(file, r.min), brute_region_at(&boxes, r.min));
            prop_assert_eq!(query::region_at(file, r.max), brute_region_at(&boxes, r.max));
        }
        // The boxes derived from the tree are the generated ones.
        prop_assert_eq!(query::region_boxes(file), boxes);
    }

    /// A descent that keeps the leaf's cell finds the region `locate` finds, with the box
    /// the walk over every leaf gives it, bit for bit: at random points, on every region's
    /// corners and just inside its upper faces, with and without a shift.
    #[test]
    fn locate_cell_gives_the_region_and_the_walks_box(seed in any::<u64>()) {
        let (view, boxes) = open(seed);
        let file = view.file();
        let tree = kd::file_tree(file);
        let b = query::bounds(file);
        let mut rng = Rng::new(seed ^ 0xCE11);
        for shift in [[0.0; 3], [0.75, -2.5, 1e3]] {
            let local = |p: [f64; 3]| -> [f64; 3] { std::array::from_fn(|a| p[a] - shift[a]) };
            let mut cells = std::collections::HashMap::new();
            kd::leaf_cells(&tree, b.min, b.max, shift, |r, lo, hi| {
                cells.insert(r, (lo.map(f64::to_bits), hi.map(f64::to_bits)));
            });
            let mut points: Vec<[f64; 3]> = (0..100).map(|_| random_point(&mut rng, &b)).collect();
            for r in &boxes {
                points.extend([r.min, r.max]);
                points.push(std::array::from_fn(|a| r.max[a].next_down().max(r.min[a])));
            }
            for p in points {
                let q = local(p);
                let found = kd::locate_cell(&tree, q, b.min, b.max, shift);
                prop_assert_eq!(found.map(|f| f.0), kd::locate(&tree, q, shift), "at {:?}", p);
                if let Some((r, lo, hi)) = found {
                    prop_assert_eq!(
                        Some(&(lo.map(f64::to_bits), hi.map(f64::to_bits))),
                        cells.get(&r),
                        "region {} at {:?}", r, p
                    );
                }
            }
        }
    }

    /// A point's descent finds for any other point what a descent from the root finds:
    /// points a little away along one axis (a shading normal's neighbours), points on
    /// region faces, points anywhere, with and without a shift of the coordinates.
    #[test]
    fn locate_near_a_descent_matches_locate(seed in any::<u64>()) {
        let (view, boxes) = open(seed);
        let tree = kd::file_tree(view.file());
        let b = query::bounds(view.file());
        let mut rng = Rng::new(seed ^ 0x5EED);
        for shift in [[0.0; 3], [0.75, -2.5, 1e3]] {
            let local = |p: [f64; 3]| -> [f64; 3] { std::array::from_fn(|a| p[a] - shift[a]) };
            for _ in 0..50 {
                let p = random_point(&mut rng, &b);
                let near = kd::Descent::of(&tree, local(p), shift);
                let region = |c: Option<(u32, [f64; 3], [f64; 3])>| c.map(|c| c.0);
                prop_assert_eq!(
                    region(near.locate_cell(&tree, local(p), b.min, b.max, shift)),
                    kd::locate(&tree, local(p), shift)
                );
                let mut others = vec![random_point(&mut rng, &b)];
                for a in 0..3 {
                    for h in [1e-9, 0.01, 0.3, 2.0] {
                        let mut q = p;
                        q[a] += h;
                        others.push(q);
                        q[a] = p[a] - h;
                        others.push(q);
                    }
                }
                if !boxes.is_empty() {
                    let r = &boxes[rng.below(boxes.len() as u64) as usize];
                    others.extend([r.min, r.max]);
                }
                for q in others {
                    prop_assert_eq!(
                        region(near.locate_cell(&tree, local(q), b.min, b.max, shift)),
                        kd::locate(&tree, local(q), shift),
                        "from {:?} to {:?}", p, q
                    );
                    // With the box: the cell a descent from the root cuts, bit for bit.
                    let bits = |c: Option<(u32, [f64; 3], [f64; 3])>| {
                        c.map(|(r, lo, hi)| (r, lo.map(f64::to_bits), hi.map(f64::to_bits)))
                    };
                    prop_assert_eq!(
                        bits(near.locate_cell(&tree, local(q), b.min, b.max, shift)),
                        bits(kd::locate_cell(&tree, local(q), b.min, b.max, shift)),
                        "cell from {:?} to {:?}", p, q
                    );
                }
            }
        }
    }

    #[test]
    fn ray_regions_match_brute_force(seed in any::<u64>()) {
        let (view, boxes) = open(seed);
        let file = view.file();
        let b = query::bounds(file);
        let mut rng = Rng::new(seed ^ 0x1234);
        for _ in 0..100 {
            let mut o = random_point(&mut rng, &b);
            let d = random_dir(&mut rng);
            // A ray in a face plane of some region: tests the half-open rule for rays
            // parallel to a split plane.
            if !boxes.is_empty() && rng.chance(0.5) {
                let r = &boxes[rng.below(boxes.len() as u64) as usize];
                for a in 0..3 {
                    if d[a] == 0.0 {
                        o[a] = if rng.chance(0.5) { r.min[a] } else { r.max[a] };
                    }
                }
            }
            let (t0, t1) = if rng.chance(0.5) {
                (0.0, f64::INFINITY)
            } else {
                let a = rng.range(-5.0, 10.0);
                (a, a + rng.range(0.0, 10.0))
            };
            let kd = query::ray_regions(file, o, d, t0, t1);
            let bf = brute_ray(&boxes, o, d, t0, t1);
            prop_assert_eq!(kd.len(), bf.len(), "o {:?} d {:?}\nkd {:?}\nbf {:?}", o, d, kd, bf);
            for (k, f) in kd.iter().zip(&bf) {
                prop_assert_eq!(k.region, f.region);
                prop_assert!(close(k.t_enter, f.t_enter) && close(k.t_exit, f.t_exit), "{:?} vs {:?}", k, f);
            }
            // Front to back, non-overlapping.
            for w in kd.windows(2) {
                prop_assert!(w[0].t_exit <= w[1].t_enter);
            }
            // The iterator form yields the same.
            let it: Vec<_> = RayRegions::new(file, o, d, t0, t1).collect();
            prop_assert_eq!(&it, &kd);
        }
    }

    #[test]
    fn brick_access_matches_layout(seed in any::<u64>()) {
        let original = common::random_file(seed);
        let (view, _) = open(seed);
        let file = view.file();
        for (bi, brick) in original.bricks.iter().enumerate() {
            let ab = &file.bricks[bi];
            for (fi, field) in original.fields.iter().enumerate() {
                let vals = query::brick_values(file, bi as u32, fi).expect("brick values");
                prop_assert_eq!(vals.len() as u64, query::brick_cells(ab));
                let [nx, ny, nz] = brick.dims;
                for k in 0..nz {
                    for j in 0..ny {
                        for i in 0..nx {
                            let c = query::cell_index(ab, [i, j, k]).expect("in brick");
                            let global = brick.first_value as usize
                                + (i + nx * (j + ny * k)) as usize;
                            prop_assert_eq!(vals[c].to_native(), field.values[global]);
                        }
                    }
                }
            }
            prop_assert!(query::cell_index(ab, brick.dims).is_none());
            let centre = query::cell_center(ab, [1, 0, 2]);
            for a in 0..3 {
                let ijk = [1.0, 0.0, 2.0][a];
                prop_assert_eq!(centre[a], brick.origin[a] + ijk * brick.cell_width);
            }
            let s = query::brick_support(ab);
            for a in 0..3 {
                prop_assert_eq!(s.min[a], brick.origin[a] - brick.cell_width);
                prop_assert_eq!(
                    s.max[a],
                    brick.origin[a] + f64::from(brick.dims[a]) * brick.cell_width
                );
            }
        }
        prop_assert!(query::brick_values(file, original.bricks.len() as u32, 0).is_none());
        prop_assert!(query::brick_values(file, 0, original.fields.len()).is_none());
        for (ri, region) in original.regions.iter().enumerate() {
            let ids: Vec<u32> = query::region_bricks(file, ri as u32).iter().map(|v| v.to_native()).collect();
            let start = region.bricks_start as usize;
            prop_assert_eq!(&ids[..], &original.region_bricks[start..start + region.bricks_len as usize]);
            for f in 0..original.fields.len() {
                let r = original.region_ranges[ri * original.fields.len() + f];
                prop_assert_eq!(query::region_range(file, ri as u32, f), Some((r.min, r.max)));
            }
        }
        prop_assert!(query::region_bricks(file, original.regions.len() as u32).is_empty());
        prop_assert_eq!(query::bounds(file), original.bounds);
    }
}

#[test]
fn ray_box_matches_point_sampling() {
    let mut rng = Rng::new(99);
    let file = common::random_file(5);
    let bytes = writer::to_bytes(&file).expect("bytes");
    let view = BrickFileView::from_bytes(Path::new("b.qbk"), &bytes).expect("open");
    let b = &view.file().bounds;
    let bounds = query::bounds(view.file());
    for _ in 0..2000 {
        let o = random_point(&mut rng, &bounds);
        let d = random_dir(&mut rng);
        let inside = |t: f64| {
            let p: [f64; 3] = std::array::from_fn(|a| o[a] + t * d[a]);
            query::contains(b, p)
        };
        match query::ray_box(b, o, d, -100.0, 100.0) {
            Some((t0, t1)) => {
                assert!(inside(0.5 * (t0 + t1)), "midpoint outside: {o:?} {d:?}");
                let eps = 1e-7 * (t1 - t0);
                assert!(inside(t0 + eps) && inside(t1 - eps));
                if t0 > -100.0 {
                    assert!(!inside(t0 - eps.max(1e-9)));
                }
            }
            None => {
                for i in 0..=200 {
                    assert!(!inside(-100.0 + i as f64), "missed {o:?} {d:?}");
                }
            }
        }
    }
}

#[test]
fn degenerate_rays_give_nothing_not_panics() {
    let (view, _) = open(11);
    let file = view.file();
    assert!(query::ray_regions(file, [f64::NAN; 3], [1.0, 0.0, 0.0], 0.0, 1.0).is_empty());
    assert!(query::ray_regions(file, [0.0; 3], [f64::INFINITY, 0.0, 0.0], 0.0, 1.0).is_empty());
    assert!(query::ray_regions(file, [0.0; 3], [1.0, 0.0, 0.0], 1.0, 0.0).is_empty());
}

/// A comb-shaped tree 100 levels deep: a ray walking into the comb keeps every far
/// child on the stack, so the iterator's inline stack (32 entries) must spill.
#[test]
fn deep_tree_spills_the_stack_and_stays_correct() {
    use qbricks_format::kd::BuildNode;
    use qbricks_format::{BrickFile, Field, Level, Provenance, Region};
    let n = 100u32;
    let mut regions = Vec::new();
    let mut boxes = Vec::new();
    let mut built = Vec::new();
    // Node 2i is the inner node splitting at x = i + 1; node 2i + 1 the leaf of slab i.
    for i in 0..n {
        let (lo, hi) = (f64::from(i), f64::from(i + 1));
        boxes.push(Aabb {
            min: [lo, 0.0, 0.0],
            max: [hi, 1.0, 1.0],
        });
        regions.push(Region {
            bricks_start: 0,
            bricks_len: 0,
        });
        if i + 1 < n {
            built.push(BuildNode::Inner {
                axis: 0,
                split: hi,
                left: 2 * i + 1,
                right: 2 * i + 2,
            });
            built.push(BuildNode::Leaf { region: Some(i) });
        } else {
            built.push(BuildNode::Leaf { region: Some(i) });
        }
    }
    let (kd_root, kd_nodes, kd_axes) = kd::pack(&built);
    let file = BrickFile {
        provenance: Provenance {
            source: String::new(),
            grids: vec![],
            bake_options: String::new(),
            tool_version: String::new(),
        },
        bounds: Aabb {
            min: [0.0; 3],
            max: [f64::from(n), 1.0, 1.0],
        },
        levels: vec![Level {
            cell_width: 1.0,
            cells: 0,
            bricks: 0,
        }],
        fields: vec![Field {
            name: "q".into(),
            min: 0.0,
            max: 0.0,
            histogram: vec![],
            values: vec![],
        }],
        bricks: vec![],
        region_ranges: vec![qbricks_format::ValueRange { min: 0.0, max: 0.0 }; n as usize],
        regions,
        region_bricks: vec![],
        kd_root,
        kd_nodes,
        kd_axes,
    };
    let bytes = writer::to_bytes(&file).expect("bytes");
    let view = BrickFileView::from_bytes(Path::new("deep.qbk"), &bytes).expect("open");
    let f = view.file();
    for (o, d) in [
        ([-1.0, 0.5, 0.5], [1.0, 0.01, 0.0]),
        ([f64::from(n) + 1.0, 0.5, 0.5], [-1.0, 0.0, 0.001]),
        ([50.5, 0.5, 0.5], [-1.0, 0.0, 0.0]),
    ] {
        let kd = query::ray_regions(f, o, d, 0.0, f64::INFINITY);
        let bf = brute_ray(&boxes, o, d, 0.0, f64::INFINITY);
        assert_eq!(kd.len(), bf.len());
        assert!(kd.len() > 40);
        for (k, b) in kd.iter().zip(&bf) {
            assert_eq!(k.region, b.region);
            assert!(close(k.t_enter, b.t_enter) && close(k.t_exit, b.t_exit));
        }
    }
    // Deeper than a descent keeps: its neighbours are found from the root.
    let tree = kd::file_tree(f);
    let near = kd::Descent::of(&tree, [99.5, 0.5, 0.5], [0.0; 3]);
    for x in [99.5, 98.9, 0.2, 64.5, 63.5] {
        let b = query::bounds(f);
        assert_eq!(
            near.locate_cell(&tree, [x, 0.5, 0.5], b.min, b.max, [0.0; 3])
                .map(|c| c.0),
            kd::locate(&tree, [x, 0.5, 0.5], [0.0; 3])
        );
        assert_eq!(
            near.locate_cell(&tree, [x, 0.5, 0.5], b.min, b.max, [0.0; 3]),
            kd::locate_cell(&tree, [x, 0.5, 0.5], b.min, b.max, [0.0; 3])
        );
    }
    assert_eq!(query::region_at(f, [99.5, 0.5, 0.5]), Some(99));
    assert_eq!(query::region_at(f, [0.0, 0.5, 0.5]), Some(0));
}

/// Every number of a packed tree, as bits (NaN ranges compare too).
type RangedBits = (
    u32,
    Vec<(u64, u32, u32, u32, u32, u8, bool)>,
    Vec<(u32, u32)>,
);

fn ranged_bits(tree: &kd::RangedTree) -> RangedBits {
    let inner = tree
        .inner
        .iter()
        .map(|n| {
            (
                n.split.to_bits(),
                n.a,
                n.b,
                n.min.to_bits(),
                n.max.to_bits(),
                n.axis,
                n.full,
            )
        })
        .collect();
    let leaves = tree
        .leaves
        .iter()
        .map(|&(a, b)| (a.to_bits(), b.to_bits()))
        .collect();
    (tree.root, inner, leaves)
}

/// A complete tree of `depth` levels over the unit cube, its leaves numbered left to
/// right, every seventh empty.
struct Complete(Vec<kd::Node>);

impl Complete {
    fn new(depth: u32) -> Complete {
        let mut nodes = Vec::new();
        let mut leaf = 0u32;
        fn build(nodes: &mut Vec<kd::Node>, leaf: &mut u32, d: u32, depth: u32) -> u32 {
            let i = nodes.len() as u32;
            if d == depth {
                let r = (*leaf % 7 != 6).then_some(*leaf);
                *leaf += 1;
                nodes.push(kd::Node::Leaf(r));
                return i;
            }
            nodes.push(kd::Node::Leaf(None));
            let left = build(nodes, leaf, d + 1, depth);
            let right = build(nodes, leaf, d + 1, depth);
            nodes[i as usize] = kd::Node::Inner {
                axis: (d % 3) as usize,
                split: 0.5 + f64::from(d) * 1e-3,
                left,
                right,
            };
            i
        }
        build(&mut nodes, &mut leaf, 0, depth);
        Complete(nodes)
    }
}

impl kd::KdTree for Complete {
    fn node_count(&self) -> usize {
        self.0.len()
    }
    fn root(&self) -> u32 {
        0
    }
    fn node(&self, i: u32) -> Option<kd::Node> {
        self.0.get(i as usize).copied()
    }
}

/// `subtree_ranges_on` gives `subtree_ranges`' tree on large trees, whatever the number
/// of threads (cuts below, at and above the tree's depth), with missing region ranges;
/// the tree lists its inner nodes only, its leaves as references.
#[test]
fn subtree_ranges_on_threads_are_the_one_walks() {
    for depth in [0, 1, 3, 6, 11] {
        let tree = Complete::new(depth);
        let regions = 1usize << depth;
        let range = |r: u32| (r % 5 != 3).then_some((r as f32 * 0.5, r as f32 * 0.5 + 2.0));
        let one = ranged_bits(&kd::subtree_ranges(&tree, regions, range));
        assert_eq!(one.1.len(), regions - 1, "inner nodes");
        assert_eq!(one.2.len(), regions, "one range a region");
        if depth == 0 {
            assert_eq!(one.0, kd::LEAF, "a root leaf is a leaf reference");
        }
        for threads in [2, 3, 4, 8, 64] {
            let on = ranged_bits(&kd::subtree_ranges_on(&tree, regions, range, threads));
            assert_eq!(on, one, "depth {depth}, {threads} threads");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The per-subtree ranges a reader derives (`kd::subtree_ranges`) against brute force:
    /// every node's range is the union of its leaves' region ranges, `full` says no leaf
    /// below is empty, parents come before children, and every region is one leaf.
    #[test]
    fn subtree_ranges_match_brute_force(seed in any::<u64>()) {
        let (view, _) = open(seed);
        let file = view.file();
        let nf = file.fields.len();
        let field = (seed % nf as u64) as usize;
        let range = |r: u32| query::region_range(file, r, field);
        let regions = file.regions.len();
        let tree = kd::subtree_ranges(&kd::file_tree(file), regions, range);
        // Counted and filled subtree by subtree on several threads: the same tree.
        for threads in [2, 3, 8] {
            let on = kd::subtree_ranges_on(&kd::file_tree(file), regions, range, threads);
            prop_assert_eq!(ranged_bits(&on), ranged_bits(&tree), "{} threads", threads);
        }
        // Leaves below each reference, by recursion over the tree.
        fn leaves(tree: &kd::RangedTree, n: u32, out: &mut Vec<Option<u32>>) {
            use kd::WalkNodes;
            match tree.node(n).expect("a node") {
                kd::Node::Inner { left, right, .. } => {
                    for c in [left, right] {
                        assert!(c & kd::LEAF != 0 || c > n, "parent first");
                    }
                    leaves(tree, left, out);
                    leaves(tree, right, out);
                }
                kd::Node::Leaf(r) => out.push(r),
            }
        }
        for (i, n) in tree.inner.iter().enumerate() {
            let mut below = Vec::new();
            leaves(&tree, i as u32, &mut below);
            prop_assert_eq!(n.full, below.iter().all(|r| r.is_some()));
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for r in below.into_iter().flatten() {
                let (a, b) = range(r).expect("region range");
                lo = lo.min(a);
                hi = hi.max(b);
            }
            prop_assert_eq!((n.min, n.max), (lo, hi), "node {}", i);
        }
        // The walk's reads of a leaf: its region's range, full unless empty.
        for r in 0..regions as u32 {
            use kd::WalkNodes;
            let want = range(r).expect("region range");
            prop_assert_eq!(tree.range(kd::LEAF | r), Some(want));
            prop_assert!(tree.full(kd::LEAF | r));
        }
        prop_assert!(!kd::WalkNodes::full(&tree, kd::EMPTY));
        let mut all = Vec::new();
        leaves(&tree, tree.root, &mut all);
        let mut regions: Vec<u32> = all.into_iter().flatten().collect();
        regions.sort_unstable();
        prop_assert_eq!(regions, (0..file.regions.len() as u32).collect::<Vec<_>>());
    }
}
