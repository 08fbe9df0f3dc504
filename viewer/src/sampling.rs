//! Sampling strategies along one ray: `uniform`, `paper`, `bisect`, `exact`
//! (see `docs/design.md`, "Sampling strategies").
//!
//! All strategies walk the regions front to back ([`Volume::segments`]) and skip a region
//! whose value bounds miss the transfer function's non-zero band. A skipped region still
//! tells on which side of the band the field is there: when the last sample before it lies
//! on the other side, the band was crossed in between and is searched for there, so
//! skipping never loses a crossing.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::integrate::{correct_opacity, Accum};
use crate::reconstruct::{Cubic, Eval};
use crate::transfer::PreIntegrated;
use crate::transfer::{Class, Mode, Transfer};
use crate::traverse::{Skip, SKIPPED};
use crate::volume::Volume;

/// Smallest bisection interval of `bisect`, in cell widths.
pub const BISECT_RESOLUTION: f64 = 0.005;

/// Sampling strategy along a ray (see `docs/design.md`, "Sampling strategies").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Strategy {
    /// Fixed step in units of the local cell width.
    Uniform,
    /// ExaBricks adaptive sampling at interval midpoints.
    Paper,
    /// Adaptive sampling plus bisection into the transfer function's band.
    Bisect,
    /// Root finding on the trilinear cubic per dual cell (iso mode).
    Exact,
}

impl Strategy {
    pub const ALL: [Strategy; 4] = [
        Strategy::Uniform,
        Strategy::Paper,
        Strategy::Bisect,
        Strategy::Exact,
    ];
    pub fn as_str(self) -> &'static str {
        match self {
            Strategy::Uniform => "uniform",
            Strategy::Paper => "paper",
            Strategy::Bisect => "bisect",
            Strategy::Exact => "exact",
        }
    }
}

impl fmt::Display for Strategy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Strategy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Strategy::ALL
            .into_iter()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| {
                format!("unknown strategy `{s}`: expected uniform, paper, bisect or exact")
            })
    }
}

/// What a ray needs to know about the volume's transfer and sampling.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    pub strategy: Strategy,
    /// Step in units of the local cell width.
    pub step: f64,
    pub tf: Transfer,
    /// Field of the iso value / transfer function.
    pub field: usize,
    /// Field that drives the colour.
    pub colour_field: Option<usize>,
    /// Reference length of the transfer function's opacity (world units).
    pub delta0: f64,
    /// Local box holding every region that can contribute (rays are clipped to it);
    /// `None`: no clipping. See [`Params::clip_to_active`].
    pub clip: Option<([f64; 3], [f64; 3])>,
    /// Pre-integrated dvr opacity (`None`: point-sampled opacity with the usual correction).
    pub preintegrated: Option<PreIntegrated>,
}

/// Work counters of one or more rays (summed in integers: deterministic).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// Reconstructions (samples, refinement probes, exact's dual-cell cubics).
    pub samples: u64,
    pub segments: u64,
    pub skipped: u64,
    /// `exact` segments through a region with more than [`MAX_LATTICES`] distinct cell
    /// lattices: the extra lattices' planes are not cut there, so the search is only
    /// approximately exact (reported, never silent; nested grids of one refinement ratio
    /// never produce such a region).
    pub inexact_segments: u64,
    /// Segments whose sample sequence stopped at [`MAX_POSITIONS_PER_SEGMENT`] or because
    /// the step fell below the resolution of `t` (`t + dt == t`).
    pub truncated_segments: u64,
}

impl std::ops::AddAssign for Stats {
    fn add_assign(&mut self, o: Stats) {
        self.samples += o.samples;
        self.segments += o.segments;
        self.skipped += o.skipped;
        self.inexact_segments += o.inexact_segments;
        self.truncated_segments += o.truncated_segments;
    }
}

/// Most distinct cell lattices `exact` cuts planes for in one region.
pub const MAX_LATTICES: usize = 8;

/// Most sample positions in one region segment. With the smallest step
/// (`view_state::MIN_STEP`, a thousand per cell width) that is a thousand cells along one
/// segment; bricks are far smaller, so only a degenerate step or geometry reaches it.
pub const MAX_POSITIONS_PER_SEGMENT: u32 = 1 << 20;

