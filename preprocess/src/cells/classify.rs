//! Leaf-cell classification: a cell is a leaf cell unless its box is covered by active
//! cells of finer grids.
//!
//! The test per cell is exact for any lattice offsets: the cell box is cut, along each
//! axis, at every finer-cell boundary strictly inside it; inside each piece the membership
//! in every finer grid is constant, so looking up the piece's midpoint is exact. A cell
//! whose centre no finer active cell holds is kept without cutting it (most cells away
//! from finer grids).
//!
//! Everything before the lookups depends on one axis at a time (cuts along x depend only on
//! the cell's x, and so does the finer cell index along x of every midpoint), so it is
//! worked out once per block and axis for the 8 cell coordinates ([`AxisPieces`]) rather
//! than once per cell. That also gives, per block, the box of finer cells any lookup of the
//! block can touch, which settles whole blocks at once: when one finer grid is active over
//! all of that box every cell of the block is covered, and when no finer grid has an active
//! cell where the block's centres fall none is. Only blocks on the edge of a finer grid
//! are tested cell by cell, with the same lookups as always, so the result is the same.

use rayon::prelude::*;

use super::{bit, BlockMasks, CellSet, BLOCK_CELLS};

/// Marks as non-leaf every active cell whose box is fully covered by active cells of
/// grids with a smaller cell width. Runs in parallel over blocks; the result does not
/// depend on the thread count.
pub(crate) fn classify_leaves(sets: &mut [CellSet]) {
    let leaves: Vec<BlockMasks> = (0..sets.len())
        .map(|s| {
            let me = &sets[s];
            let finer: Vec<&CellSet> = sets
                .iter()
                .filter(|o| o.width < me.width * (1.0 - 1e-9))
                .collect();
            if finer.is_empty() {
                return me.active.clone();
            }
            // A chunk of blocks at a time, so that only a chunk's masks are ever held at
            // 64 bytes a block.
            let mut leaf = me.active.clone();
            let n = me.blocks.len();
            for first in (0..n).step_by(CLASSIFY_CHUNK) {
                let chunk: Vec<[u64; 8]> = (first..(first + CLASSIFY_CHUNK).min(n))
                    .into_par_iter()
                    .map(|b| block_leaves(me, b, &finer))
                    .collect();
                for (b, m) in (first..).zip(chunk) {
                    leaf.set(b, m);
                }
            }
            leaf
        })
        .collect();
    for (set, leaf) in sets.iter_mut().zip(leaves) {
        set.leaf = leaf;
    }
}

/// Blocks classified at once (4 MiB of their masks).
const CLASSIFY_CHUNK: usize = 1 << 16;

/// Largest box of finer cells (in 8³ blocks) that the whole-block tests look at; beyond it
/// (a finer grid hundreds of times finer) the block is tested cell by cell.
const MAX_BOX_BLOCKS: i64 = 4096;

