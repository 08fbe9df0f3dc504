//! `exact`: iso search without samples. Between two consecutive lattice planes (of every
//! cell lattice present in the region) `Σ H (v − iso)` along the ray is a cubic, so each
//! such interval whose cells straddle the iso value is solved for its first root.

use super::roots::first_root;
use super::Gaps;
use super::{Event, Tracer};
use crate::active::{range_holds, LeafSearch};
use crate::lattice::{Lattice, Lattices, MAX_LATTICES};
use crate::traverse::{segments_skipping, Segment, Skip, SKIPPED};
use crate::volume::RegionBox;

impl Tracer<'_> {
    /// Exact iso search: per region whose range holds the iso value (the view's
    /// [`ActiveTree`](crate::active) for it; everything else is stepped over), per
    /// interval between lattice planes of every level present (inside which
    /// `Σ H (v − iso)` is a cubic), skip when all contributing cells lie on one side, else
    /// take the cubic's first root.
    pub(super) fn iso_exact(
        &mut self,
        o: [f64; 3],
        d: [f64; 3],
        t0: f64,
        t1: f64,
    ) -> Option<(f64, Option<RegionBox>)> {
        let vol = self.vol;
        let (field, iso) = (self.params.field, self.params.tf.iso);
        let (tree, start) = self.active_walk();
        let mut found = None;
        let mut stack = std::mem::take(&mut self.stack);
        match tree {
            Some(tree) => {
                let mut gaps = Gaps::new(vol, &o, &d, t0, t1);
                let share = self.owned.zip(self.owned_nodes).map(|(r, n)| (n, r));
                tree.segments(vol, start, o, d, t0, t1, share, &mut stack, |seg, leaf| {
                    gaps.before(self, &seg);
                    self.enter_segment(&seg, false);
                    found = self.exact_in_segment(&seg, &o, &d, iso, leaf);
                    found.is_none()
                });
                if found.is_none() {
                    gaps.finish(self);
                }
            }
            None => {
                let skip = Skip {
                    field,
                    keep: |a: f32, b: f32| range_holds(a, b, iso),
                    across_gaps: true,
                };
                let packed = self.packed();
                segments_skipping(vol, packed, o, d, t0, t1, &mut stack, &skip, |seg| {
                    let skipped = seg.region == SKIPPED || !range_holds(seg.min, seg.max, iso);
                    self.enter_segment(&seg, skipped);
                    if skipped {
                        return true;
                    }
                    let l = Lattices::of(vol, seg.region as usize);
                    let leaf = LeafSearch {
                        lattices: l.as_slice(),
                        inexact: l.inexact,
                        mask: None,
                        region_box: None,
                    };
                    found = self.exact_in_segment(&seg, &o, &d, iso, &leaf);
                    found.is_none()
                });
            }
        }
        self.stack = stack;
        found
    }

    /// What [`Tracer::iso`] does along a ray whose walk starts nowhere: counts the
    /// ray's stretch through the data (within the active box) as stepped over.
    pub(crate) fn step_over_all(&mut self, o: [f64; 3], d: [f64; 3], t0: f64, t1: f64) {
        if let Some((t0, t1)) = self.clip(&o, &d, t0, t1) {
            Gaps::new(self.vol, &o, &d, t0, t1).finish(self);
        }
    }

    /// [`Tracer::step_over_all`] of a ray known to cross the data within the active box:
    /// its one stretch, counted without a log (the bounds would only be logged, and
    /// callers trace no `--pixel`).
    pub(crate) fn step_over_data(&mut self) {
        debug_assert!(self.log.is_none());
        self.enter_gap(f64::NAN, f64::NAN);
    }

    /// The first root in one region segment whose range holds the iso value, searched
    /// as `leaf` says (the region's lattices, its dual-cell mask when it has one, see
    /// [`crate::dual_mask`]); the hit's region is the segment's, with the leaf's box.
    fn exact_in_segment(
        &mut self,
        seg: &Segment,
        o: &[f64; 3],
        d: &[f64; 3],
        iso: f64,
        leaf: &LeafSearch,
    ) -> Option<(f64, Option<RegionBox>)> {
        let LeafSearch {
            lattices,
            inexact,
            mask,
            ..
        } = *leaf;
        if !self.owns(seg.region) {
            // Another rank's: its first root there is that rank's candidate.
            return None;
        }
        let vol = self.vol;
        let field = self.params.field;
        let r = seg.region as usize;
        let mut planes = Planes::new(lattices, o, d, seg.t0);
        // The region's bricks are converted when the first interval needs its corners, and
        // kept for the next segment of the same region (the parts of a region the active
        // tree lists are segments of their own).
        let mut bricks = std::mem::take(&mut self.bricks);
        if self.bricks_of != Some(seg.region) {
            bricks.clear();
        }
        if inexact {
            self.stats.inexact_segments += 1;
        }
        let mut ta = seg.t0;
        let mut found = None;
        while ta < seg.t1 {
            let tb = planes.next(ta).min(seg.t1);
            if tb <= ta {
                break;
            }
            // What the mask says of the interval's midpoint (as `cubic_in` takes it).
            let known = mask.and_then(|m| {
                let tm = 0.5 * (ta + tb);
                m.may_cross(&std::array::from_fn(|a| o[a] + tm * d[a]))
            });
            if known == Some(false) {
                self.record(Event::Interval {
                    t0: ta,
                    t1: tb,
                    may_cross: false,
                });
                ta = tb;
                continue;
            }
            if bricks.is_empty() {
                vol.dual_bricks(r, &mut bricks);
                self.bricks_of = Some(seg.region);
                self.touch(seg.region);
            }
            let cubic = vol.cubic_in(&bricks, o, d, ta, tb, field, iso, known == Some(true));
            self.stats.samples += 1;
            let may_cross = cubic.any_above && cubic.any_below;
            self.record(Event::Interval {
                t0: ta,
                t1: tb,
                may_cross,
            });
            if may_cross {
                if let Some(x) = first_root(&cubic) {
                    found = Some((ta + x * (tb - ta), Some(leaf.hit(seg.region))));
                    break;
                }
            }
            ta = tb;
        }
        self.bricks = bricks;
        found
    }
}

