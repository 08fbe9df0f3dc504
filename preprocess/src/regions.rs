//! Active brick regions: boxes partitioning the union of brick supports, each listing every
//! brick whose support overlaps it.
//!
//! Built by recursive splitting at support boundaries (a KD-style build), so the KD-tree
//! over the regions falls out of the recursion, written as it goes in the file's layout
//! ([`crate::kdtree`]). A node whose box has no support boundary strictly inside is a region:
//! every support that overlaps it covers it. Otherwise it splits at the boundary plane with
//! the lowest cost `cut − shared`: `cut` supports straddle the plane (each is fragmented by
//! it), `shared` supports have a face on it (the plane is a cut the partition needs anyway).
//! Ties go to the plane nearest the middle of the box. On the synthetic wake this gives
//! about 23% fewer regions than minimising `cut` alone (4491 instead of 5849 for 238
//! bricks).
//!
//! That partition has one region per distinct overlap of supports, which is what a ray
//! needs where bricks are large, and far too much where many small supports of several
//! levels cross (next to an obstacle whose cells are inactive on every level, where thin
//! shells of partly covered coarse cells lie over small fine bricks): there a ray crosses
//! dozens of regions of a few bricks each. So as each subtree is finished, bottom-up,
//! it is replaced by one region, listing the union of its regions' bricks, wherever that costs a
//! ray less: a region costs `A·s` for the walk to it and the segment (A its surface area,
//! which a random ray's chance of crossing it is proportional to; `s` a length, see
//! [`build`]) plus `V·n` for sampling it (V its volume, which the ray's expected path in it
//! is proportional to; n its bricks, each of which a sample visits), an inner node `A·s`.
//! Subtrees holding empty space are never merged, so the regions still cover the union of
//! the supports exactly, and a region's bricks are still exactly the supports that overlap
//! its box; only the set of supports *containing a point* may now change inside a region.
//! The reconstruction does not mind (a brick whose tents are zero at a point adds nothing
//! there), the value ranges stay exact over the cells that can contribute to the region,
//! and every brick's lattice is among the region's, so `exact` still cuts every plane
//! where the reconstruction stops being one cubic.

use std::sync::Arc;

use format::kd::EMPTY;
use format::Aabb;

use crate::kdtree::{Limits, Part, Regions, TooLarge, Tree};
use crate::spilled::SpillTo;

/// A region's walk and segment cost as a length of path through one brick's samples, in
/// finest cell widths (`s` of the module docs over the finest width). Measured on issue
/// 33's benchmark files: see BENCHMARKS.md.
pub(crate) const SEGMENT_COST_CELLS: f64 = 0.5;

/// The regions over a set of supports and the KD-tree that finds them, as the file stores
/// them.
#[derive(Debug)]
pub(crate) struct Built {
    /// The union box of all supports (None when there are none).
    pub bounds: Option<Aabb>,
    pub tree: Tree,
    pub regions: Regions,
}

/// Builds the regions over `supports` (indexed by brick id), merging subtrees where a
/// region costs `segment` (a length) per crossing (see the module docs; 0 keeps one region
/// per overlap), straight into the file's layout ([`crate::kdtree`]); its arrays move to
/// scratch files where `to` says.
pub(crate) fn build(
    supports: &[Aabb],
    segment: f64,
    to: Option<Arc<SpillTo>>,
) -> Result<Built, TooLarge> {
    build_within(
        supports,
        segment,
        Limits::FILE,
        parallel_min(supports.len()),
        to,
    )
}

/// Below this many supports a node recurses on the current thread.
const PARALLEL_MIN: usize = 64;

/// Supports at which a node still hands its right half to another thread: a few tasks per
/// thread balance the load, and each hand-off copies that half's nodes and regions once
/// more, so the split stops well above [`PARALLEL_MIN`] on large inputs.
fn parallel_min(supports: usize) -> usize {
    (supports / (8 * rayon::current_num_threads())).max(PARALLEL_MIN)
}