/// What `--pixel` prints.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    Segment {
        region: u32,
        t0: f64,
        t1: f64,
        min: f32,
        max: f32,
        skipped: bool,
    },
    Sample {
        t: f64,
        value: Option<f64>,
        alpha: f64,
    },
    Interval {
        t0: f64,
        t1: f64,
        may_cross: bool,
    },
    Hit {
        t: f64,
        value: Option<f64>,
        /// Unit shading normal (world), filled in by the ray caster that shades the hit.
        #[serde(skip_serializing_if = "Option::is_none")]
        normal: Option<[f64; 3]>,
    },
}

/// First iso-surface crossing along a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IsoHit {
    pub t: f64,
    /// Local frame.
    pub p: [f64; 3],
    /// Reconstruction at the hit (`None` only where the weights vanish).
    pub eval: Option<Eval>,
}

#[derive(Debug, Clone, Copy)]
struct Prev {
    t: f64,
    v: f64,
    /// A real sample (`false`: a bound of a skipped region, only its side is known).
    real: bool,
}

/// Sample positions of one region segment: `(t, Δ)`. Ends early (and says so in
/// `truncated`) when a step no longer moves `t` or after [`MAX_POSITIONS_PER_SEGMENT`]
/// positions, so no step size can make a ray march for ever.
struct Positions {
    strategy: Strategy,
    a: f64,
    b: f64,
    end: f64,
    dt: f64,
    count: u32,
    truncated: bool,
}

impl Positions {
    /// `t_next` carries the uniform sequence from region to region.
    fn new(strategy: Strategy, t0: f64, t1: f64, dt: f64, jitter: f64, t_next: f64) -> Self {
        match strategy {
            Strategy::Uniform => {
                let a = if t_next < t0 {
                    t0 + jitter * dt
                } else {
                    t_next
                };
                Positions {
                    strategy,
                    a,
                    b: a,
                    end: t1,
                    dt,
                    count: 0,
                    truncated: false,
                }
            }
            _ => Positions {
                strategy,
                a: t0,
                b: t0 + jitter * dt,
                end: t1,
                dt,
                count: 0,
                truncated: false,
            },
        }
    }

    /// Where the uniform sequence continues after this segment.
    fn next_t(&self) -> f64 {
        self.a
    }
}

impl Iterator for Positions {
    type Item = (f64, f64);

    fn next(&mut self) -> Option<(f64, f64)> {
        if self.count >= MAX_POSITIONS_PER_SEGMENT {
            self.truncated |= self.a < self.end;
            return None;
        }
        self.count += 1;
        if self.strategy == Strategy::Uniform {
            if self.a >= self.end {
                return None;
            }
            let t = self.a;
            self.a += self.dt;
            if self.a <= t {
                // The step is below the resolution of t here: stop rather than loop.
                self.truncated = true;
                self.a = self.end;
            }
            return Some((t, self.dt));
        }
        // Interval delimiters t0, t0 + jitter·dt, t0 + (1 + jitter)·dt, …, t1; midpoints.
        loop {
            if self.a >= self.end {
                return None;
            }
            let b = self.b.min(self.end);
            let a = self.a;
            self.a = b;
            let next_b = self.b + self.dt;
            if next_b.partial_cmp(&self.b) != Some(std::cmp::Ordering::Greater) && b < self.end {
                // `b + dt == b`: no further delimiter can be placed; end the segment here.
                self.truncated = true;
                self.b = self.end;
            } else {
                self.b = next_b;
            }
            if b > a {
                return Some((0.5 * (a + b), b - a));
            }
        }
    }
}

#[inline]
fn at(o: &[f64; 3], d: &[f64; 3], t: f64) -> [f64; 3] {
    std::array::from_fn(|a| o[a] + t * d[a])
}

