//! Direct volume rendering: samples composited front to back ([`Tracer::dvr`]), shadow-ray
//! transmittance ([`Tracer::transmittance`]), and `bisect`'s search for the transfer
//! function's band between two samples that lie on opposite sides of it.

use super::positions::Positions;
use super::{at, bisect_depth, Event, Strategy, Tracer};
use crate::integrate::{correct_opacity, Accum};
use crate::reconstruct::Eval;
use crate::transfer::Class;
use crate::traverse::{segments_skipping, Skip, SKIPPED};

impl Tracer<'_> {
    /// Direct volume rendering of `o + t d`, `t ∈ [t0, t1]`; `shade` gives the colour of a
    /// visible sample from its local position and reconstruction.
    pub fn dvr<S: FnMut(&[f64; 3], &Eval) -> [f64; 3]>(
        &mut self,
        o: [f64; 3],
        d: [f64; 3],
        t0: f64,
        t1: f64,
        jitter: f64,
        shade: &mut S,
    ) -> Accum {
        self.dvr_in(o, d, t0, t1, jitter, shade, None)
    }

    /// [`Tracer::dvr`] of one rank's share (the regions the tracer is
    /// [restricted](Tracer::restrict) to; not `bisect`): every stretch of the ray through
    /// the share, composited on its own, with the distance of its first sample, into
    /// `runs`. The samples are those of the whole ray: the positions advance through the
    /// other ranks' regions as they would be sampled, and where a stretch of this rank's
    /// follows one of theirs directly, the last sample there (read from their data) is the
    /// front of the first pre-integrated segment.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn dvr_runs<S: FnMut(&[f64; 3], &Eval) -> [f64; 3]>(
        &mut self,
        o: [f64; 3],
        d: [f64; 3],
        t0: f64,
        t1: f64,
        jitter: f64,
        shade: &mut S,
        runs: &mut Vec<(f64, Accum)>,
    ) {
        self.dvr_in(o, d, t0, t1, jitter, shade, Some(runs));
    }

    #[allow(clippy::too_many_arguments)]
    fn dvr_in<S: FnMut(&[f64; 3], &Eval) -> [f64; 3]>(
        &mut self,
        o: [f64; 3],
        d: [f64; 3],
        t0: f64,
        t1: f64,
        jitter: f64,
        shade: &mut S,
        mut runs: Option<&mut Vec<(f64, Accum)>>,
    ) -> Accum {
        let mut acc = Accum::default();
        // With `runs`: where the current run's first sample lies.
        let mut run_start: Option<f64> = None;
        let Some((t0, t1)) = self.clip(&o, &d, t0, t1) else {
            return acc;
        };
        let vol = self.vol;
        let params = self.params;
        let tf = params.tf;
        let mut prev: Option<(f64, Class, bool)> = None;
        // Value of the previous sample when it lies just behind the current one on a
        // contiguous stretch (the front of a pre-integrated segment).
        let mut front: Option<f64> = None;
        let mut last_t1 = f64::NEG_INFINITY;
        let mut t_next = f64::NEG_INFINITY;
        let mut stack = std::mem::take(&mut self.stack);
        let skip = Skip {
            field: params.field,
            keep: |a, b| tf.may_contribute(a, b),
            // Only `bisect` needs to know about gaps (band crossings next to skipped space).
            across_gaps: params.strategy != Strategy::Bisect,
        };
        let packed = self.packed();
        segments_skipping(vol, packed, o, d, t0, t1, &mut stack, &skip, |seg| {
            let r = seg.region as usize;
            let w = vol.step_width(seg.region);
            if seg.t0 > last_t1 + 1e-9 * w {
                prev = None;
                front = None;
            }
            last_t1 = seg.t1;
            let (mn, mx) = (seg.min, seg.max);
            let skipped = seg.region == SKIPPED || !tf.may_contribute(mn, mx);
            self.enter_segment(&seg, skipped);
            if skipped {
                front = None;
                if params.strategy == Strategy::Bisect {
                    let class = tf.classify(mn as f64);
                    if let Some((pt, pc, _)) = prev {
                        if pc != class && pc != Class::Inside {
                            // The band lies between the last sample and this region.
                            self.band_search(o, d, pt, seg.t0, w, &mut acc, shade);
                            if acc.done() {
                                return false;
                            }
                        }
                    }
                    prev = Some((seg.t1, class, false));
                }
                return true;
            }
            let mut pos = Positions::new(
                params.strategy,
                seg.t0,
                seg.t1,
                params.step * w,
                jitter,
                t_next,
            );
            if !self.owns(seg.region) {
                // Another rank's samples: the positions advance as they are taken there.
                let last = pos.by_ref().last();
                t_next = pos.next_t();
                if let Some((t, _)) = last {
                    front = match params.preintegrated {
                        Some(_) => {
                            self.touch(seg.region);
                            vol.eval_value(r, at(&o, &d, t), params.field)
                        }
                        None => None,
                    };
                }
                if let (Some(runs), Some(t)) = (runs.as_deref_mut(), run_start.take()) {
                    runs.push((t, std::mem::take(&mut acc)));
                }
                return true;
            }
            if runs.is_some() {
                self.touch(seg.region);
            }
            if params.strategy == Strategy::Bisect && prev.is_none_or(|p| !p.2) {
                // Entry sample: a band crossing between skipped space (or the clipped ray
                // start) and this region's first sample is bisected from here.
                let v = vol.eval_value(r, at(&o, &d, seg.t0), params.field);
                self.stats.samples += 1;
                if let Some(v) = v {
                    let class = tf.classify(v);
                    if let Some((pt, pc, _)) = prev {
                        if pc != class && pc != Class::Inside && class != Class::Inside {
                            self.band_search(o, d, pt, seg.t0, w, &mut acc, shade);
                            if acc.done() {
                                return false;
                            }
                        }
                    }
                    prev = Some((seg.t0, class, true));
                }
            }
            for (t, delta) in pos.by_ref() {
                let p = at(&o, &d, t);
                let v = vol.eval_value(r, p, params.field);
                self.stats.samples += 1;
                let Some(v) = v else {
                    prev = None;
                    front = None;
                    continue;
                };
                let class = tf.classify(v);
                let mut delta = delta;
                if params.strategy == Strategy::Bisect {
                    if let Some((pt, pc, _)) = prev {
                        if pc != Class::Inside && class != Class::Inside && pc != class {
                            let tm = self.band_search(o, d, pt, t, w, &mut acc, shade);
                            if acc.done() {
                                return false;
                            }
                            if tm.is_some() {
                                // The band sample took the front of this segment.
                                front = None;
                            }
                            delta = t - tm.unwrap_or(pt);
                        } else {
                            delta = t - pt;
                        }
                    }
                    prev = Some((t, class, true));
                }
                let a = match &params.preintegrated {
                    Some(pre) => pre.segment_alpha(front.unwrap_or(v), v, delta),
                    None => correct_opacity(tf.opacity(v), delta, params.delta0),
                };
                front = Some(v);
                self.record(Event::Sample {
                    t,
                    value: Some(v),
                    alpha: a,
                });
                if a > 0.0 {
                    if let Some(e) = vol.eval(r, p, params.field, params.colour_field) {
                        run_start.get_or_insert(t);
                        acc.add(shade(&p, &e), a);
                        if acc.done() {
                            return false;
                        }
                    }
                }
            }
            t_next = pos.next_t();
            if pos.truncated {
                self.stats.truncated_segments += 1;
            }
            true
        });
        self.stack = stack;
        if let (Some(runs), Some(t)) = (runs, run_start) {
            runs.push((t, std::mem::take(&mut acc)));
        }
        acc
    }

    /// `bisect`: the band lies between `ta` and `tb` (values on opposite sides); bisects
    /// for a point inside it and composites that sample with the distance from `ta`.
    #[allow(clippy::too_many_arguments)]
    fn band_search<S: FnMut(&[f64; 3], &Eval) -> [f64; 3]>(
        &mut self,
        o: [f64; 3],
        d: [f64; 3],
        ta: f64,
        tb: f64,
        w: f64,
        acc: &mut Accum,
        shade: &mut S,
    ) -> Option<f64> {
        let tf = self.params.tf;
        let (mut a, mut b) = (ta, tb);
        let side_a = self.probe(at(&o, &d, a)).map(|v| tf.classify(v));
        for _ in 0..bisect_depth(tb - ta, w) {
            let tm = 0.5 * (a + b);
            let p = at(&o, &d, tm);
            let v = self.probe(p)?;
            let class = tf.classify(v);
            if class == Class::Inside {
                let vol = self.vol;
                let e = vol.region_at(p).and_then(|r| {
                    vol.eval(r as usize, p, self.params.field, self.params.colour_field)
                })?;
                let alpha = correct_opacity(tf.opacity(v), tm - ta, self.params.delta0);
                self.record(Event::Sample {
                    t: tm,
                    value: Some(v),
                    alpha,
                });
                acc.add(shade(&p, &e), alpha);
                return Some(tm);
            }
            if Some(class) == side_a {
                a = tm;
            } else {
                b = tm;
            }
        }
        None
    }

    /// Transmittance along a shadow ray (dvr), with `paper` sampling and no shading.
    pub fn transmittance(&mut self, o: [f64; 3], d: [f64; 3], t0: f64, t1: f64) -> f64 {
        let saved = self.log.take();
        let acc = self.dvr(o, d, t0, t1, 0.5, &mut |_, _| [0.0; 3]);
        self.log = saved;
        acc.transmittance
    }
}