/// Walks the lattice planes (cell-centre planes) of every lattice present in a region.
struct Planes {
    /// Next plane crossing per (lattice, axis) and the spacing in t.
    next: [f64; 3 * MAX_LATTICES],
    step: [f64; 3 * MAX_LATTICES],
    n: usize,
}

impl Planes {
    fn new(lattices: &[Lattice], o: &[f64; 3], d: &[f64; 3], t: f64) -> Planes {
        let mut pl = Planes {
            next: [f64::INFINITY; 3 * MAX_LATTICES],
            step: [f64::INFINITY; 3 * MAX_LATTICES],
            n: 0,
        };
        for &(w, inv_w, origin) in lattices.iter().take(MAX_LATTICES) {
            for a in 0..3 {
                if d[a] == 0.0 {
                    continue;
                }
                let x = o[a] + t * d[a];
                let u = (x - origin[a]) * inv_w;
                let kplane = if d[a] > 0.0 {
                    u.floor() + 1.0
                } else {
                    u.ceil() - 1.0
                };
                let tp = (origin[a] + kplane * w - o[a]) / d[a];
                pl.next[pl.n] = tp;
                pl.step[pl.n] = w / d[a].abs();
                pl.n += 1;
            }
        }
        pl
    }

    /// The next plane crossing after `t`.
    fn next(&mut self, t: f64) -> f64 {
        let mut best = f64::INFINITY;
        for i in 0..self.n {
            // Round-off can leave a plane at or just before t: step past it.
            while self.next[i] <= t + 1e-12 * self.step[i] {
                let n = self.next[i] + self.step[i];
                if n <= self.next[i] || n.is_nan() {
                    // The spacing is below the resolution of t here: stop cutting.
                    self.next[i] = f64::INFINITY;
                    break;
                }
                self.next[i] = n;
            }
            best = best.min(self.next[i]);
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reconstruct::Cubic;
    use crate::traverse::{inverse, ray_box};
    use crate::volume::Volume;

    /// Deterministic numbers in `[0, 1)`.
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    fn bits(c: &Cubic) -> ([u64; 4], [u64; 4], bool, bool) {
        (
            c.c.map(f64::to_bits),
            c.weight.map(f64::to_bits),
            c.any_above,
            c.any_below,
        )
    }

    /// `cubic_in` (bricks converted once per segment, eight fixed corner offsets inside a
    /// brick) gives the straightforward `cubic`'s numbers bit for bit: on every interval
    /// `exact` cuts along random rays, rays along cell faces and level boundaries
    /// (axis-parallel, on whole and half coordinates) and rays grazing the data's outer
    /// faces, and on intervals cut anywhere (across lattice planes, so with corners on
    /// brick edges and outside the data). The field is per-cell noise in [0, 1],
    /// so a corner read from the wrong cell changes the dual-cell test, and bricks of at
    /// most 3 cells per axis put many corners on brick edges.
    /// Per-cell noise in [0, 1] (so a corner read from the wrong cell changes the dual-cell
    /// test) on two nested levels at an offset, in bricks of at most 3 cells per axis (many
    /// corners on brick edges).
    fn noise_file() -> format::BrickFile {
        let noise = |p: [f64; 3]| {
            let k = p.map(|x| (2.0 * x).floor() as i64);
            let mut h = (k[0] * 73_856_093) ^ (k[1] * 19_349_663) ^ (k[2] * 83_492_791);
            h = h.wrapping_mul(0x2545_f491_4f6c_dd1d_u64 as i64);
            ((h >> 40) & 0xff) as f64 / 255.0
        };
        crate::testvol::nested(8, [0.5, -3.0, 2.0], &[("n", &noise)], 3)
    }

    /// Random rays, rays along cell faces and level boundaries (axis-parallel, on whole and
    /// half coordinates) and rays grazing the data's outer faces of [`noise_file`].
    fn noise_rays(vol: &Volume) -> Vec<([f64; 3], [f64; 3])> {
        let mut seed = 11;
        let mut rays = Vec::new();
        let c = vol.to_local([8.5, 5.0, 10.0]);
        for _ in 0..300 {
            let o: [f64; 3] = std::array::from_fn(|a| c[a] + 30.0 * (lcg(&mut seed) - 0.5));
            let d: [f64; 3] = std::array::from_fn(|_| lcg(&mut seed) - 0.5);
            rays.push((o, d));
        }
        let lo = vol.to_local([0.5, -3.0, 2.0]);
        for a in 0..3 {
            for k in 0..=32 {
                // Whole and half coordinates: cell faces and centres of both levels, the
                // fine grid's boundary (4, 12) and the data's faces (0, 16).
                let mut o = lo;
                o[(a + 1) % 3] += 0.5 * k as f64;
                o[(a + 2) % 3] += [0.0, 4.0, 12.0, 16.0, 5.5][k % 5];
                o[a] -= 3.0;
                let mut d = [0.0; 3];
                d[a] = 1.0;
                rays.push((o, d));
                let mut d2 = d;
                d2[(a + 1) % 3] = 0.25;
                rays.push((o, d2));
            }
        }
        rays
    }

    /// `cubic_in` (bricks converted once per segment, eight fixed corner offsets inside a
    /// brick) gives the straightforward `cubic`'s numbers bit for bit: on every interval
    /// `exact` cuts along [`noise_rays`] through [`noise_file`], and on intervals cut
    /// anywhere (across lattice planes, so with corners on brick edges and outside the
    /// data).
    #[test]
    fn cubic_in_matches_the_straightforward_cubic_bit_for_bit() {
        let file = noise_file();
        let view = crate::testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let rays = noise_rays(&vol);
        let mut seed = 12;
        let mut bricks = Vec::new();
        let (mut intervals, mut straddling) = (0, 0);
        for (o, d) in rays {
            for r in 0..vol.region_count() {
                let reg = vol.region(r);
                let Some((t0, t1)) = ray_box(&reg.min, &reg.max, &o, &inverse(&d), -1e3, 1e3)
                else {
                    continue;
                };
                vol.dual_bricks(r, &mut bricks);
                let l = Lattices::of(&vol, r);
                let mut planes = Planes::new(l.as_slice(), &o, &d, t0);
                let mut ta = t0;
                while ta < t1 {
                    let tb = planes.next(ta).min(t1);
                    if tb <= ta {
                        break;
                    }
                    // The interval `exact` cuts, and one cut at a random place (with a second
                    // iso value, above most of the noise: mostly one-sided intervals).
                    let tr = ta + (t1 - ta) * lcg(&mut seed);
                    for ((x, y), iso) in [(ta, tb), (ta, tr)].into_iter().zip([0.5, 0.9]) {
                        let want = vol.cubic(r, &o, &d, x, y, 0, iso);
                        let got = vol.cubic_in(&bricks, &o, &d, x, y, 0, iso, false);
                        assert_eq!(
                            bits(&got),
                            bits(&want),
                            "region {r}, ray {o:?} + t {d:?}, [{x}, {y}], iso {iso}"
                        );
                        // Told that the cells straddle (as a mask tells it), the same.
                        if want.any_above && want.any_below {
                            let told = vol.cubic_in(&bricks, &o, &d, x, y, 0, iso, true);
                            assert_eq!(bits(&told), bits(&want), "told: region {r}, [{x}, {y}]");
                        }
                        intervals += 1;
                        straddling += usize::from(want.any_above && want.any_below);
                    }
                    ta = tb;
                }
            }
        }
        assert!(
            intervals > 10_000 && straddling > 2_000 && intervals - straddling > 2_000,
            "{intervals} intervals, {straddling} straddling"
        );
    }

    /// A region's dual-cell mask answers every interval `exact` cuts along
    /// [`noise_rays`] as the straightforward corner test does (`cubic`'s `any_above &&
    /// any_below`), or not at all where the midpoint is within round-off of a lattice
    /// plane, at an iso value that splits the noise and one above most of it. Most
    /// intervals get an answer, of both kinds.
    #[test]
    fn dual_masks_answer_as_the_corner_test() {
        let file = noise_file();
        let view = crate::testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let rays = noise_rays(&vol);
        let mut bricks = Vec::new();
        let (mut answered, mut crossing, mut unsure, mut masked_regions) = (0, 0, 0, 0);
        for iso in [0.5, 0.9] {
            for r in 0..vol.region_count() {
                let l = Lattices::of(&vol, r);
                let [lattice] = l.as_slice() else {
                    continue;
                };
                let reg = vol.region(r);
                vol.dual_bricks(r, &mut bricks);
                let mask = crate::dual_mask::DualMask::build(
                    &vol, &bricks, lattice, &reg.min, &reg.max, 0, iso,
                )
                .expect("a small region has a mask");
                masked_regions += 1;
                for &(o, d) in &rays {
                    let Some((t0, t1)) = ray_box(&reg.min, &reg.max, &o, &inverse(&d), -1e3, 1e3)
                    else {
                        continue;
                    };
                    let mut planes = Planes::new(l.as_slice(), &o, &d, t0);
                    let mut ta = t0;
                    while ta < t1 {
                        let tb = planes.next(ta).min(t1);
                        if tb <= ta {
                            break;
                        }
                        let tm = 0.5 * (ta + tb);
                        let pm: [f64; 3] = std::array::from_fn(|a| o[a] + tm * d[a]);
                        let want = vol.cubic(r, &o, &d, ta, tb, 0, iso);
                        match mask.may_cross(&pm) {
                            Some(got) => {
                                assert_eq!(
                                    got,
                                    want.any_above && want.any_below,
                                    "region {r}, ray {o:?} + t {d:?}, [{ta}, {tb}], iso {iso}"
                                );
                                answered += 1;
                                crossing += usize::from(got);
                            }
                            None => unsure += 1,
                        }
                        ta = tb;
                    }
                }
            }
        }
        assert!(masked_regions > 100, "{masked_regions} regions with a mask");
        assert!(
            answered > 5_000 && crossing > 1_000 && answered - crossing > 2_000 && unsure > 100,
            "{answered} answered ({crossing} may cross), {unsure} unsure"
        );
    }

    /// Exact hits of the ray `o + t d` (local frame) at `iso` with the regions of `tree`.
    fn hit_with(
        vol: &Volume,
        tree: &std::sync::Arc<crate::active::ActiveTree>,
        iso: f64,
        o: [f64; 3],
        d: [f64; 3],
    ) -> Option<(f64, Option<RegionBox>)> {
        let params = crate::testvol::params(
            vol,
            super::super::Strategy::Exact,
            0.5,
            crate::transfer::Mode::Iso,
            iso,
        );
        let accel = crate::accel::Accel::with_active(params.accel_key(), tree.clone());
        let mut tracer = Tracer::new(vol, &accel, params);
        tracer.iso_exact(o, d, -1e3, 1e3)
    }

    /// Cutting regions into the parts where their dual cells can hold the iso value
    /// (`DualMask::sub_boxes`, what `exact` walks) changes which stretches of a ray are
    /// searched, never what is found: every ray hits in the same region at the same `t`
    /// (to round-off: a part's segment starts where the ray enters its box, not at the
    /// lattice plane computed along the ray) as with every region whole, or misses with
    /// both. On [`noise_rays`] through [`noise_file`] (small regions, level boundaries)
    /// and through smooth shells in bricks of up to 24 cells, whose regions are cut into
    /// several parts.
    #[test]
    fn cut_regions_find_the_hits_of_whole_regions() {
        let shell = |p: [f64; 3]| {
            let r2: f64 = (0..3).map(|a| (p[a] - 16.3).powi(2)).sum();
            (r2.sqrt() * 0.7).sin()
        };
        let files = [
            (noise_file(), vec![0.5, 0.9]),
            (
                crate::testvol::nested(16, [0.0; 3], &[("s", &shell)], 24),
                vec![0.0, 0.6],
            ),
        ];
        let (mut hits, mut cut_regions) = (0, 0);
        for (file, isos) in files {
            let view = crate::testvol::open(&file).expect("opens");
            let vol = Volume::new(&view).expect("volume");
            let mut rays = noise_rays(&vol);
            let mut seed = 5;
            let c = vol.to_local([16.0; 3]);
            for _ in 0..1500 {
                let o: [f64; 3] = std::array::from_fn(|a| c[a] + 40.0 * (lcg(&mut seed) - 0.5));
                let d: [f64; 3] = std::array::from_fn(|_| lcg(&mut seed) - 0.5);
                rays.push((o, d));
            }
            for iso in isos {
                let cut = std::sync::Arc::new(
                    crate::active::ActiveTree::of(&vol, 0, iso).expect("a tree"),
                );
                let whole = std::sync::Arc::new(
                    crate::active::ActiveTree::uncut(&vol, 0, iso).expect("a tree"),
                );
                let ((cut_leaves, cut_regs), (_, whole_regs)) =
                    (cut.leaf_count(), whole.leaf_count());
                assert!(cut_regs <= whole_regs);
                cut_regions += cut_leaves - cut_regs;
                // Masks for the first regions only (the work bound of a huge file): the
                // others are searched whole, with their corners read.
                let (_, all) = crate::active::ActiveTree::with_mask_work(&vol, 0, iso, usize::MAX)
                    .expect("a tree");
                let (part, some) =
                    crate::active::ActiveTree::with_mask_work(&vol, 0, iso, 2000).expect("a tree");
                assert!(some > 0 && some < all, "{some} of {all} regions masked");
                let part = std::sync::Arc::new(part);
                for &(o, d) in &rays {
                    let want = hit_with(&vol, &whole, iso, o, d);
                    let got = hit_with(&vol, &cut, iso, o, d);
                    let partly = hit_with(&vol, &part, iso, o, d);
                    assert_eq!(
                        got.map(|h| h.1),
                        partly.map(|h| h.1),
                        "iso {iso}, ray {o:?} + t {d:?}"
                    );
                    match (want, got) {
                        (None, None) => {}
                        (Some((tw, rw)), Some((tg, rg))) => {
                            assert!(
                                (tw - tg).abs() <= 1e-9 * (1.0 + tw.abs()) && rw == rg,
                                "iso {iso}, ray {o:?} + t {d:?}: {want:?} whole, {got:?} cut"
                            );
                            hits += 1;
                        }
                        _ => panic!("iso {iso}, ray {o:?} + t {d:?}: {want:?} whole, {got:?} cut"),
                    }
                }
            }
        }
        assert!(hits > 2_000, "only {hits} hits");
        assert!(
            cut_regions > 20,
            "only {cut_regions} parts beyond one per region"
        );
    }

    /// The sampled strategies walk the same parts as `exact` in iso mode and treat the
    /// stretches between them as gaps (an exit and an entry sample): at a fine step they
    /// find `exact`'s surface on the same rays, at the same place to a fraction of the
    /// step, through smooth shells in regions cut into several parts and through noise
    /// (level boundaries, small regions). A few grazing rays may differ, where the surface
    /// dips into a ray by less than a step.
    #[test]
    fn sampled_strategies_on_the_parts_find_the_exact_surface() {
        use super::super::Strategy;
        use crate::transfer::Mode;
        let shell = |p: [f64; 3]| {
            let r2: f64 = (0..3).map(|a| (p[a] - 16.3).powi(2)).sum();
            (r2.sqrt() * 0.7).sin()
        };
        let files = [
            (
                crate::testvol::nested(16, [0.0; 3], &[("s", &shell)], 24),
                [0.0, 0.6],
            ),
            (noise_file(), [0.5, 0.9]),
        ];
        let (mut rays, mut hits, mut differ) = (0, 0, 0);
        for (file, isos) in files {
            let view = crate::testvol::open(&file).expect("opens");
            let vol = Volume::new(&view).expect("volume");
            let step = 0.02;
            let mut seed = 9;
            let c = vol.to_local([12.0; 3]);
            for iso in isos {
                let params = |s| crate::testvol::params(&vol, s, step, Mode::Iso, iso);
                let accel = crate::accel::Accel::new(params(Strategy::Exact).accel_key());
                let mut exact = Tracer::new(&vol, &accel, params(Strategy::Exact));
                let mut tracers = [Strategy::Uniform, Strategy::Paper, Strategy::Bisect]
                    .map(|s| Tracer::new(&vol, &accel, params(s)));
                for _ in 0..600 {
                    let o: [f64; 3] = std::array::from_fn(|a| c[a] + 40.0 * (lcg(&mut seed) - 0.5));
                    let d: [f64; 3] = std::array::from_fn(|_| lcg(&mut seed) - 0.5);
                    let n = d.iter().map(|x| x * x).sum::<f64>().sqrt();
                    let d = d.map(|x| x / n);
                    let want = exact.iso(o, d, 0.0, f64::INFINITY, 0.5).map(|h| h.t);
                    for tr in &mut tracers {
                        let got = tr.iso(o, d, 0.0, f64::INFINITY, 0.37).map(|h| h.t);
                        rays += 1;
                        match (want, got) {
                            (None, None) => {}
                            // Within two steps of the local cell width (at most 2).
                            (Some(a), Some(b)) if (a - b).abs() <= 2.0 * step * 2.0 => hits += 1,
                            _ => differ += 1,
                        }
                    }
                }
            }
        }
        assert!(hits > 1500, "only {hits} hits in {rays} rays");
        assert!(
            differ * 200 <= rays,
            "{differ} of {rays} rays differ from exact"
        );
    }
}