/// Casts rays through one volume with one set of parameters; keeps its scratch space.
pub struct Tracer<'v> {
    pub vol: &'v Volume<'v>,
    pub params: Params,
    pub stats: Stats,
    /// Set to `Some` to record what the next rays do (`--pixel`).
    pub log: Option<Vec<Event>>,
    stack: Vec<(u32, f64, f64)>,
    /// Region of the last refinement probe.
    probe_hint: Option<u32>,
}

impl<'v> Tracer<'v> {
    pub fn new(vol: &'v Volume<'v>, params: Params) -> Self {
        Tracer {
            vol,
            params,
            stats: Stats::default(),
            log: None,
            stack: Vec::with_capacity(64),
            probe_hint: None,
        }
    }

    /// `[t0, t1]` clipped to the active box.
    fn clip(&self, o: &[f64; 3], d: &[f64; 3], t0: f64, t1: f64) -> Option<(f64, f64)> {
        match &self.params.clip {
            None => Some((t0, t1)),
            Some((lo, hi)) => {
                if (0..3).any(|a| lo[a] > hi[a]) {
                    return None;
                }
                crate::traverse::ray_box(lo, hi, o, &crate::traverse::inverse(d), t0, t1)
            }
        }
    }

    fn record(&mut self, e: Event) {
        if let Some(l) = &mut self.log {
            l.push(e);
        }
    }

    /// Counts a region segment the ray enters (and whether its bounds let it be skipped)
    /// and logs it for `--pixel`.
    fn enter_segment(&mut self, seg: &crate::traverse::Segment, skipped: bool) {
        self.stats.segments += 1;
        if skipped {
            self.stats.skipped += 1;
        }
        self.record(Event::Segment {
            region: seg.region,
            t0: seg.t0,
            t1: seg.t1,
            min: seg.min,
            max: seg.max,
            skipped,
        });
    }

