//! Iso mode: the entry points ([`Tracer::iso`], [`Tracer::iso_occluded`]) for every strategy,
//! and the sample-based search of `uniform`, `paper` and `bisect`. Consecutive samples (or a
//! sample and the side of a skipped region, or an exit sample where the data ends) on
//! opposite sides of the iso value bracket a crossing, which is then narrowed to a position.
//! `exact` has its own search (`exact.rs`).

use super::positions::Positions;
use super::{at, bisect_depth, Event, Gaps, IsoHit, Strategy, Tracer};
use crate::traverse::{segments_skipping, Segment, Skip, SKIPPED};

#[derive(Debug, Clone, Copy)]
struct Prev {
    t: f64,
    v: f64,
    /// A real sample (`false`: a bound of a skipped region, only its side is known).
    real: bool,
}

impl Tracer<'_> {
    /// First crossing of the iso value along `o + t d` (local frame, unit `d`) for `t` in
    /// `[t0, t1]`; `jitter ∈ [0, 1)` offsets the first sample.
    pub fn iso(
        &mut self,
        o: [f64; 3],
        d: [f64; 3],
        t0: f64,
        t1: f64,
        jitter: f64,
    ) -> Option<IsoHit> {
        let (t0, t1) = self.clip(&o, &d, t0, t1)?;
        let (t, region) = match self.params.strategy {
            Strategy::Exact => self.iso_exact(o, d, t0, t1),
            _ => self.iso_sampled(o, d, t0, t1, jitter).map(|t| (t, None)),
        }?;
        let p = at(&o, &d, t);
        let vol = self.vol;
        let mut region = region.or_else(|| vol.region_box_at(p));
        if let Some(r) = region {
            self.touch(r.region);
        }
        let eval = region
            .and_then(|r| {
                vol.eval(
                    r.region as usize,
                    p,
                    self.params.field,
                    self.params.colour_field,
                )
            })
            .or_else(|| {
                // The hit may lie on the region's far face (round-off): look it up.
                region = vol.region_box_at(p);
                vol.eval(
                    region?.region as usize,
                    p,
                    self.params.field,
                    self.params.colour_field,
                )
            });
        self.stats.samples += 1;
        self.record(Event::Hit {
            t,
            value: eval.map(|e| e.value),
            normal: None,
            surface: None,
        });
        Some(IsoHit { t, p, eval, region })
    }

    /// Whether anything opaque (iso mode) lies on `o + t d`, `t ∈ (t0, t1)`.
    pub fn iso_occluded(&mut self, o: [f64; 3], d: [f64; 3], t0: f64, t1: f64) -> bool {
        let Some((t0, t1)) = self.clip(&o, &d, t0, t1) else {
            return false;
        };
        let saved = self.log.take();
        let hit = match self.params.strategy {
            Strategy::Exact => self.iso_exact(o, d, t0, t1).map(|h| h.0),
            _ => self.iso_sampled(o, d, t0, t1, 0.5),
        };
        self.log = saved;
        hit.is_some()
    }

    /// Sample-based iso search (uniform, paper, bisect): a crossing is two consecutive
    /// samples (or a sample and a skipped region) on opposite sides of the iso value.
    fn iso_sampled(
        &mut self,
        o: [f64; 3],
        d: [f64; 3],
        t0: f64,
        t1: f64,
        jitter: f64,
    ) -> Option<f64> {
        let vol = self.vol;
        let params = self.params;
        let iso = params.tf.iso;
        let mut prev: Option<Prev> = None;
        let mut last_t1 = f64::NEG_INFINITY;
        let mut t_next = f64::NEG_INFINITY;
        let mut bracket: Option<(Prev, Prev, f64)> = None;
        // Last region sampled and its step width: where an exit sample is taken.
        let mut last_live: Option<(usize, f64)> = None;
        let mut stack = std::mem::take(&mut self.stack);
        let tf = params.tf;
        let skip = Skip {
            field: params.field,
            keep: |a, b| tf.may_contribute(a, b),
            across_gaps: false,
        };
        // The regions where the iso value can lie, cut into the parts where their dual
        // cells can hold it (the tree `exact` walks, see `crate::active`): everywhere else
        // the field lies on one side of the value, so no crossing is lost by treating the
        // stretches between parts as gaps in the data (an exit sample before each, an
        // entry sample after). Without a tree, the file's walk with skipped subtrees.
        let (tree, start) = self.active_walk();
        let packed = self.packed();
        let mut gaps = tree.map(|_| Gaps::new(vol, &o, &d, t0, t1));
        let mut visit = |seg: Segment| {
            if let Some(g) = gaps.as_mut() {
                g.before(self, &seg);
            }
            let r = seg.region as usize;
            let w = vol.step_width(seg.region);
            if seg.t0 > last_t1 + 1e-9 * w {
                // A gap in the data: a crossing between the last sample and the end of
                // the data before the gap is bracketed by an exit sample.
                if let Some(b) = self.exit_bracket(o, d, prev, last_live, last_t1) {
                    bracket = Some(b);
                    return false;
                }
                prev = None;
            }
            last_t1 = seg.t1;
            let (mn, mx) = (seg.min, seg.max);
            let skipped = seg.region == SKIPPED || !params.tf.may_contribute(mn, mx);
            self.enter_segment(&seg, skipped);
            if skipped {
                let side = if mn as f64 > iso { mn } else { mx } as f64;
                let here = Prev {
                    t: seg.t0,
                    v: side,
                    real: false,
                };
                if let Some(pv) = prev {
                    if (pv.v >= iso) != (side >= iso) {
                        bracket = Some((pv, here, w));
                        return false;
                    }
                }
                prev = Some(Prev { t: seg.t1, ..here });
                return true;
            }
            if prev.is_none_or(|p| !p.real) {
                // Entry sample: a crossing between skipped space (or the clipped ray start)
                // and this region's first sample is bracketed from here.
                let v = vol.eval_value(r, at(&o, &d, seg.t0), params.field);
                self.stats.samples += 1;
                if let Some(v) = v {
                    let cur = Prev {
                        t: seg.t0,
                        v,
                        real: true,
                    };
                    if let Some(pv) = prev {
                        if (pv.v >= iso) != (v >= iso) {
                            bracket = Some((pv, cur, w));
                            return false;
                        }
                    }
                    prev = Some(cur);
                }
            }
            last_live = Some((r, w));
            let mut pos = Positions::new(
                params.strategy,
                seg.t0,
                seg.t1,
                params.step * w,
                jitter,
                t_next,
            );
            for (t, _) in pos.by_ref() {
                let v = vol.eval_value(r, at(&o, &d, t), params.field);
                self.stats.samples += 1;
                self.record(Event::Sample {
                    t,
                    value: v,
                    alpha: 0.0,
                });
                match v {
                    None => prev = None,
                    Some(v) => {
                        let cur = Prev { t, v, real: true };
                        if let Some(pv) = prev {
                            if (pv.v >= iso) != (v >= iso) {
                                bracket = Some((pv, cur, w));
                                return false;
                            }
                        }
                        prev = Some(cur);
                    }
                }
            }
            t_next = pos.next_t();
            if pos.truncated {
                self.stats.truncated_segments += 1;
            }
            true
        };
        match tree {
            Some(tree) => tree.segments(vol, start, o, d, t0, t1, None, &mut stack, |seg, _| {
                visit(seg)
            }),
            None => segments_skipping(vol, packed, o, d, t0, t1, &mut stack, &skip, visit),
        }
        self.stack = stack;
        if bracket.is_none() {
            if let Some(g) = &gaps {
                g.finish(self);
            }
            // The ray leaves the data (or the clipped box) after its last sample.
            bracket = self.exit_bracket(o, d, prev, last_live, last_t1);
        }
        let (a, b, w) = bracket?;
        Some(self.refine_iso(o, d, a, b, w))
    }

    /// Exit sample at `t_end`, the end of region `last` (step width `w`) after the real
    /// sample `prev`: a bracket if the value there lies on the other side of the iso value.
    fn exit_bracket(
        &mut self,
        o: [f64; 3],
        d: [f64; 3],
        prev: Option<Prev>,
        last: Option<(usize, f64)>,
        t_end: f64,
    ) -> Option<(Prev, Prev, f64)> {
        let (pv, (r, w)) = (prev?, last?);
        if !pv.real || t_end <= pv.t || !t_end.is_finite() {
            return None;
        }
        let iso = self.params.tf.iso;
        let field = self.params.field;
        // On the region's far face; step back by a hair if round-off puts it outside.
        let vol = self.vol;
        let (t, v) = [t_end, t_end - 1e-9 * w]
            .into_iter()
            .filter(|&t| t > pv.t)
            .find_map(|t| vol.eval_value(r, at(&o, &d, t), field).map(|v| (t, v)))?;
        self.stats.samples += 1;
        self.record(Event::Sample {
            t,
            value: Some(v),
            alpha: 0.0,
        });
        ((pv.v >= iso) != (v >= iso)).then_some((pv, Prev { t, v, real: true }, w))
    }

    /// Narrows a bracket `[a, b]` of the iso crossing to a position.
    fn refine_iso(&mut self, o: [f64; 3], d: [f64; 3], mut a: Prev, mut b: Prev, w: f64) -> f64 {
        let iso = self.params.tf.iso;
        let depth = match self.params.strategy {
            Strategy::Bisect => bisect_depth(b.t - a.t, w),
            _ if a.real && b.real => 0,
            _ => 12,
        };
        let side_a = a.v >= iso;
        for _ in 0..depth {
            let tm = 0.5 * (a.t + b.t);
            let Some(v) = self.probe(at(&o, &d, tm)) else {
                break;
            };
            let m = Prev {
                t: tm,
                v,
                real: true,
            };
            if (v >= iso) == side_a {
                a = m;
            } else {
                b = m;
            }
        }
        if a.real && b.real && a.v != b.v {
            let s = ((iso - a.v) / (b.v - a.v)).clamp(0.0, 1.0);
            a.t + s * (b.t - a.t)
        } else {
            0.5 * (a.t + b.t)
        }
    }
}