/// Leaf mask of block `b` of `me` (see the module docs).
fn block_leaves(me: &CellSet, b: usize, finer: &[&CellSet]) -> [u64; 8] {
    let mask = *me.active.get(b);
    if mask == [0; 8] {
        return mask;
    }
    let origin = me.blocks[b];
    let axes: [AxisPieces; 3] = [0, 1, 2].map(|a| AxisPieces::new(me, origin[a], a, finer));
    let ng = finer.len();
    // Whole block covered by one finer grid?
    for (gi, g) in finer.iter().enumerate() {
        let span = |a: usize| axes[a].range(gi, true);
        if let (Some(x), Some(y), Some(z)) = (span(0), span(1), span(2)) {
            if axes.iter().all(|ax| !ax.any_too_fine())
                && g.all_active_in([x.0, y.0, z.0], [x.1, y.1, z.1], MAX_BOX_BLOCKS) == Some(true)
            {
                return [0; 8];
            }
        }
    }
    // No finer grid active where the block's centres fall: every cell stays a leaf.
    let centres_clear = finer.iter().enumerate().all(|(gi, g)| {
        let span = |a: usize| axes[a].range(gi, false);
        match (span(0), span(1), span(2)) {
            (Some(x), Some(y), Some(z)) => {
                g.any_active_in([x.0, y.0, z.0], [x.1, y.1, z.1], MAX_BOX_BLOCKS) == Some(false)
            }
            // Some axis has no centre inside g's index range: no centre is in g.
            _ => true,
        }
    });
    if centres_clear {
        return mask;
    }
    let mut leaf = mask;
    for n in 0..BLOCK_CELLS {
        if !bit(&mask, n) {
            continue;
        }
        let local = [n >> 6, (n >> 3) & 7, n & 7];
        let [ax, ay, az] = [0, 1, 2].map(|a| &axes[a].coords[local[a]]);
        let centre_in_finer = finer
            .iter()
            .enumerate()
            .any(|(gi, g)| active_at(g, [ax.centre[gi], ay.centre[gi], az.centre[gi]]));
        if !centre_in_finer || ax.too_fine || ay.too_fine || az.too_fine {
            continue;
        }
        let covered = (0..az.pieces()).all(|iz| {
            (0..ay.pieces()).all(|iy| {
                (0..ax.pieces()).all(|ix| {
                    (0..ng).any(|gi| {
                        active_at(
                            finer[gi],
                            [ax.piece(ix, gi), ay.piece(iy, gi), az.piece(iz, gi)],
                        )
                    })
                })
            })
        });
        if covered {
            leaf[n >> 6] &= !(1u64 << (n & 63));
        }
    }
    leaf
}

/// Whether `g` has an active cell at the index (None: outside `i32`, so not in `g`).
#[inline]
fn active_at(g: &CellSet, k: [Option<i32>; 3]) -> bool {
    match k {
        [Some(x), Some(y), Some(z)] => g.active_slot([x, y, z]).is_some(),
        _ => false,
    }
}

/// Along one axis, for each of a block's 8 cell coordinates: the finer-grid index of the
/// cell centre and of every piece midpoint (see the module docs).
struct AxisPieces {
    coords: [AxisCell; 8],
}

/// One cell coordinate along one axis.
#[derive(Default)]
struct AxisCell {
    /// Some finer grid has more than 4096 cells across this cell: the cell is kept (always
    /// correct, only less compact).
    too_fine: bool,
    /// Index along this axis of the cell centre in each finer grid.
    centre: Vec<Option<i32>>,
    /// Index along this axis of each piece midpoint in each finer grid, piece after piece.
    midpoints: Vec<Option<i32>>,
    ng: usize,
}

impl AxisCell {
    fn pieces(&self) -> usize {
        self.midpoints.len() / self.ng
    }

    fn piece(&self, i: usize, g: usize) -> Option<i32> {
        self.midpoints[i * self.ng + g]
    }
}

impl AxisPieces {
    fn new(me: &CellSet, block_origin: i32, a: usize, finer: &[&CellSet]) -> AxisPieces {
        let mut cuts: Vec<f64> = Vec::new();
        let coords = std::array::from_fn(|l| {
            let ijk = block_origin + l as i32;
            // As `CellSet::centre` and the cell box `centre ± width / 2`.
            let c = me.transform.voxel_size[a] * ijk as f64 + me.transform.translation[a];
            let h = 0.5 * me.width;
            let (lo, hi) = (c - h, c + h);
            let mut cell = AxisCell {
                centre: finer.iter().map(|g| axis_cell(g, a, c)).collect(),
                ng: finer.len(),
                ..AxisCell::default()
            };
            if !axis_cuts(lo, hi, a, finer, &mut cuts) {
                cell.too_fine = true;
                return cell;
            }
            for w in cuts.windows(2) {
                let m = 0.5 * (w[0] + w[1]);
                cell.midpoints
                    .extend(finer.iter().map(|g| axis_cell(g, a, m)));
            }
            cell
        });
        AxisPieces { coords }
    }

