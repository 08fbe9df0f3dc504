//! Sampling strategies along one ray: `uniform`, `paper`, `bisect`, `exact`
//! (see `docs/sampling.md`, "The four strategies").
//!
//! In dvr mode all strategies walk the regions front to back ([`Volume::segments`]) and skip
//! a region whose value bounds miss the transfer function's non-zero band. A skipped region
//! still tells on which side of the band the field is there: when the last sample before it
//! lies on the other side, the band was crossed in between and is searched for there, so
//! skipping never loses a crossing. In iso mode they walk the parts of the regions that can
//! hold the iso value ([`crate::active`]); the field lies on one side of it everywhere else.
//!
//! The files follow the algorithms, because that is what one reads or changes at a time;
//! what every strategy shares stays here, once:
//!
//! - here: the public types ([`Strategy`], [`Params`], [`Stats`], [`Event`], [`IsoHit`]),
//!   the limits, and [`Tracer`] with the per-segment bookkeeping every walk uses (clipping
//!   to the active box, the trees of the view's acceleration, counting and logging a
//!   segment and the gaps between the active tree's leaves, probing a point during
//!   refinement) and the bisection depth that `iso` and `dvr` both refine to under
//!   `bisect`;
//! - `positions`: where the samples of one region segment go (`uniform`'s fixed step carried
//!   from region to region, `paper`/`bisect` interval midpoints);
//! - `iso`: iso mode ([`Tracer::iso`], [`Tracer::iso_occluded`]) and its sample-based
//!   search for `uniform`, `paper` and `bisect`: bracket a crossing, then narrow it;
//! - `exact`: the `exact` iso search, a cubic per interval between lattice planes; `roots`:
//!   the cubic's first root;
//! - `dvr`: direct volume rendering ([`Tracer::dvr`], [`Tracer::transmittance`]) and
//!   `bisect`'s search for the band between two samples.
//!
//! Every strategy is a method of the one [`Tracer`] (the files add `impl Tracer` blocks), so
//! the scratch stack, counters and log have a single owner and the skip bookkeeping a single
//! copy; the strategy is picked by matching on [`Strategy`], not through a trait per strategy.
//!
//! A tracer reads the volume (the file) and the view's acceleration ([`Accel`]: the packed
//! tree of its iso field, the active tree of its iso value), which its caller built for the
//! same field and iso value as its [`Params`] ([`Params::accel_key`]); it never looks a
//! tree up.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::accel::{Accel, AccelKey};
use crate::active::{ActiveTree, Start};
use crate::reconstruct::Eval;
use crate::transfer::PreIntegrated;
use crate::transfer::{Mode, Transfer};
use crate::volume::{RegionBox, Volume};

mod dvr;
mod exact;
mod iso;
mod positions;
mod roots;

/// Smallest bisection interval of `bisect`, in cell widths.
pub(crate) const BISECT_RESOLUTION: f64 = 0.005;

/// Sampling strategy along a ray (see `docs/sampling.md`, "The four strategies").
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
    /// Every strategy, in the order `qbricks-lab bench` runs them.
    pub const ALL: [Strategy; 4] = [
        Strategy::Uniform,
        Strategy::Paper,
        Strategy::Bisect,
        Strategy::Exact,
    ];
    /// The strategy rays use for this one in `mode`: `exact` finds iso-surface roots; a
    /// dvr band has no single root, so in dvr mode `exact` samples as `uniform` when the
    /// opacity is pre-integrated and as `bisect` when it is point-sampled. Point samples
    /// catch a band thinner than the step only by chance, which `bisect`'s search between
    /// samples repairs; pre-integration already counts the band between two samples, so
    /// plain `uniform` steps reach a lower error with fewer samples than either `bisect`
    /// variant (BENCHMARKS.md, "Direct volume rendering").
    pub(crate) fn in_mode(self, mode: Mode, preintegrated: bool) -> Strategy {
        match (mode, self) {
            (Mode::Dvr, Strategy::Exact) if preintegrated => Strategy::Uniform,
            (Mode::Dvr, Strategy::Exact) => Strategy::Bisect,
            _ => self,
        }
    }

    /// The name in view-state files and reports (`uniform`, `paper`, `bisect`, `exact`).
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

impl Params {
    /// Sets [`Params::clip`] to the bounding box of the regions whose value range can
    /// contribute (contains iso / meets the band). Everything outside it is skipped anyway;
    /// the strategies that track the side of skipped space take an entry sample in the first
    /// region they process, so nothing is lost by starting there.
    pub fn clip_to_active(&mut self, vol: &Volume) {
        let (lo, hi) = self.tf.band();
        // Nothing can contribute: an empty box (min > max) that no ray enters.
        self.clip = Some(vol.active_box(self.field, lo, hi));
    }