fn build_within(
    supports: &[Aabb],
    segment: f64,
    limits: Limits,
    parallel_min: usize,
    to: Option<Arc<SpillTo>>,
) -> Result<Built, TooLarge> {
    let mut part = Part::new(limits, to);
    let Some(first) = supports.first() else {
        let (tree, regions) = part.finish(EMPTY)?;
        return Ok(Built {
            bounds: None,
            tree,
            regions,
        });
    };
    let bounds = supports.iter().fold(*first, |acc, s| acc.union(*s));
    let ids: Vec<u32> = (0..supports.len() as u32).collect();
    let split = Splitter {
        sup: supports,
        segment,
        parallel_min,
    };
    let root = split.node(bounds, ids, &mut part).root;
    let (tree, regions) = part.finish(root)?;
    Ok(Built {
        bounds: Some(bounds),
        tree,
        regions,
    })
}

/// Surface area (the whole surface: only ratios matter).
fn area(b: &Aabb) -> f64 {
    2.0 * b.half_area()
}

fn volume(b: &Aabb) -> f64 {
    (0..3).map(|a| (b.max[a] - b.min[a]).max(0.0)).product()
}

/// What the split of a box left in the part.
struct Sub {
    /// Its reference (a node, a region or empty space).
    root: u32,
    /// Its cost (see the module docs).
    cost: f64,
    /// The sorted union of its regions' bricks, when it holds no empty space and may be
    /// merged (or is a region, whose bricks the parent compares with its sibling's).
    union: Option<Vec<u32>>,
    /// One region per overlap, not merged: two such siblings listing the same bricks are
    /// one region (a plane inside an overlap that a split elsewhere needed).
    leaf: bool,
    empty: bool,
}

const EMPTY_SUB: Sub = Sub {
    root: EMPTY,
    cost: 0.0,
    union: None,
    leaf: false,
    empty: true,
};

/// The recursive split (see the module docs), merging each subtree as soon as its two
/// halves are done: bottom-up, so each subtree is compared with the best of its own
/// subtrees, and what a merged subtree had stored is dropped from the part at once.
struct Splitter<'a> {
    sup: &'a [Aabb],
    segment: f64,
    parallel_min: usize,
}

impl Splitter<'_> {
    fn region(&self, part: &mut Part, b: Aabb, bricks: Vec<u32>, leaf: bool) -> Sub {
        Sub {
            root: part.region(&bricks),
            cost: area(&b) * self.segment + volume(&b) * bricks.len() as f64,
            union: Some(bricks),
            leaf,
            empty: false,
        }
    }

    fn node(&self, b: Aabb, ids: Vec<u32>, part: &mut Part) -> Sub {
        let sup = self.sup;
        if ids.is_empty() {
            return EMPTY_SUB;
        }
        let Some((axis, split)) = choose_split(sup, &b, &ids) else {
            let mut bricks = ids;
            bricks.sort_unstable();
            return self.region(part, b, bricks, true);
        };
        let mark = part.mark();
        let id = part.open(axis, split);
        let a = axis as usize;
        let left_ids: Vec<u32> = ids
            .iter()
            .copied()
            .filter(|&i| sup[i as usize].min[a] < split)
            .collect();
        let right_ids: Vec<u32> = ids
            .into_iter()
            .filter(|&i| sup[i as usize].max[a] > split)
            .collect();
        let mut lb = b;
        lb.max[a] = split;
        let mut rb = b;
        rb.min[a] = split;
        let (left, right) = if left_ids.len() + right_ids.len() >= self.parallel_min {
            let mut own = part.another();
            let (left, (right, right_part)) = rayon::join(
                || self.node(lb, left_ids, part),
                || {
                    let right = self.node(rb, right_ids, &mut own);
                    (right, own)
                },
            );
            let root = part.append(right_part, right.root);
            (left, Sub { root, ..right })
        } else {
            let left = self.node(lb, left_ids, part);
            (left, self.node(rb, right_ids, part))
        };
        if left.empty && right.empty {
            part.rollback(mark);
            return EMPTY_SUB;
        }
        if left.leaf && right.leaf && left.union == right.union {
            part.rollback(mark);
            let bricks = left.union.unwrap_or_default();
            return self.region(part, b, bricks, true);
        }
        part.close(id, left.root, right.root);
        let split_cost = area(&b) * self.segment + left.cost + right.cost;
        // Only a subtree without empty space may be merged, and nothing is when a
        // crossing costs nothing (then no union is needed).
        let mut union = match (left.union, right.union) {
            (Some(lu), Some(ru)) if self.segment > 0.0 => Some(sorted_union(&lu, &ru)),
            _ => None,
        };
        // One region costs what `region` counts for it.
        let cheaper =
            |u: &mut Vec<u32>| area(&b) * self.segment + volume(&b) * u.len() as f64 <= split_cost;
        if let Some(union) = union.take_if(cheaper) {
            part.rollback(mark);
            return self.region(part, b, union, false);
        }
        Sub {
            root: id,
            cost: split_cost,
            union,
            leaf: false,
            empty: false,
        }
    }
}