    fn any_too_fine(&self) -> bool {
        self.coords.iter().any(|c| c.too_fine)
    }

    /// Lowest and highest index in finer grid `g` over the block's 8 coordinates: of the
    /// centres and, with `pieces`, of the midpoints too. None when some index is outside
    /// `i32` (with `pieces`) or no centre is inside it (without).
    fn range(&self, g: usize, pieces: bool) -> Option<(i32, i32)> {
        let mut out: Option<(i32, i32)> = None;
        for c in &self.coords {
            let mids = c.midpoints.iter().skip(g).step_by(c.ng);
            let all = std::iter::once(&c.centre[g]).chain(mids.filter(|_| pieces));
            for k in all {
                match k {
                    Some(k) => {
                        let (lo, hi) = out.get_or_insert((*k, *k));
                        *lo = (*lo).min(*k);
                        *hi = (*hi).max(*k);
                    }
                    None if pieces => return None,
                    None => {}
                }
            }
        }
        out
    }
}

/// Cuts of the cell `[lo, hi]` along axis `a`: its ends and every boundary of a finer cell
/// strictly inside (closer ones than a 1e-7 fraction of the cell merged), sorted. False
/// when some finer grid is more than 4096 cells across the cell.
fn axis_cuts(lo: f64, hi: f64, a: usize, finer: &[&CellSet], c: &mut Vec<f64>) -> bool {
    let tol = 1e-7 * (hi - lo);
    c.clear();
    c.push(lo);
    for g in finer {
        let w = g.width;
        let t = g.transform.translation[a];
        // Boundaries of g's cells: t + (k - 0.5) w.
        let k0 = ((lo - t) / w + 0.5).floor() as i64;
        let k1 = ((hi - t) / w + 0.5).ceil() as i64;
        if k1 - k0 > 1 << 12 {
            return false;
        }
        for k in k0..=k1 {
            let x = t + (k as f64 - 0.5) * w;
            if x > lo + tol && x < hi - tol {
                c.push(x);
            }
        }
    }
    c.push(hi);
    c.sort_by(f64::total_cmp);
    c.dedup_by(|x, y| (*x - *y).abs() <= tol);
    true
}

/// Index along axis `a` of the cell of `g` containing coordinate `x` (None outside `i32`),
/// as [`CellSet::cell_at`] computes it.
#[inline]
fn axis_cell(g: &CellSet, a: usize, x: f64) -> Option<i32> {
    let f = round_half_away((x - g.transform.translation[a]) / g.width);
    (f >= i32::MIN as f64 && f <= i32::MAX as f64).then_some(f as i32)
}