    /// The settings of these parameters that decide the acceleration their rays need:
    /// field, iso value and band.
    pub fn accel_key(&self) -> AccelKey {
        AccelKey {
            field: self.field,
            iso: self.tf.iso,
            band: self.tf.band(),
        }
    }
}

/// Work counters of one or more rays (summed in integers: deterministic).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Stats {
    /// Reconstructions (samples, refinement probes, exact's dual-cell cubics).
    pub samples: u64,
    pub segments: u64,
    pub skipped: u64,
    /// `exact` segments through a region with more than
    /// [`MAX_LATTICES`](crate::lattice::MAX_LATTICES) distinct cell
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

/// Most sample positions in one region segment. With the smallest step
/// (`view_state::MIN_STEP`, a thousand per cell width) that is a thousand cells along one
/// segment; bricks are far smaller, so only a degenerate step or geometry reaches it.
pub(crate) const MAX_POSITIONS_PER_SEGMENT: u32 = 1 << 20;

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
        /// Which iso-surface (0: `iso`, 1…: `more_isos`); absent for the first.
        #[serde(skip_serializing_if = "Option::is_none")]
        surface: Option<u32>,
    },
    /// The part of the ray the clip planes keep (both infinite: none of it).
    Clip {
        t0: f64,
        t1: f64,
    },
    /// The ray meets slice `slice`, where the colour field has `value`.
    Slice {
        t: f64,
        slice: u32,
        value: f64,
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
    /// The region the hit was evaluated in, with a box within it (a hint for shading
    /// lookups near it).
    pub region: Option<RegionBox>,
}

#[inline]
fn at(o: &[f64; 3], d: &[f64; 3], t: f64) -> [f64; 3] {
    std::array::from_fn(|a| o[a] + t * d[a])
}

/// Casts rays through one volume with one set of parameters; keeps its scratch space.
pub struct Tracer<'v> {
    pub vol: &'v Volume<'v>,
    /// The trees the rays walk, built for the field and iso value of `params`.
    accel: &'v Accel,
    /// `accel`'s packed tree (taken once here, not at every ray).
    packed: Option<&'v crate::packed::Packed>,
    /// `accel`'s active tree, once an iso-surface ray has asked for it (a dvr tracer
    /// never builds it).
    active: Option<Option<&'v ActiveTree>>,
    pub params: Params,
    pub stats: Stats,
    /// Set to `Some` to record what the next rays do (`--pixel`).
    pub log: Option<Vec<Event>>,
    stack: Vec<(u32, f64, f64)>,
    /// Region of the last refinement probe.
    probe_hint: Option<RegionBox>,
    /// Where an iso-surface search starts walking the active tree for the next rays: set
    /// by the frame loop for each group of pixels (see [`Tracer::group_start`]), the root
    /// otherwise.
    start: Start,
    /// The bricks of the region `exact` is searching (scratch, refilled per region), and
    /// that region.
    bricks: Vec<crate::reconstruct::DualBrick>,
    bricks_of: Option<u32>,
    /// One frame over ranks (`crate::parts`): the regions (by index) this rank searches;
    /// the others are another rank's, and a walk steps over them. `None`: all.
    owned: Option<&'v [bool]>,
    /// With `owned`, per inner node of the active tree, whether it leads to an owned
    /// region (`ActiveTree::owned_nodes`): the walk steps over the others' subtrees.
    owned_nodes: Option<&'v [bool]>,
    /// The regions whose values this tracer read while `owned` is set (a region may be
    /// listed more than once): what a rank's report counts.
    pub(crate) touched: Vec<u32>,
}

impl<'v> Tracer<'v> {
    /// A tracer of rays with `params` through `vol`, walking the trees of `accel`, which
    /// must be an acceleration of `vol` for the field and iso value of `params` (the key
    /// [`Params::accel_key`] gives; the clip box is `params.clip`'s business).
    pub fn new(vol: &'v Volume<'v>, accel: &'v Accel, params: Params) -> Self {
        // The same iso value: equal, or both NaN (a key is compared with `==`, so a NaN
        // key is never shared, but it still describes its own tracer).
        let (key, iso) = (accel.key(), params.tf.iso);
        debug_assert!(
            key.field == params.field && (key.iso == iso || (key.iso.is_nan() && iso.is_nan())),
            "an acceleration for {key:?} traced with field {} at iso {iso}",
            params.field,
        );
        Tracer {
            vol,
            accel,
            packed: accel.packed(vol),
            active: None,
            params,
            stats: Stats::default(),
            log: None,
            stack: Vec::with_capacity(64),
            probe_hint: None,
            start: Start::Root,
            bricks: Vec::new(),
            bricks_of: None,
            owned: None,
            owned_nodes: None,
            touched: Vec::new(),
        }
    }