/// The union of two sorted lists of ids, sorted.
fn sorted_union(a: &[u32], b: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].cmp(&b[j]) {
            std::cmp::Ordering::Less => {
                out.push(a[i]);
                i += 1;
            }
            std::cmp::Ordering::Greater => {
                out.push(b[j]);
                j += 1;
            }
            std::cmp::Ordering::Equal => {
                out.push(a[i]);
                i += 1;
                j += 1;
            }
        }
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
    out
}

/// Differences of balance (distance to the middle over the box's extent) below this are
/// taken for rounding: far from the origin a coordinate's spacing is up to 2^26 · 2^-52 ≈
/// 1.5e-8 of a finest cell (see `MAX_BAKE_REACH_LOG2`), so in a box one cell wide rounding
/// moves a balance by at most that. Split positions lie half a finest cell apart or more,
/// so only in boxes wider than 500 000 finest cells are two real positions this close,
/// and then the tie-break (not the partition's correctness) is all that changes.
const BALANCE_TIE: f64 = 1e-6;

/// Plane (axis, coordinate) among the support boundaries strictly inside `b` with the
/// lowest `cut − shared` (see the module docs); ties go to the plane nearest the middle,
/// then to the lower axis and coordinate.
fn choose_split(sup: &[Aabb], b: &Aabb, ids: &[u32]) -> Option<(u8, f64)> {
    let mut best: Option<(usize, f64, u8, f64)> = None;
    let mut mins = Vec::with_capacity(ids.len());
    let mut maxs = Vec::with_capacity(ids.len());
    for a in 0..3 {
        mins.clear();
        maxs.clear();
        mins.extend(ids.iter().map(|&i| sup[i as usize].min[a]));
        maxs.extend(ids.iter().map(|&i| sup[i as usize].max[a]));
        mins.sort_unstable_by(f64::total_cmp);
        maxs.sort_unstable_by(f64::total_cmp);
        let (lo, hi) = (b.min[a], b.max[a]);
        let mid = 0.5 * (lo + hi);
        let ext = hi - lo;
        let mut consider = |v: f64| {
            if !(v > lo && v < hi) {
                return;
            }
            // Supports with min < v < max straddle v: all with min < v minus those
            // entirely below (max <= v).
            let below_start = mins.partition_point(|&m| m < v);
            let ended = maxs.partition_point(|&m| m <= v);
            let cost = below_start - ended;
            // Supports with a face on v: the partition needs this plane for them anyway.
            let shared = mins.partition_point(|&m| m <= v) - below_start + ended
                - maxs.partition_point(|&m| m < v);
            let bal = (v - mid).abs() / ext;
            let cost = cost + ids.len() - shared.min(ids.len());
            // Balances that differ by rounding only are a tie, kept by the first plane
            // (lowest axis, then lowest coordinate): which of two planes symmetric about
            // the middle rounds nearer it depends on where the data lies, and the tree
            // must not.
            let better = match best {
                None => true,
                Some((c, bb, _, _)) => cost < c || (cost == c && bal < bb - BALANCE_TIE),
            };
            if better {
                best = Some((cost, bal, a as u8, v));
            }
        };
        let mut prev = f64::NAN;
        for &v in mins.iter().chain(maxs.iter()) {
            if v != prev {
                consider(v);
                prev = v;
            }
        }
    }
    best.map(|(_, _, a, v)| (a, v))
}