/// `x.round()` (halves away from zero) without the library call that `f64::round` is on
/// the baseline x86-64 target: classification calls it for every cell and every finer
/// grid. Exact for `|x| < 2^52` (beyond that every `f64` is an integer already).
#[inline]
pub(super) fn round_half_away(x: f64) -> f64 {
    const BIG: f64 = 4_503_599_627_370_496.0; // 2^52
    let a = x.abs();
    if a.is_nan() || a >= BIG {
        return x;
    }
    let t = a as i64 as f64; // trunc(|x|), exact here
    let r = if a - t >= 0.5 { t + 1.0 } else { t };
    r.copysign(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::tests::grid;
    use crate::grid::Transform;
    use proptest::prelude::*;

    /// The cell-by-cell classification that [`classify_leaves`] must reproduce: every
    /// active cell whose centre is in some finer active cell is cut into pieces, each
    /// looked up in every finer grid, with no per-axis or per-block sharing.
    fn classify_reference(sets: &[CellSet]) -> Vec<Vec<[u64; 8]>> {
        let cell_at = |g: &CellSet, p: [f64; 3]| -> Option<[i32; 3]> {
            Some([
                axis_cell(g, 0, p[0])?,
                axis_cell(g, 1, p[1])?,
                axis_cell(g, 2, p[2])?,
            ])
        };
        let in_finer = |finer: &[&CellSet], p: [f64; 3]| {
            finer
                .iter()
                .any(|g| cell_at(g, p).and_then(|q| g.active_slot(q)).is_some())
        };
        sets.iter()
            .map(|me| {
                let finer: Vec<&CellSet> = sets
                    .iter()
                    .filter(|o| o.width < me.width * (1.0 - 1e-9))
                    .collect();
                let mut leaf = me.active.to_vec();
                for slot in me.active_slots() {
                    let c = me.centre(me.ijk(slot));
                    if finer.is_empty() || !in_finer(&finer, c) {
                        continue;
                    }
                    let h = 0.5 * me.width;
                    let mut cuts: [Vec<f64>; 3] = Default::default();
                    let fits =
                        (0..3).all(|a| axis_cuts(c[a] - h, c[a] + h, a, &finer, &mut cuts[a]));
                    if !fits {
                        continue;
                    }
                    let mid = |c: &Vec<f64>, i: usize| 0.5 * (c[i] + c[i + 1]);
                    let covered = (0..cuts[2].len() - 1).all(|iz| {
                        (0..cuts[1].len() - 1).all(|iy| {
                            (0..cuts[0].len() - 1).all(|ix| {
                                let p = [mid(&cuts[0], ix), mid(&cuts[1], iy), mid(&cuts[2], iz)];
                                in_finer(&finer, p)
                            })
                        })
                    });
                    if covered {
                        let (b, n) = (slot / BLOCK_CELLS, slot % BLOCK_CELLS);
                        leaf[b][n >> 6] &= !(1u64 << (n & 63));
                    }
                }
                leaf
            })
            .collect()
    }

    /// One grid of a random layout: width `2^level`, a lattice offset, a box of cells, and
    /// every `holes`-th cell of the box left out (0: none).
    fn grid_strategy() -> impl Strategy<Value = (u32, f64, [i32; 3], [i32; 3], u32)> {
        (
            0u32..3,
            prop::sample::select(vec![0.0, 0.5, 0.25, 0.3, -0.5]),
            prop::array::uniform3(-24i32..4),
            prop::array::uniform3(4i32..40),
            prop::sample::select(vec![0u32, 0, 7, 61]),
        )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        #[test]
        fn matches_cell_by_cell_reference(specs in prop::collection::vec(grid_strategy(), 1..4)) {
            let mut sets = Vec::new();
            for (i, (level, offset, lo, size, holes)) in specs.into_iter().enumerate() {
                let w = f64::from(1u32 << level);
                // Boxes in world units about the same place whatever the width.
                let lo = lo.map(|c| c * 2 / (1 << level));
                let hi = [0, 1, 2].map(|a| lo[a] + (size[a] * 2 / (1 << level)).max(1));
                let mut cells = Vec::new();
                for z in lo[2]..hi[2] {
                    for y in lo[1]..hi[1] {
                        for x in lo[0]..hi[0] {
                            let hash = (x * 73 + y * 151 + z * 37).unsigned_abs();
                            if holes == 0 || hash % holes != 0 {
                                cells.push([x, y, z]);
                            }
                        }
                    }
                }
                let mut g = grid(&format!("g{i}"), w, 0.0, &cells);
                g.transform = Transform { voxel_size: [w; 3], translation: [offset * w; 3] };
                sets.push(CellSet::from_grid(g, level, |v| v).expect("small").0);
            }
            let expect = classify_reference(&sets);
            classify_leaves(&mut sets);
            for (s, e) in sets.iter().zip(&expect) {
                prop_assert_eq!(&s.leaf.to_vec(), e);
            }
        }
    }

    #[test]
    fn round_half_away_matches_round() {
        let cases = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.49999999999999994,
            1e15 + 0.5,
            -1e15 - 0.5,
            4.5e15,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            3.2,
            -3.7,
        ];
        for x in cases {
            assert_eq!(round_half_away(x).to_bits(), x.round().to_bits(), "{x}");
        }
        assert!(round_half_away(f64::NAN).is_nan());
        let mut v = 0.123_f64;
        for _ in 0..10_000 {
            v = (v * 7.3 + 0.37).rem_euclid(200.0) - 100.0;
            assert_eq!(round_half_away(v), v.round(), "{v}");
            let h = v.trunc() + 0.5 * v.signum();
            assert_eq!(round_half_away(h), h.round(), "{h}");
        }
    }

    #[test]
    fn coverage_aligned_and_offset() {
        // Coarse cell 0 (width 2, centre 0) spans [-1, 1]; fine cells width 1 centred at
        // -0.5 and 0.5 (translation 0.5 - 1 = -0.5) cover it exactly.
        let mut fine_cells = vec![];
        for z in -1..1 {
            for y in -1..1 {
                for x in -1..1 {
                    fine_cells.push([x, y, z]);
                }
            }
        }
        let fine = grid("fine", 1.0, 0.5, &fine_cells);
        let coarse = grid("coarse", 2.0, 0.0, &[[0, 0, 0], [1, 0, 0]]);
        let (f, _) = CellSet::from_grid(fine.clone(), 0, |v| v).expect("small");
        let (c, _) = CellSet::from_grid(coarse.clone(), 1, |v| v).expect("small");
        let mut sets = vec![f, c];
        classify_leaves(&mut sets);
        assert_eq!(sets[1].leaf_count(), 1, "cell 0 covered, cell 1 kept");
        assert!(sets[1].leaf_slot([1, 0, 0]).is_some());
        assert_eq!(sets[0].leaf_count(), 8);

        // Fine lattice shifted by half a fine cell: coarse cell only partially covered.
        let fine2 = grid("fine", 1.0, 0.0, &fine_cells);
        let (f2, _) = CellSet::from_grid(fine2.clone(), 0, |v| v).expect("small");
        let (c2, _) = CellSet::from_grid(coarse.clone(), 1, |v| v).expect("small");
        let mut sets = vec![f2, c2];
        classify_leaves(&mut sets);
        assert_eq!(sets[1].leaf_count(), 2);
    }

    /// A coarse grid's blocks are wholly active, and under a finer grid wholly covered or
    /// not at all except along its edge: only the blocks the edge cuts hold a mask pattern
    /// of their own (64 bytes; the others 4).
    #[test]
    fn only_blocks_partly_set_hold_a_mask_pattern() {
        let cube = |lo: i32, hi: i32| -> Vec<[i32; 3]> {
            (lo..hi)
                .flat_map(|z| (lo..hi).flat_map(move |y| (lo..hi).map(move |x| [x, y, z])))
                .collect()
        };
        // Coarse cell i (width 2) spans [2i - 1, 2i + 1]; fine cell j (width 1, centre
        // j + 0.5) spans [j, j + 1].
        let coarse = grid("coarse", 2.0, 0.0, &cube(0, 32));
        for (fine_cells, covered, own) in [
            // Coarse cells 8..16 ([15, 31]): one whole block covered, none cut.
            (cube(15, 31), 512, 0),
            // Coarse cells 4..12 ([7, 23]): the eight blocks about (8, 8, 8) cut.
            (cube(7, 23), 512, 8),
        ] {
            let (f, _) =
                CellSet::from_grid(grid("fine", 1.0, 0.5, &fine_cells), 0, |v| v).expect("small");
            let (c, _) = CellSet::from_grid(coarse.clone(), 1, |v| v).expect("small");
            let mut sets = vec![f, c];
            classify_leaves(&mut sets);
            let c = &sets[1];
            assert_eq!(c.active_count(), 32 * 32 * 32);
            assert_eq!(
                c.active.own_patterns(),
                0,
                "every coarse block is wholly active"
            );
            assert_eq!(c.leaf_count(), 32 * 32 * 32 - covered);
            assert_eq!(c.leaf.own_patterns(), own);
            assert_eq!(sets[0].leaf.own_patterns(), sets[0].active.own_patterns());
        }
    }
}
