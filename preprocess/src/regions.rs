//! Active brick regions: boxes partitioning the union of brick supports, each listing every
//! brick whose support overlaps it.
//!
//! Built in two passes. First by recursive splitting at support boundaries (a KD-style
//! build), so the KD-tree over the regions falls out of the recursion ([`crate::kdtree`]
//! serialises it). A node whose box has no support boundary strictly inside is a region:
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
//! dozens of regions of a few bricks each. So the second pass ([`merge`]) replaces a
//! subtree by one region, listing the union of its regions' bricks, wherever that costs a
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

use format::Aabb;

/// The region tree before serialisation.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum RegionTree {
    /// Space inside the global bounds that no support reaches.
    Empty,
    /// A region with its sorted brick ids (a boxed slice: millions of regions are held at
    /// once while the tree is built, and a list's spare capacity would be held with them).
    Region { bounds: Aabb, bricks: Box<[u32]> },
    /// Points with coordinate `< split` on `axis` go left.
    Split {
        axis: u8,
        split: f64,
        left: Box<RegionTree>,
        right: Box<RegionTree>,
    },
}

/// A region's walk and segment cost as a length of path through one brick's samples, in
/// finest cell widths (`s` of the module docs over the finest width). Measured on issue
/// 33's benchmark files: see `merge`'s tests and BENCHMARKS.md.
pub(crate) const SEGMENT_COST_CELLS: f64 = 0.5;

/// Builds the region tree over `supports` (indexed by brick id), merging subtrees where a
/// region costs `segment` (a length) per crossing (see the module docs; 0 keeps one region
/// per overlap). Returns the union box of all supports (None when there are none) and the
/// tree.
pub(crate) fn build(supports: &[Aabb], segment: f64) -> (Option<Aabb>, RegionTree) {
    let Some(first) = supports.first() else {
        return (None, RegionTree::Empty);
    };
    let bounds = supports.iter().fold(*first, |acc, s| acc.union(*s));
    let ids: Vec<u32> = (0..supports.len() as u32).collect();
    let tree = node(supports, bounds, ids);
    let tree = if segment > 0.0 {
        merge(tree, bounds, segment).0
    } else {
        tree
    };
    (Some(bounds), tree)
}

/// Surface area (the whole surface: only ratios matter).
fn area(b: &Aabb) -> f64 {
    2.0 * b.half_area()
}

fn volume(b: &Aabb) -> f64 {
    (0..3).map(|a| (b.max[a] - b.min[a]).max(0.0)).product()
}

/// What [`merge`] returns for a subtree: the subtree, its cost, and the sorted union of its
/// regions' bricks when it holds no empty space (None: it may not be merged).
type Merged = (RegionTree, f64, Option<Vec<u32>>);

/// Replaces every subtree of `t` (whose box is `b`) that holds no empty space by one region
/// when that costs less (see the module docs); bottom-up, so each subtree is compared with
/// the best of its own subtrees.
fn merge(t: RegionTree, b: Aabb, segment: f64) -> Merged {
    match t {
        RegionTree::Empty => (RegionTree::Empty, 0.0, None),
        RegionTree::Region { bounds, bricks } => {
            let cost = area(&bounds) * segment + volume(&bounds) * bricks.len() as f64;
            let union = bricks.to_vec();
            (RegionTree::Region { bounds, bricks }, cost, Some(union))
        }
        RegionTree::Split {
            axis,
            split,
            left,
            right,
        } => {
            let a = axis as usize;
            let (mut lb, mut rb) = (b, b);
            lb.max[a] = split;
            rb.min[a] = split;
            let ((lt, lc, lu), (rt, rc, ru)) = if PARALLEL_MIN_MERGE <= count_regions(&left) {
                rayon::join(|| merge(*left, lb, segment), || merge(*right, rb, segment))
            } else {
                (merge(*left, lb, segment), merge(*right, rb, segment))
            };
            let split_cost = area(&b) * segment + lc + rc;
            let tree = RegionTree::Split {
                axis,
                split,
                left: Box::new(lt),
                right: Box::new(rt),
            };
            let (Some(lu), Some(ru)) = (lu, ru) else {
                return (tree, split_cost, None);
            };
            let union = sorted_union(&lu, &ru);
            let leaf_cost = area(&b) * segment + volume(&b) * union.len() as f64;
            if leaf_cost <= split_cost {
                let bricks = union.clone().into_boxed_slice();
                (
                    RegionTree::Region { bounds: b, bricks },
                    leaf_cost,
                    Some(union),
                )
            } else {
                (tree, split_cost, Some(union))
            }
        }
    }
}