    /// Searches only the regions `owned` marks (one rank's share of a frame over ranks,
    /// see `crate::parts`); the iso search is the only one that supports it.
    pub(crate) fn restrict(&mut self, owned: &'v [bool], nodes: Option<&'v [bool]>) {
        self.owned = Some(owned);
        self.owned_nodes = nodes;
    }

    /// Whether region `r` is this tracer's to search.
    #[inline]
    fn owns(&self, r: u32) -> bool {
        self.owned
            .is_none_or(|o| o.get(r as usize).copied().unwrap_or(false))
    }

    /// Notes that the values of region `r` were read (only counted for a rank's share).
    #[inline]
    fn touch(&mut self, r: u32) {
        if self.owned.is_some() {
            self.touched.push(r);
        }
    }

    /// Where iso-surface walks can start for rays inside `frustum` (the pixels of one
    /// group, see [`ActiveTree::start_in`]). dvr walks the file's tree: for it, the root.
    pub(crate) fn group_start(&mut self, frustum: &crate::camera::Frustum) -> Start {
        if self.params.tf.mode != Mode::Iso {
            return Start::Root;
        }
        match self.active_walk().0 {
            Some(tree) => tree.start_in(frustum),
            None => Start::Root,
        }
    }

    /// Where the next rays' walks start: a [`Tracer::group_start`] of this tracer for a
    /// frustum that holds them, or the root.
    pub(crate) fn set_start(&mut self, start: Start) {
        self.start = start;
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

    pub(crate) fn record(&mut self, e: Event) {
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

    /// The active tree of the view's iso value, and where the next ray's walk starts in it
    /// (the group start the frame loop set, found in the same tree).
    fn active_walk(&mut self) -> (Option<&'v ActiveTree>, Start) {
        let (accel, vol) = (self.accel, self.vol);
        let tree = *self.active.get_or_insert_with(|| accel.active_tree(vol));
        (tree, self.start)
    }

    /// The file's tree packed with the iso field's ranges, for walks that skip by them.
    fn packed(&self) -> Option<&'v crate::packed::Packed> {
        self.packed
    }

    /// Counts (and logs) the stretch `[t0, t1]` of the data that a walk of the active tree
    /// steps over: no region there can hold the iso value.
    fn enter_gap(&mut self, t0: f64, t1: f64) {
        self.enter_segment(
            &crate::traverse::Segment {
                region: crate::traverse::SKIPPED,
                t0,
                t1,
                min: f32::NAN,
                max: f32::NAN,
            },
            true,
        );
    }

    /// Value at any local point (probe during refinement, regions found by KD descent).
    fn probe(&mut self, p: [f64; 3]) -> Option<f64> {
        self.stats.samples += 1;
        let vol = self.vol;
        // Refinement probes cluster: try the region of the previous probe before a KD descent.
        let r = match self.probe_hint {
            Some(h) if (h.region as usize) < vol.region_count() && h.holds(&p) => h.region,
            _ => {
                let h = vol.region_box_at(p)?;
                self.probe_hint = Some(h);
                h.region
            }
        };
        vol.eval_value(r as usize, p, self.params.field)
    }
}

/// The stretches of the data between the leaves a walk of the active tree visits, counted
/// (and logged) as skipped, as the file's walk reports the subtrees it steps over.
struct Gaps {
    /// The ray's interval inside the data.
    data: Option<(f64, f64)>,
    /// How far along the ray the walk has accounted for.
    covered: Option<f64>,
}

impl Gaps {
    fn new(vol: &Volume, o: &[f64; 3], d: &[f64; 3], t0: f64, t1: f64) -> Gaps {
        let data = crate::traverse::ray_box(
            &vol.bounds_min,
            &vol.bounds_max,
            o,
            &crate::traverse::inverse(d),
            t0,
            t1,
        );
        Gaps {
            data,
            covered: data.map(|(a, _)| a),
        }
    }

    /// Before the walk's segment `seg`: the stretch since the last one.
    fn before(&mut self, tracer: &mut Tracer, seg: &crate::traverse::Segment) {
        if let Some(c) = self.covered.filter(|&c| seg.t0 > c) {
            tracer.enter_gap(c, seg.t0);
        }
        self.covered = Some(self.covered.map_or(seg.t1, |c| c.max(seg.t1)));
    }

    /// After a walk that went to its end: the stretch to the end of the data.
    fn finish(&self, tracer: &mut Tracer) {
        if let (Some((_, end)), Some(c)) = (self.data, self.covered) {
            if end > c {
                tracer.enter_gap(c, end);
            }
        }
    }
}

/// Bisection depth that narrows `len` (world units) to `BISECT_RESOLUTION` cells of width `w`.
fn bisect_depth(len: f64, w: f64) -> u32 {
    let r = (len / w / BISECT_RESOLUTION).max(1.0);
    (r.log2().ceil() as u32).clamp(1, 40)
}