    /// Value at any local point (probe during refinement, regions found by KD descent).
    fn probe(&mut self, p: [f64; 3]) -> Option<f64> {
        self.stats.samples += 1;
        let vol = self.vol;
        // Refinement probes cluster: try the region of the previous probe before a KD descent.
        let r = match self.probe_hint {
            Some(r)
                if (r as usize) < vol.region_count() && {
                    let g = vol.region(r as usize);
                    (0..3).all(|a| p[a] >= g.min[a] && p[a] < g.max[a])
                } =>
            {
                r
            }
            _ => vol.region_at(p)?,
        };
        self.probe_hint = Some(r);
        vol.eval_value(r as usize, p, self.params.field)
    }

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
        let eval = region
            .or_else(|| vol.region_at(p))
            .and_then(|r| vol.eval(r as usize, p, self.params.field, self.params.colour_field))
            .or_else(|| {
                // The hit may lie on the region's far face (round-off): look it up.
                let r = vol.region_at(p)?;
                vol.eval(r as usize, p, self.params.field, self.params.colour_field)
            });
        self.stats.samples += 1;
        self.record(Event::Hit {
            t,
            value: eval.map(|e| e.value),
            normal: None,
        });
        Some(IsoHit { t, p, eval })
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
        vol.segments_skipping(o, d, t0, t1, &mut stack, &skip, |seg| {
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
        });
        self.stack = stack;
        if bracket.is_none() {
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

    /// Exact iso search: per region (skipped by bounds), per interval between lattice
    /// planes of every level present (inside which `Σ H (v − iso)` is a cubic), skip when
    /// all contributing cells lie on one side, else take the cubic's first root.
    fn iso_exact(
        &mut self,
        o: [f64; 3],
        d: [f64; 3],
        t0: f64,
        t1: f64,
    ) -> Option<(f64, Option<u32>)> {
        let vol = self.vol;
        let params = self.params;
        let iso = params.tf.iso;
        let mut found = None;
        let mut stack = std::mem::take(&mut self.stack);
        let skip = Skip {
            field: params.field,
            keep: |a: f32, b: f32| a as f64 <= iso && iso <= b as f64,
            across_gaps: true,
        };
        vol.segments_skipping(o, d, t0, t1, &mut stack, &skip, |seg| {
            let r = seg.region as usize;
            let (mn, mx) = (seg.min, seg.max);
            let skipped = seg.region == SKIPPED || !(mn as f64 <= iso && iso <= mx as f64);
            self.enter_segment(&seg, skipped);
            if skipped {
                return true;
            }
            let mut planes = Planes::new(vol, r, &o, &d, seg.t0);
            if planes.inexact {
                self.stats.inexact_segments += 1;
            }
            let mut ta = seg.t0;
            while ta < seg.t1 {
                let tb = planes.next(ta).min(seg.t1);
                if tb <= ta {
                    break;
                }
                let cubic = vol.cubic(r, &o, &d, ta, tb, params.field, iso);
                self.stats.samples += 1;
                let may_cross = cubic.any_above && cubic.any_below;
                self.record(Event::Interval {
                    t0: ta,
                    t1: tb,
                    may_cross,
                });
                if may_cross {
                    if let Some(x) = first_root(&cubic) {
                        found = Some((ta + x * (tb - ta), Some(seg.region)));
                        return false;
                    }
                }
                ta = tb;
            }
            true
        });
        self.stack = stack;
        found
    }

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
        let mut acc = Accum::default();
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
        vol.segments_skipping(o, d, t0, t1, &mut stack, &skip, |seg| {
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
            let mut pos = Positions::new(
                params.strategy,
                seg.t0,
                seg.t1,
                params.step * w,
                jitter,
                t_next,
            );
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

/// Bisection depth that narrows `len` (world units) to `BISECT_RESOLUTION` cells of width `w`.
fn bisect_depth(len: f64, w: f64) -> u32 {
    let r = (len / w / BISECT_RESOLUTION).max(1.0);
    (r.log2().ceil() as u32).clamp(1, 40)
}

/// Walks the lattice planes (cell-centre planes) of every lattice present in a region.
struct Planes {
    /// Next plane crossing per (lattice, axis) and the spacing in t.
    next: [f64; 3 * MAX_LATTICES],
    step: [f64; 3 * MAX_LATTICES],
    n: usize,
    /// The region has more lattices than are cut (see [`Stats::inexact_segments`]).
    inexact: bool,
}

impl Planes {
    fn new(vol: &Volume, r: usize, o: &[f64; 3], d: &[f64; 3], t: f64) -> Planes {
        let mut pl = Planes {
            next: [f64::INFINITY; 3 * MAX_LATTICES],
            step: [f64::INFINITY; 3 * MAX_LATTICES],
            n: 0,
            inexact: false,
        };
        let ids = vol.region_brick_ids(r);
        // Distinct lattices: (cell width, 1 / width, a cell centre).
        let mut lattices = [(0.0f64, 0.0f64, [0.0f64; 3]); MAX_LATTICES];
        let mut nl = 0;
        for b in ids {
            let br = vol.brick(b.to_native());
            let same = |&(w, _, origin): &(f64, f64, [f64; 3])| {
                w == br.w
                    && (origin == br.origin
                        || (0..3).all(|a| {
                            // Whole cells apart (a cast truncates in one instruction;
                            // `round` is a library call on the baseline target).
                            let q = (origin[a] - br.origin[a]) * br.inv_w;
                            let frac = (q - q as i64 as f64).abs();
                            !(1e-9..=1.0 - 1e-9).contains(&frac)
                        }))
            };
            if lattices[..nl].iter().any(same) {
                continue;
            }
            if nl == MAX_LATTICES {
                // More distinct lattices in one region than are cut (never produced by
                // nested grids of one refinement ratio): the remaining lattices' planes are
                // not cut, so intervals there are only approximately cubic. Counted in
                // `Stats::inexact_segments` and reported by `render --json`.
                pl.inexact = true;
                break;
            }
            lattices[nl] = (br.w, br.inv_w, br.origin);
            nl += 1;
        }
        for &(w, inv_w, origin) in &lattices[..nl] {
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

/// First root of the cubic on `[0, 1]` (a sign change or an exact zero), refined by
/// bisection to round-off.
pub fn first_root(c: &Cubic) -> Option<f64> {
    // Bernstein coefficients on [0, 1]: g lies in their convex hull, so when all of them
    // are clearly of one sign g has no zero there (most intervals whose cells straddle
    // the iso value), without the critical points and evaluations below.
    let b = [
        c.c[0],
        c.c[0] + c.c[1] / 3.0,
        c.c[0] + (2.0 * c.c[1] + c.c[2]) / 3.0,
        c.c[0] + c.c[1] + c.c[2] + c.c[3],
    ];
    let margin = 1e-9 * (c.c[0].abs() + c.c[1].abs() + c.c[2].abs() + c.c[3].abs());
    if b.iter().all(|&x| x > margin) || b.iter().all(|&x| x < -margin) {
        return None;
    }
    // Where the weights vanish (outer support boundary) g is zero without a surface.
    let wscale = c.weight.iter().map(|x| x.abs()).sum::<f64>();
    let real_zero = |x: f64| c.weight_at(x) > 1e-7 * wscale;
    let mut g0 = c.eval(0.0);
    if g0 == 0.0 {
        if real_zero(0.0) {
            return Some(0.0);
        }
        g0 = c.eval(1e-9);
        if g0 == 0.0 {
            return None;
        }
    }
    // Monotone pieces between the critical points.
    let mut cuts = [0.0, 1.0, 1.0, 1.0];
    let mut n = 1;
    let (qa, qb, qc) = (3.0 * c.c[3], 2.0 * c.c[2], c.c[1]);
    let scale = qa.abs() + qb.abs() + qc.abs();
    let mut roots = [f64::NAN; 2];
    if qa.abs() <= 1e-14 * scale {
        if qb != 0.0 {
            roots[0] = -qc / qb;
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let q = -0.5 * (qb + qb.signum() * disc.sqrt());
            roots[0] = q / qa;
            if q != 0.0 {
                roots[1] = qc / q;
            }
        }
    }
    if roots[0] > roots[1] {
        roots.swap(0, 1);
    }
    for x in roots {
        if x > 0.0 && x < 1.0 {
            cuts[n] = x;
            n += 1;
        }
    }
    cuts[n] = 1.0;
    let mut xa = 0.0;
    let mut ga = g0;
    for &xb in &cuts[1..=n] {
        if xb <= xa {
            continue;
        }
        let gb = c.eval(xb);
        if gb == 0.0 {
            if real_zero(xb) {
                return Some(xb);
            }
            xa = xb;
            continue;
        }
        if (ga < 0.0) != (gb < 0.0) {
            // g is monotone on [xa, xb]: Newton steps kept inside the shrinking bracket
            // (bisection where a step would leave it), to round-off.
            let (mut lo, mut hi) = (xa, xb);
            let mut x = 0.5 * (lo + hi);
            for _ in 0..100 {
                let gm = c.eval(x);
                if gm == 0.0 {
                    if real_zero(x) {
                        return Some(x);
                    }
                    break;
                }
                if (gm < 0.0) == (ga < 0.0) {
                    lo = x;
                } else {
                    hi = x;
                }
                let dg = c.slope(x);
                let newton = x - gm / dg;
                let next = if newton > lo && newton < hi {
                    newton
                } else {
                    0.5 * (lo + hi)
                };
                if next <= lo || next >= hi || (next - x).abs() <= 4.0 * f64::EPSILON {
                    x = next.clamp(lo, hi);
                    break;
                }
                x = next;
            }
            if real_zero(x) {
                return Some(x);
            }
        }
        xa = xb;
        ga = gb;
    }
    None
}

impl Params {
    pub fn mode(&self) -> Mode {
        self.tf.mode
    }

    /// Sets [`Params::clip`] to the bounding box of the regions whose value range can
    /// contribute (contains iso / meets the band). Everything outside it is skipped anyway;
    /// the strategies that track the side of skipped space take an entry sample in the first
    /// region they process, so nothing is lost by starting there.
    pub fn clip_to_active(&mut self, vol: &Volume) {
        let tf = self.tf;
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (r, reg) in vol.regions().enumerate() {
            let [mn, mx] = vol.range(r, self.field);
            if tf.may_contribute(mn, mx) {
                for a in 0..3 {
                    lo[a] = lo[a].min(reg.min[a]);
                    hi[a] = hi[a].max(reg.max[a]);
                }
            }
        }
        // Nothing can contribute: an empty box (min > max) that no ray enters.
        self.clip = Some((lo, hi));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cubic_from_roots(r: [f64; 3], scale: f64) -> Cubic {
        // scale·(x − r0)(x − r1)(x − r2), weights constant 1.
        let [a, b, c] = r;
        Cubic {
            c: [
                -scale * a * b * c,
                scale * (a * b + a * c + b * c),
                -scale * (a + b + c),
                scale,
            ],
            weight: [1.0, 0.0, 0.0, 0.0],
            any_above: true,
            any_below: true,
        }
    }

    #[test]
    fn first_root_of_cubics() {
        for (roots, want) in [
            ([0.3, 0.5, 0.9], Some(0.3)),
            ([-1.0, 0.7, 2.0], Some(0.7)),
            ([-1.0, 1.5, 2.0], None),
            ([0.25, 0.2500001, 3.0], Some(0.25)), // two close roots: the first
        ] {
            for scale in [1.0, -3.0, 1e-6] {
                let got = first_root(&cubic_from_roots(roots, scale));
                match (got, want) {
                    (Some(g), Some(w)) => assert!((g - w).abs() < 1e-9, "{roots:?}: {g} vs {w}"),
                    (None, None) => {}
                    _ => panic!("{roots:?} scale {scale}: got {got:?}, want {want:?}"),
                }
            }
        }
        // A zero where the weights vanish (outer support boundary) is not a surface.
        let mut c = cubic_from_roots([0.0, 5.0, 6.0], 1.0);
        c.weight = [0.0, 1.0, 0.0, 0.0];
        assert_eq!(first_root(&c), None);
    }

    #[test]
    fn paper_intervals_tile_the_segment() {
        for jitter in [0.0, 0.3, 0.999] {
            let (t0, t1, dt) = (1.25, 4.0, 0.4);
            let pos: Vec<(f64, f64)> =
                Positions::new(Strategy::Paper, t0, t1, dt, jitter, 0.0).collect();
            let total: f64 = pos.iter().map(|p| p.1).sum();
            assert!((total - (t1 - t0)).abs() < 1e-12);
            let mut a = t0;
            for &(t, delta) in &pos {
                assert!(
                    (t - (a + 0.5 * delta)).abs() < 1e-12 && delta > 0.0 && delta <= dt + 1e-12
                );
                a += delta;
            }
            // Uniform: fixed step, continuing a sequence that reached this segment.
            let u: Vec<f64> = Positions::new(Strategy::Uniform, t0, t1, dt, jitter, 2.0)
                .map(|p| p.0)
                .collect();
            assert_eq!(u.first().copied(), Some(2.0));
            assert!(u.windows(2).all(|w| (w[1] - w[0] - dt).abs() < 1e-12));
        }
    }

    /// A step below the resolution of `t` (`t + dt == t` far from the origin) or a segment
    /// of more than `MAX_POSITIONS_PER_SEGMENT` steps ends the sequence, marked truncated,
    /// instead of marching for ever.
    #[test]
    fn positions_end_when_the_step_cannot_advance() {
        for strategy in [Strategy::Uniform, Strategy::Paper, Strategy::Bisect] {
            let mut p = Positions::new(strategy, 1e12, 1e12 + 1.0, 1e-6, 0.5, 0.0);
            let n = p.by_ref().count();
            assert!(n <= 3, "{strategy:?}: {n} positions");
            assert!(p.truncated, "{strategy:?}");

            let mut p = Positions::new(strategy, 0.0, 1.0, 1e-9, 0.5, 0.0);
            let n = p.by_ref().count();
            assert_eq!(n as u32, MAX_POSITIONS_PER_SEGMENT, "{strategy:?}");
            assert!(p.truncated, "{strategy:?}");

            let mut p = Positions::new(strategy, 0.0, 1.0, 0.25, 0.5, 0.0);
            assert!(p.by_ref().count() <= 5);
            assert!(
                !p.truncated,
                "{strategy:?}: an ordinary segment is not truncated"
            );
        }
    }
}