/// Regions (box, bricks) in the order the tree numbers them (depth-first, left-first).
#[cfg(test)]
pub(crate) fn leaves(built: &Built) -> Vec<(Aabb, &[u32])> {
    let Some(bounds) = built.bounds else {
        return Vec::new();
    };
    let boxes: Vec<Aabb> = crate::kdtree::leaf_boxes(&built.tree, bounds).collect();
    assert_eq!(boxes.len(), built.regions.len(), "a box for every region");
    boxes
        .into_iter()
        .enumerate()
        .map(|(r, b)| (b, built.regions.bricks_of(r)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn volume(b: &Aabb) -> f64 {
        (0..3).map(|a| (b.max[a] - b.min[a]).max(0.0)).product()
    }

    fn intersect(a: &Aabb, b: &Aabb) -> Aabb {
        Aabb {
            min: [0, 1, 2].map(|i| a.min[i].max(b.min[i])),
            max: [0, 1, 2].map(|i| a.max[i].min(b.max[i])),
        }
    }

    /// Random multi-level layouts: supports of bricks on lattices of width 1, 2, 4
    /// (origin - w .. origin + dims*w), like the baker makes.
    fn layout() -> impl Strategy<Value = Vec<Aabb>> {
        prop::collection::vec(
            (
                0u32..3,
                0i32..6,
                0i32..6,
                0i32..6,
                1u32..4,
                1u32..4,
                1u32..4,
            ),
            1..14,
        )
        .prop_map(|v| {
            v.into_iter()
                .map(|(l, x, y, z, dx, dy, dz)| {
                    let w = (1u32 << l) as f64;
                    let o = [x, y, z].map(|c| c as f64 * w + 0.5 * w);
                    let d = [dx, dy, dz].map(|c| c as f64);
                    Aabb {
                        min: [0, 1, 2].map(|a| o[a] - w),
                        max: [0, 1, 2].map(|a| o[a] + d[a] * w),
                    }
                })
                .collect()
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(96))]
        #[test]
        fn regions_partition_supports(
            sup in layout(),
            pts in prop::collection::vec((0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0), 32),
            segment in prop_oneof![Just(0.0), Just(0.5), Just(4.0)],
        ) {
            let built = build(&sup, segment, None).expect("few regions");
            let bounds = built.bounds.expect("non-empty");
            let regs = leaves(&built);
            // The walk cut into subtrees (how the viewer derives its region table on all
            // cores) gives the whole walk's leaves, bit for bit and in order.
            let tree = crate::kdtree::stored(&built.tree);
            let bits = |(r, lo, hi): (u32, [f64; 3], [f64; 3])| (r, lo.map(f64::to_bits), hi.map(f64::to_bits));
            let whole: Vec<_> = format::kd::LeafCells::new(tree, bounds.min, bounds.max, [0.0; 3]).map(bits).collect();
            prop_assert_eq!(whole.len(), regs.len());
            for depth in [0, 1, 2, 5, 40] {
                let parts = format::kd::LeafCells::split(tree, bounds.min, bounds.max, [0.0; 3], depth);
                prop_assert!(parts.len() <= 1 << depth.min(20));
                let joined: Vec<_> = parts.into_iter().flatten().map(bits).collect();
                prop_assert_eq!(&joined, &whole, "depth {}", depth);
            }
            // Disjoint.
            for i in 0..regs.len() {
                prop_assert!(volume(&regs[i].0) > 0.0);
                for j in i + 1..regs.len() {
                    prop_assert!(!regs[i].0.overlaps(&regs[j].0), "regions {} and {} overlap", i, j);
                }
            }
            // Brick list equals brute force, and every support is covered by the regions
            // overlapping it (volumes of the pieces add up).
            for (b, bricks) in &regs {
                let brute: Vec<u32> = (0..sup.len() as u32)
                    .filter(|&i| sup[i as usize].overlaps(b))
                    .collect();
                prop_assert_eq!(&brute, &bricks.to_vec());
                for a in 0..3 {
                    prop_assert!(b.min[a] >= bounds.min[a] && b.max[a] <= bounds.max[a]);
                }
                // Unmerged, one region per overlap: every support it lists covers it.
                if segment == 0.0 {
                    for &i in bricks.iter() {
                        let s = &sup[i as usize];
                        prop_assert!((0..3).all(|a| s.min[a] <= b.min[a] && s.max[a] >= b.max[a]));
                    }
                }
            }
            for (i, s) in sup.iter().enumerate() {
                let covered: f64 = regs
                    .iter()
                    .filter(|(_, br)| br.contains(&(i as u32)))
                    .map(|(b, _)| volume(&intersect(b, s)))
                    .sum();
                prop_assert!((covered - volume(s)).abs() <= 1e-9 * volume(s));
                // and no region lists a brick whose support it does not overlap (checked
                // above), so the union of regions is exactly the union of supports.
            }
            // The stored KD-tree finds the same region as brute force.
            let (packed, flat) = (&built.tree, &built.regions);
            for (x, y, z) in pts {
                let f = [x, y, z];
                let p = [0, 1, 2].map(|a| bounds.min[a] + f[a] * (bounds.max[a] - bounds.min[a]));
                let brute = regs.iter().map(|(b, _)| b).position(|b| {
                    (0..3).all(|a| p[a] >= b.min[a] && p[a] < b.max[a])
                });
                prop_assert_eq!(crate::kdtree::locate(packed, p), brute.map(|r| r as u32));
                let in_support = sup.iter().any(|s| (0..3).all(|a| p[a] >= s.min[a] && p[a] < s.max[a]));
                prop_assert_eq!(brute.is_some(), in_support);
            }
            // Parents before children, and every region in exactly one leaf, in order.
            let (root, nodes, axes) = packed;
            prop_assert_eq!(nodes.len(), axes.len());
            let mut seen = Vec::new();
            let mut todo = vec![(*root, None::<u32>)];
            while let Some((r, parent)) = todo.pop() {
                if r == EMPTY {
                    continue;
                }
                if r & format::kd::LEAF != 0 {
                    seen.push(r & !format::kd::LEAF);
                    continue;
                }
                prop_assert!(parent.is_none_or(|p| r > p));
                let n = &nodes[r as usize];
                todo.push((n.right, Some(r)));
                todo.push((n.left, Some(r)));
            }
            prop_assert_eq!(seen, (0..flat.len() as u32).collect::<Vec<_>>());
            // Handing halves to other threads (at every node, or none) builds the same.
            for every in [1, usize::MAX] {
                let other = build_within(&sup, segment, Limits::FILE, every, None).expect("few regions");
                prop_assert_eq!(&other.tree, &built.tree);
                prop_assert_eq!(&other.regions, &built.regions);
            }
            // Kept in scratch files (every array of every part, or past a few values):
            // the same tree and regions.
            let dir = tempfile::tempdir().expect("tempdir");
            for (every, above) in [(1, 0), (usize::MAX, 0), (1, 40)] {
                let to = Arc::new(SpillTo { dir: dir.path().to_path_buf(), above, window: 64 });
                let other = build_within(&sup, segment, Limits::FILE, every, Some(to))
                    .expect("few regions");
                prop_assert!(above > 0 || other.tree.1.is_empty() || other.tree.1.on_disk());
                prop_assert_eq!(&other.tree, &built.tree);
                prop_assert_eq!(&other.regions, &built.regions);
            }
            // Just past what the limits allow, the tree is refused with its size; at
            // them, it is built as before.
            let size = Limits {
                regions: flat.len() as u64,
                nodes: nodes.len() as u64,
                refs: flat.bricks.len() as u64,
            };
            for every in [1, usize::MAX] {
                let at = build_within(&sup, segment, size, every, None).expect("at the limits");
                prop_assert_eq!(&at.regions, &built.regions);
                let fewer = |l: Limits| build_within(&sup, segment, l, every, None).map(|b| b.regions);
                let regions = size.regions;
                prop_assert_eq!(
                    fewer(Limits { regions: regions - 1, ..size }),
                    Err(TooLarge::Regions(regions))
                );
                prop_assert_eq!(
                    fewer(Limits { refs: size.refs - 1, ..size }),
                    Err(TooLarge::BrickRefs(size.refs))
                );
                if size.nodes > 0 {
                    prop_assert_eq!(
                        fewer(Limits { nodes: size.nodes - 1, ..size }),
                        Err(TooLarge::Regions(regions))
                    );
                }
            }
        }
    }

    /// Many small supports of three lattices crossing each other (as next to an obstacle,
    /// where partly covered coarse cells lie over small fine bricks): merged into far fewer
    /// regions, each listing exactly the supports that overlap it, with the empty space
    /// between two such clusters left out; one region per overlap without merging.
    #[test]
    fn crossing_small_supports_merge_but_empty_space_stays_out() {
        let mut sup = Vec::new();
        for cluster in [0.0, 40.0] {
            for k in 0..40 {
                let w = [1.0, 2.0, 4.0][k % 3];
                let o = [0, 1, 2].map(|a| cluster + ((k * (a + 3) * 7) % 13) as f64 * 0.5);
                sup.push(Aabb {
                    min: o.map(|v| v - w),
                    max: o.map(|v| v + w * (1 + k % 2) as f64),
                });
            }
        }
        let exact = build(&sup, 0.0, None).expect("few regions");
        let merged = build(&sup, 0.5, None).expect("few regions");
        let bounds = merged.bounds;
        let (exact, merged) = (leaves(&exact), leaves(&merged));
        assert!(
            merged.len() * 4 < exact.len(),
            "{} regions merged from {}",
            merged.len(),
            exact.len()
        );
        let bounds = bounds.expect("supports");
        for (b, bricks) in &merged {
            let brute: Vec<u32> = (0..sup.len() as u32)
                .filter(|&i| sup[i as usize].overlaps(b))
                .collect();
            assert_eq!(&brute, bricks);
            // No region reaches into the gap between the clusters (x from 14 to 36).
            assert!(b.max[0] <= 14.0 || b.min[0] >= 36.0, "{b:?} in {bounds:?}");
        }
    }

    #[test]
    fn single_support_is_one_region() {
        let s = Aabb {
            min: [0.0; 3],
            max: [1.0, 2.0, 3.0],
        };
        let built = build(&[s], 0.5, None).expect("one region");
        assert_eq!(built.tree.0, format::kd::LEAF);
        assert!(built.tree.1.is_empty() && built.tree.2.is_empty());
        assert_eq!(leaves(&built), vec![(s, &[0u32][..])]);
    }

    /// Scratch files that cannot be made (a directory that does not exist, as a full disk
    /// would fail them) stop the build with the failure, whichever thread's part met it.
    #[test]
    fn regions_whose_scratch_files_fail_are_refused() {
        let sup: Vec<Aabb> = (0..300)
            .map(|k| {
                let o = [(k % 10) as f64, ((k / 10) % 10) as f64, (k / 100) as f64];
                Aabb {
                    min: o,
                    max: o.map(|v| v + 1.5),
                }
            })
            .collect();
        let to = Arc::new(SpillTo {
            dir: std::path::PathBuf::from("/nonexistent/qbricks-scratch"),
            above: 0,
            window: 64,
        });
        for every in [1, usize::MAX] {
            let e = build_within(&sup, 0.5, Limits::FILE, every, Some(to.clone()))
                .expect_err("no scratch file");
            assert!(matches!(e, TooLarge::Scratch(_)), "{e:?}");
        }
        assert!(build(&sup, 0.5, None).is_ok());
    }

    #[test]
    fn no_support_is_an_empty_tree() {
        let built = build(&[], 0.5, None).expect("nothing");
        assert_eq!(built.bounds, None);
        assert_eq!(built.tree.0, EMPTY);
        assert!(built.tree.1.is_empty() && built.tree.2.is_empty());
        assert_eq!(built.regions.len(), 0);
    }
}