/// Below this many regions a subtree is merged on the current thread.
const PARALLEL_MIN_MERGE: usize = 256;

/// Regions of `t`, counted up to [`PARALLEL_MIN_MERGE`] (enough to decide on a thread).
fn count_regions(t: &RegionTree) -> usize {
    let mut n = 0;
    let mut todo = vec![t];
    while let Some(t) = todo.pop() {
        match t {
            RegionTree::Empty => {}
            RegionTree::Region { .. } => n += 1,
            RegionTree::Split { left, right, .. } => {
                if n >= PARALLEL_MIN_MERGE {
                    break;
                }
                todo.push(left);
                todo.push(right);
            }
        }
    }
    n
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

/// Below this many supports a node recurses on the current thread.
const PARALLEL_MIN: usize = 64;

fn node(sup: &[Aabb], b: Aabb, ids: Vec<u32>) -> RegionTree {
    if ids.is_empty() {
        return RegionTree::Empty;
    }
    let Some((axis, split)) = choose_split(sup, &b, &ids) else {
        let mut bricks = ids;
        bricks.sort_unstable();
        return RegionTree::Region {
            bounds: b,
            bricks: bricks.into_boxed_slice(),
        };
    };
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
    let (left, right) = if left_ids.len() + right_ids.len() >= PARALLEL_MIN {
        rayon::join(|| node(sup, lb, left_ids), || node(sup, rb, right_ids))
    } else {
        (node(sup, lb, left_ids), node(sup, rb, right_ids))
    };
    match (&left, &right) {
        (RegionTree::Empty, RegionTree::Empty) => RegionTree::Empty,
        (RegionTree::Region { bricks: l, .. }, RegionTree::Region { bricks: r, .. }) if l == r => {
            RegionTree::Region {
                bounds: b,
                bricks: l.clone(),
            }
        }
        _ => RegionTree::Split {
            axis,
            split,
            left: Box::new(left),
            right: Box::new(right),
        },
    }
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

/// Regions (bounds, bricks) of a tree in depth-first, left-first order.
#[cfg(test)]
pub(crate) fn leaves(tree: &RegionTree) -> Vec<(Aabb, &[u32])> {
    let mut out = Vec::new();
    fn walk<'t>(t: &'t RegionTree, out: &mut Vec<(Aabb, &'t [u32])>) {
        match t {
            RegionTree::Empty => {}
            RegionTree::Region { bounds, bricks } => out.push((*bounds, bricks)),
            RegionTree::Split { left, right, .. } => {
                walk(left, out);
                walk(right, out);
            }
        }
    }
    walk(tree, &mut out);
    out
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
            let (bounds, tree) = build(&sup, segment);
            let bounds = bounds.expect("non-empty");
            let regs = leaves(&tree);
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
            // The serialised KD-tree finds the same region as brute force.
            let (packed, flat) = crate::kdtree::flatten(tree.clone()).expect("few regions");
            prop_assert_eq!(flat.len(), regs.len());
            for (x, y, z) in pts {
                let f = [x, y, z];
                let p = [0, 1, 2].map(|a| bounds.min[a] + f[a] * (bounds.max[a] - bounds.min[a]));
                let brute = flat.bounds.iter().position(|b| {
                    (0..3).all(|a| p[a] >= b.min[a] && p[a] < b.max[a])
                });
                prop_assert_eq!(crate::kdtree::locate(&packed, p), brute.map(|r| r as u32));
                let in_support = sup.iter().any(|s| (0..3).all(|a| p[a] >= s.min[a] && p[a] < s.max[a]));
                prop_assert_eq!(brute.is_some(), in_support);
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
        let (_, exact) = build(&sup, 0.0);
        let (bounds, merged) = build(&sup, 0.5);
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
        let (_, t) = build(&[s], 0.5);
        assert_eq!(
            t,
            RegionTree::Region {
                bounds: s,
                bricks: vec![0].into()
            }
        );
    }
}
