//! Whole images: which rays to cast and where their colours go.
//!
//! A frame is a list of tiles times a range of sample indices. Tiles run in parallel on a
//! [`Renderer`]'s persistent rayon pool; each finished tile goes to a sink (the film of a
//! headless render, or the progressive viewer's display), and a [`CancelToken`] stops a
//! frame that a newer view has made stale between tile rows. Every pixel is a pure
//! function of the scene, its coordinates, the sample index and the seed (see
//! [`crate::ray`]), and work counters are summed as integers, so the image and the
//! statistics are the same whatever the number of threads or the order of the tiles.

use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;

use crate::active::Start;
use crate::fields::UnknownField;
use crate::film::Film;
use crate::mesh::Meshes;
use crate::ray::RayCaster;
use crate::sampling::{Event, Stats, Strategy};
use crate::transfer::Mode;
use crate::view_state::{ViewCommand, ViewState};
use crate::volume::Volume;

pub use crate::ray::jitter;
pub use crate::scene::Scene;
pub use crate::tiles::{tiles, Tile, TileResult};

/// Edge in pixels of the groups whose rays share one start in the active tree
/// (`Tracer::group_start`): small enough that most groups beside a
/// thin surface see none of it, large enough that finding the start costs little per ray.
const GROUP: u32 = 4;

/// What the rays of one group of pixels may meet, from the group's frustum.
#[derive(Debug, Clone, Copy)]
struct Group {
    /// Where their walks start in the active tree.
    start: Start,
    /// Where they search the meshes' tree (`None`: the frustum misses every triangle's
    /// box).
    mesh_start: Option<u32>,
    /// For a group whose pixels take the background without a search (it sees no region
    /// that can hold the value and no mesh, in a view where nothing else can be met, see
    /// [`RayCaster::background_beside_surface`]): how its rays cross the data, which
    /// they count.
    beside: Option<Crossing>,
}

/// Whether the rays of a group of pixels cross the data's bounds (within the active box),
/// each stepping over one stretch of data where its walk starts nowhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Crossing {
    /// None of them: the frustum misses the bounds.
    None,
    /// Every one of them.
    All,
    /// Some may: each ray is tested.
    Some,
}

/// The part of the data's size by which its bounds are shrunk for [`Crossing::All`].
const CROSSING_MARGIN: f64 = 1e-6;

impl Crossing {
    /// How the rays through the pixels `x0..x1` × `y0..y1` of `scene`'s view, inside
    /// `frustum` (local frame), cross the data's bounds within the view's active box.
    ///
    /// All of them do when the rays through the rectangle's four corners cross that box
    /// shrunk by a millionth of its size: the rays of a rectangle that meet a
    /// convex box form a convex set (the directions from one eye, or the origins on one
    /// image plane, are affine in the pixel position), and one through a point of the
    /// shrunk box meets the whole box for a length of at least twice the margin, far
    /// more than the rounding of the box test along it (checked: the data lies within
    /// 1e8 margins of the rays' origins). Anything else is tested ray by ray.
    pub(crate) fn of(
        scene: &Scene,
        frustum: &crate::camera::Frustum,
        (x0, y0, x1, y1): (f64, f64, f64, f64),
    ) -> Crossing {
        let vol = scene.vol;
        // A ray's stretch is where it crosses both the data's bounds and the active box
        // (`Tracer::step_over_all`); an empty active box keeps nothing.
        let (mut lo, mut hi) = (vol.bounds_min, vol.bounds_max);
        if let Some((clo, chi)) = scene.params.clip {
            if (0..3).any(|a| clo[a] > chi[a]) {
                return Crossing::None;
            }
            for a in 0..3 {
                lo[a] = lo[a].max(clo[a]);
                hi[a] = hi[a].min(chi[a]);
            }
        }
        if (0..3).any(|a| lo[a] > hi[a]) || !frustum.may_meet(&lo, &hi) {
            return Crossing::None;
        }
        let size = (0..3).map(|a| hi[a] - lo[a]).fold(0.0f64, f64::max);
        let margin = CROSSING_MARGIN * size;
        let inner_lo: [f64; 3] = std::array::from_fn(|a| lo[a] + margin);
        let inner_hi: [f64; 3] = std::array::from_fn(|a| hi[a] - margin);
        if !(margin > 0.0 && margin.is_finite()) || (0..3).any(|a| inner_lo[a] >= inner_hi[a]) {
            return Crossing::Some;
        }
        let all = [(x0, y0), (x1, y0), (x0, y1), (x1, y1)]
            .into_iter()
            .all(|(x, y)| {
                let ray = scene.rays.ray(x, y);
                let o = vol.to_local(ray.origin.to_array());
                let d = ray.dir.to_array();
                // The farthest point of the data from this origin bounds every `t` the box
                // test meets (the other rays' origins lie between the corners').
                let reach = (0..8)
                    .map(|c| {
                        let p: [f64; 3] =
                            std::array::from_fn(|a| if c >> a & 1 == 1 { hi[a] } else { lo[a] });
                        (0..3).map(|a| (p[a] - o[a]).abs()).sum::<f64>()
                    })
                    .fold(0.0f64, f64::max);
                reach < 1e8 * margin
                    && crate::traverse::ray_box(
                        &inner_lo,
                        &inner_hi,
                        &o,
                        &crate::traverse::inverse(&d),
                        0.0,
                        f64::INFINITY,
                    )
                    .is_some_and(|(a, b)| b > a)
            });
        if all {
            Crossing::All
        } else {
            Crossing::Some
        }
    }
}

/// A rendered image (linear RGB in 0..=1 per pixel, row-major from the top-left).
#[derive(Debug, Clone)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[f32; 3]>,
    pub stats: Stats,
    pub rays: u64,
    /// Rays that hit the iso-surface (iso) or gathered opacity ≥ 0.01 (dvr).
    pub hits: u64,
    /// Per pixel (row-major), how many of its samples hit: what `bench` compares against
    /// a reference to count missed and false surfaces, which the colours alone cannot tell
    /// (a surface may be shaded like the background).
    pub pixel_hits: Vec<u32>,
    /// Per pixel, the distance along the first sample's ray to the first surface it met
    /// (iso-surface or mesh; infinite where none): the outline box hides behind it.
    pub depth: Vec<f32>,
    /// Per pixel, the colour field's value on the iso-surface the first sample met (NaN
    /// where it met none): the colour range of what is visible.
    pub surface_values: Vec<f32>,
}

/// Frames are equal when every pixel and counter is, NaN surface values included (a
/// pixel without a surface is the same in both).
impl PartialEq for Frame {
    fn eq(&self, o: &Frame) -> bool {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        (
            self.width,
            self.height,
            &self.rgb,
            self.stats,
            self.rays,
            self.hits,
        ) == (o.width, o.height, &o.rgb, o.stats, o.rays, o.hits)
            && self.pixel_hits == o.pixel_hits
            && bits(&self.depth) == bits(&o.depth)
            && bits(&self.surface_values) == bits(&o.surface_values)
    }
}

/// Tells a frame in flight to stop. Clones share the flag. It also counts the pixel rows
/// started under it, which shows how far a frame got (and that a cancel stops it).
#[derive(Debug, Clone, Default)]
pub struct CancelToken(Arc<(AtomicBool, AtomicU64)>);

impl CancelToken {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn cancel(&self) {
        self.0 .0.store(true, Ordering::Relaxed);
    }
    pub(crate) fn is_cancelled(&self) -> bool {
        self.0 .0.load(Ordering::Relaxed)
    }
    /// Pixel rows started so far by frames under this token.
    pub fn rows_started(&self) -> u64 {
        self.0 .1.load(Ordering::Relaxed)
    }
    /// Checked before every row: false once cancelled.
    fn start_row(&self) -> bool {
        if self.is_cancelled() {
            return false;
        }
        self.0 .1.fetch_add(1, Ordering::Relaxed);
        true
    }
}

/// Renders samples `samples` of every tile in `tiles` on the current rayon pool, handing
/// each finished tile to `sink` (from the worker threads, in any order). Tiles check
/// `cancel` before every pixel row: a cancelled frame stops within one row per worker,
/// and the unfinished tiles are not delivered. Returns whether every tile was delivered.
pub(crate) fn render_tiles(
    scene: &Scene,
    tiles: &[Tile],
    samples: Range<u32>,
    cancel: &CancelToken,
    sink: &(dyn Fn(TileResult) + Sync),
) -> bool {
    // The view's trees are built here, the active tree's masks on all the pool's
    // threads, before the tiles' rays walk them (a no-op once a frame of the view has).
    scene.accel.prepare(scene.vol, scene.params.tf.mode);
    for s in &scene.more_surfaces {
        s.accel.prepare(scene.vol, scene.params.tf.mode);
    }
    tiles.par_iter().all(|&tile| {
        if cancel.is_cancelled() {
            return false;
        }
        let mut caster = RayCaster::new(scene);
        let n = ((tile.x1 - tile.x0) * (tile.y1 - tile.y0)) as usize;
        let mut sum = Vec::with_capacity(n);
        let mut hit_samples = Vec::with_capacity(n);
        let first_wave = samples.start == 0 && !samples.is_empty();
        let mut first = Vec::with_capacity(if first_wave { n } else { 0 });
        // Where the walks of each group of pixels start (every sample of a group's pixels,
        // at any sub-pixel offset, is a ray through its rectangle).
        let frame = DVec3::from_array(scene.vol.frame);
        let groups_x = (tile.x1 - tile.x0).div_ceil(GROUP);
        let beside = caster.background_beside_surface();
        let groups: Vec<Group> = tile
            .groups(GROUP)
            .map(|rect| {
                let frustum = scene.rays.frustum(rect.0, rect.1, rect.2, rect.3, frame);
                // The meshes are placed in world coordinates.
                let mesh_start = if scene.meshes.is_empty() {
                    None
                } else {
                    let world = scene
                        .rays
                        .frustum(rect.0, rect.1, rect.2, rect.3, DVec3::ZERO);
                    scene.meshes.start_in(&world)
                };
                let start = caster.main.group_start(&frustum);
                let walkless = beside && start == Start::Nothing && mesh_start.is_none();
                Group {
                    start,
                    mesh_start,
                    beside: walkless.then(|| Crossing::of(scene, &frustum, rect)),
                }
            })
            .collect();
        for y in tile.y0..tile.y1 {
            if !cancel.start_row() {
                return false;
            }
            for x in tile.x0..tile.x1 {
                let group = (y - tile.y0) / GROUP * groups_x + (x - tile.x0) / GROUP;
                let g = groups[group as usize];
                caster.main.set_start(g.start);
                caster.set_mesh_start(g.mesh_start);
                let mut c = [0.0f64; 3];
                let hits_before = caster.hits;
                for s in samples.clone() {
                    let v = match g.beside {
                        Some(crossing) => caster.sample_beside_surface(x, y, s, crossing),
                        None => caster.sample(x, y, s),
                    };
                    if s == 0 {
                        first.push(caster.first);
                    }
                    for a in 0..3 {
                        c[a] += v[a];
                    }
                }
                sum.push(c);
                // A sample adds at most one hit (shadow rays are not counted).
                hit_samples.push((caster.hits - hits_before) as u32);
            }
        }
        sink(TileResult {
            tile,
            samples: samples.clone(),
            sum,
            hit_samples,
            first,
            stats: caster.stats(),
            rays: caster.rays,
            hits: caster.hits,
        });
        true
    })
}

/// Work counters of a frame, summed over its tiles.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    pub stats: Stats,
    pub rays: u64,
    pub hits: u64,
}

impl Counts {
    pub(crate) fn add(&mut self, r: &TileResult) {
        self.stats += r.stats;
        self.rays += r.rays;
        self.hits += r.hits;
    }
}

/// Renders the whole image on the current rayon pool.
pub fn render(scene: &Scene) -> Frame {
    render_under(scene, &CancelToken::new()).0
}

/// [`render`] under `cancel`: `None` when it was cancelled before every tile was done
/// (the Python module's Ctrl-C).
pub fn render_cancellable(scene: &Scene, cancel: &CancelToken) -> Option<Frame> {
    let (frame, done) = render_under(scene, cancel);
    done.then_some(frame)
}

/// The frame, and whether every tile of it was rendered (not cancelled).
fn render_under(scene: &Scene, cancel: &CancelToken) -> (Frame, bool) {
    let (w, h) = (scene.state.width, scene.state.height);
    let acc = Mutex::new((Film::one_pass(w, h), Counts::default()));
    let sink = |r: TileResult| {
        // A poisoned lock only means another tile panicked; its panic propagates anyway.
        let mut g = acc.lock().unwrap_or_else(|e| e.into_inner());
        g.0.add(&r);
        g.1.add(&r);
    };
    let done = render_tiles(
        scene,
        &tiles(w, h),
        0..scene.state.spp.max(1),
        cancel,
        &sink,
    );
    let (film, counts) = acc.into_inner().unwrap_or_else(|e| e.into_inner());
    let parts = film.into_parts();
    let frame = Frame {
        width: w,
        height: h,
        rgb: parts.rgb,
        pixel_hits: parts.hits,
        depth: parts.depth,
        surface_values: parts.values,
        stats: counts.stats,
        rays: counts.rays,
        hits: counts.hits,
    };
    (frame, done)
}

/// Niceness of [`Renderer::background`]'s workers: each step of niceness weighs a thread
/// about 1.25 times less for Linux's scheduler, so at 5 a busy UI thread gets about three
/// times a worker's share of a core, while the workers still have the rest of it.
pub const BACKGROUND_NICENESS: i8 = 5;

/// Lowers the calling thread's priority to [`BACKGROUND_NICENESS`] (Linux), or leaves it.
pub(crate) fn lower_priority() {
    #[cfg(target_os = "linux")]
    {
        use thread_priority::unix::{
            set_thread_priority_and_policy, thread_native_id, NormalThreadSchedulePolicy,
            ThreadSchedulePolicy,
        };
        use thread_priority::{ThreadPriority, ThreadPriorityValue};
        // The crate maps its 0..=99 scale onto niceness 19..=-20 as
        // `(39 · (1 − p/99)) as i8 − 20`: 35 is niceness 5 (the test below reads it back).
        if let Ok(p) = ThreadPriorityValue::try_from(35u8) {
            let _ = set_thread_priority_and_policy(
                thread_native_id(),
                ThreadPriority::Crossplatform(p),
                ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Other),
            );
        }
    }
}

/// The view `--colour-range visible` renders first to see which surfaces show: `state`
/// at one sample per pixel.
pub fn visible_range_view(state: &ViewState) -> ViewState {
    let mut first = state.clone();
    first.spp = 1;
    first
}

/// Applies `scale` (a [`ViewCommand::ColourScale`] over the given range) to `state` with the
/// colour field's range over the surface pixels of `frame` (a render of
/// [`visible_range_view`]); returns that range, `None` when no surface shows.
pub fn fit_colours_to_frame(
    frame: &Frame,
    vol: &Volume,
    state: &mut ViewState,
    scale: impl Fn(Option<(f32, f32)>) -> Option<ViewCommand>,
) -> Result<Option<(f32, f32)>, UnknownField> {
    let range = crate::colormap::visible_range(&frame.surface_values);
    if let Some(command) = range.and_then(|r| scale(Some(r))) {
        state.apply(&command, &vol.fields)?;
    }
    Ok(range)
}

/// A persistent pool of render threads (building a pool costs more than a small frame).
pub struct Renderer {
    pool: rayon::ThreadPool,
}

impl Renderer {
    /// A pool of `threads` workers (`None` or 0: one per core).
    pub fn new(threads: Option<usize>) -> Result<Renderer, rayon::ThreadPoolBuildError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.unwrap_or(0))
            .thread_name(|i| format!("qbricks-render-{i}"))
            .build()?;
        Ok(Renderer { pool })
    }

    /// A pool of `threads` workers that yield to the process's other threads: each runs
    /// below normal priority (niceness [`BACKGROUND_NICENESS`] on Linux), so that a window
    /// drawing its frames on a machine the renderer keeps busy is served first. Where the
    /// priority cannot be lowered the workers run at normal priority.
    pub fn background(threads: Option<usize>) -> Result<Renderer, rayon::ThreadPoolBuildError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.unwrap_or(0))
            .thread_name(|i| format!("qbricks-render-{i}"))
            .start_handler(|_| lower_priority())
            .build()?;
        Ok(Renderer { pool })
    }

    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// [`render`] on this pool.
    pub fn render(&self, scene: &Scene) -> Frame {
        self.pool.install(|| render(scene))
    }

    /// [`render_cancellable`] on this pool.
    pub fn render_cancellable(&self, scene: &Scene, cancel: &CancelToken) -> Option<Frame> {
        self.pool.install(|| render_cancellable(scene, cancel))
    }

    /// `--colour-range visible`: renders `state` once (one sample per pixel, enough to
    /// see which surfaces show) and applies `scale` (a [`ViewCommand::ColourScale`] over
    /// the given range) with the colour field's range over the surface pixels. Returns
    /// that range, or `None` when no surface shows (the map is then left as it was).
    pub fn fit_colours_to_visible(
        &self,
        vol: &Volume,
        state: &mut ViewState,
        meshes: &Meshes,
        scale: impl Fn(Option<(f32, f32)>) -> Option<ViewCommand>,
    ) -> Result<Option<(f32, f32)>, UnknownField> {
        let first = visible_range_view(state);
        let frame = self.render(&Scene::new(vol, &first, meshes)?);
        fit_colours_to_frame(&frame, vol, state, scale)
    }

    /// Runs `f` on this pool.
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pool.install(f)
    }

    /// [`render_tiles`] on this pool.
    pub fn render_tiles(
        &self,
        scene: &Scene,
        tiles: &[Tile],
        samples: Range<u32>,
        cancel: &CancelToken,
        sink: &(dyn Fn(TileResult) + Sync),
    ) -> bool {
        self.pool
            .install(|| render_tiles(scene, tiles, samples, cancel, sink))
    }

    /// [`trace_pixel`] on this pool.
    pub fn trace_pixel(&self, scene: &Scene, x: u32, y: u32) -> PixelTrace {
        self.pool.install(|| trace_pixel(scene, x, y))
    }
}

/// What `render --json` prints about a frame: timing, work per ray, hits.
#[derive(Debug, Clone, Serialize)]
pub struct FrameReport {
    /// Wall time of one frame (the median when repeated), ms.
    pub ms: f64,
    /// Opening the file and building the volume tables, ms.
    pub open_ms: f64,
    pub rays: u64,
    pub samples_per_ray: f64,
    pub segments_per_ray: f64,
    pub skipped_per_ray: f64,
    pub mrays_per_s: f64,
    pub hit_fraction: f64,
    pub width: u32,
    pub height: u32,
    pub strategy: &'static str,
    pub mode: &'static str,
    pub threads: usize,
    /// `exact` segments through regions with more cell lattices than it cuts planes for
    /// (`sampling::MAX_LATTICES`), where the search was only approximately exact; 0 for
    /// nested grids of one refinement ratio.
    pub inexact_segments: u64,
    /// Segments whose samples stopped early because the step no longer advanced along the
    /// ray or hit the per-segment cap (`sampling::MAX_POSITIONS_PER_SEGMENT`).
    pub truncated_segments: u64,
}

impl FrameReport {
    pub fn new(frame: &Frame, state: &ViewState, ms: f64, open_ms: f64, threads: usize) -> Self {
        let rays = frame.rays.max(1) as f64;
        FrameReport {
            ms,
            open_ms,
            rays: frame.rays,
            samples_per_ray: frame.stats.samples as f64 / rays,
            segments_per_ray: frame.stats.segments as f64 / rays,
            skipped_per_ray: frame.stats.skipped as f64 / rays,
            mrays_per_s: frame.rays as f64 / (ms * 1e3),
            hit_fraction: frame.hits as f64 / rays,
            width: frame.width,
            height: frame.height,
            strategy: state.effective_strategy().as_str(),
            mode: state.mode.as_str(),
            threads,
            inexact_segments: frame.stats.inexact_segments,
            truncated_segments: frame.stats.truncated_segments,
        }
    }
}

/// A debug buffer written instead of the shaded image (`render --aov`), taken at the
/// first iso-surface point of each pixel's centre ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Aov {
    /// Shading normal as `0.5 + 0.5·n` (world axes to red, green, blue).
    Normal,
    /// Distance along the ray, near bright, far dark, over the image's range of hits.
    Depth,
    /// Finest level contributing at the hit, one false colour per level (0 red, 1 green,
    /// 2 blue, 3 yellow, 4 magenta, 5 cyan, finer grey).
    Level,
    /// The colour map's colour of the colour field at the hit, unshaded.
    Value,
}

/// What an AOV pixel's centre ray found at the first surface point.
#[derive(Debug, Clone, Copy)]
struct AovHit {
    /// Distance along the ray.
    t: f64,
    normal: [f64; 3],
    /// The finest level contributing there.
    level: Option<u32>,
    /// The colour field's value there.
    value: Option<f64>,
}

const LEVEL_COLOURS: [[f32; 3]; 6] = [
    [0.9, 0.2, 0.2],
    [0.2, 0.8, 0.3],
    [0.25, 0.4, 0.95],
    [0.95, 0.85, 0.2],
    [0.85, 0.3, 0.85],
    [0.3, 0.85, 0.9],
];

/// The first surface point of each pixel's centre ray, row-major (`None`: no surface): what
/// every debug buffer (`--aov`) is made of, as a picture or as numbers.
pub struct AovTrace {
    width: u32,
    height: u32,
    hits: Vec<Option<AovHit>>,
}

impl AovTrace {
    /// Traces the view's centre rays. In dvr mode the surface is the iso value's, found
    /// with `exact`.
    pub fn new(scene: &Scene) -> AovTrace {
        AovTrace {
            width: scene.state.width,
            height: scene.state.height,
            hits: aov_hits(scene),
        }
    }

    /// The `aov` buffer as a picture of `scene` (misses show its background).
    pub fn picture(&self, scene: &Scene, aov: Aov) -> Frame {
        let (w, h) = (self.width, self.height);
        let pixels = &self.hits;
        let ts = pixels.iter().flatten().map(|p| p.t);
        let (tmin, tmax) = ts.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), t| {
            (a.min(t), b.max(t))
        });
        let span = (tmax - tmin).max(1e-300);
        let mut hits = 0;
        let mut pixel_hits = Vec::with_capacity(pixels.len());
        let mut depth = Vec::with_capacity(pixels.len());
        let rgb = pixels
            .iter()
            .map(|px| match px {
                Some(p) => {
                    hits += 1;
                    pixel_hits.push(1);
                    depth.push(p.t as f32);
                    match aov {
                        Aov::Normal => p.normal.map(|v| (0.5 + 0.5 * v) as f32),
                        Aov::Depth => [(1.0 - 0.85 * (p.t - tmin) / span) as f32; 3],
                        Aov::Level => p.level.map_or([0.5; 3], |l| {
                            LEVEL_COLOURS.get(l as usize).copied().unwrap_or([0.6; 3])
                        }),
                        Aov::Value => p
                            .value
                            .map_or([0.8; 3], |v| scene.state.colormap.colour(v as f32)),
                    }
                }
                None => {
                    pixel_hits.push(0);
                    depth.push(f32::INFINITY);
                    scene.state.background
                }
            })
            .collect();
        let surface_values = vec![f32::NAN; depth.len()];
        Frame {
            width: w,
            height: h,
            rgb,
            stats: Stats::default(),
            rays: u64::from(w) * u64::from(h),
            hits,
            pixel_hits,
            depth,
            surface_values,
        }
    }

    pub fn values(&self, aov: Aov) -> AovValues {
        let channels = if aov == Aov::Normal { 3 } else { 1 };
        let mut values = Vec::with_capacity(self.hits.len() * channels);
        for px in &self.hits {
            match (aov, px) {
                (Aov::Normal, Some(p)) => values.extend(p.normal.map(|v| v as f32)),
                (Aov::Normal, None) => values.extend([f32::NAN; 3]),
                (Aov::Depth, p) => values.push(p.map_or(f32::INFINITY, |p| p.t as f32)),
                (Aov::Level, p) => {
                    values.push(p.and_then(|p| p.level).map_or(f32::NAN, |l| l as f32))
                }
                (Aov::Value, p) => {
                    values.push(p.and_then(|p| p.value).map_or(f32::NAN, |v| v as f32))
                }
            }
        }
        AovValues {
            width: self.width,
            height: self.height,
            channels,
            values,
        }
    }
}

/// The `aov` buffer of the view as numbers, for analysis (the Python module's `aov=`):
/// per pixel, row-major, `channels` values at the first surface point of its centre ray —
/// the unit normal (3), the distance along the ray (1, infinite on a miss), the finest
/// level there (1) or the colour field's value (1); NaN on a miss otherwise.
pub struct AovValues {
    pub width: u32,
    pub height: u32,
    pub channels: usize,
    pub values: Vec<f32>,
}

fn aov_hits(scene: &Scene) -> Vec<Option<AovHit>> {
    let mut iso_scene = Scene {
        vol: scene.vol,
        state: scene.state,
        meshes: scene.meshes,
        params: scene.params,
        rays: scene.rays,
        shading: scene.shading,
        accel: Arc::clone(&scene.accel),
        // The buffers are of the first surface, where the clip planes leave it.
        more_surfaces: Vec::new(),
        first_style: scene.first_style,
        cuts: scene.cuts.clone(),
    };
    if iso_scene.params.tf.mode == Mode::Dvr {
        iso_scene.params.tf.mode = Mode::Iso;
        iso_scene.params.strategy = Strategy::Exact;
    }
    let (w, h) = (scene.state.width, scene.state.height);
    let vol = scene.vol;
    let rows: Vec<Vec<Option<AovHit>>> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut caster = RayCaster::new(&iso_scene);
            (0..w)
                .map(|x| {
                    let (ray, jit) = caster.camera_ray(x, y, 0);
                    let s = caster.surface(&ray, jit)?;
                    let level = vol.region_at(s.local).and_then(|r| {
                        vol.region_brick_ids(r as usize)
                            .iter()
                            .map(|b| vol.brick(b.to_native()).level)
                            .min()
                    });
                    let value = match (scene.params.colour_field, s.eval) {
                        (Some(_), Some(e)) => Some(e.colour),
                        _ => None,
                    };
                    Some(AovHit {
                        t: (s.world - ray.origin).dot(ray.dir),
                        normal: s.normal.to_array(),
                        level,
                        value,
                    })
                })
                .collect()
        })
        .collect();
    rows.into_iter().flatten().collect()
}

/// Renders the `aov` buffer of the view as a picture (misses show the background).
pub fn render_aov(scene: &Scene, aov: Aov) -> Frame {
    AovTrace::new(scene).picture(scene, aov)
}

/// What `--pixel` reports about one pixel.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PixelTrace {
    pub x: u32,
    pub y: u32,
    pub colour: [f32; 3],
    /// Per sample (spp): the ray and what happened along it.
    pub rays: Vec<RayTrace>,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct RayTrace {
    pub origin: [f64; 3],
    pub dir: [f64; 3],
    pub jitter: f64,
    pub events: Vec<Event>,
}

/// Renders one pixel and records its rays' region segments, samples and hits
/// (`t` along each unit-length ray from its origin).
pub(crate) fn trace_pixel(scene: &Scene, x: u32, y: u32) -> PixelTrace {
    let spp = scene.state.spp.max(1);
    let mut caster = RayCaster::new(scene);
    let mut rays = Vec::new();
    let mut sum = [0.0f64; 3];
    for s in 0..spp {
        let (ray, jit) = caster.camera_ray(x, y, s);
        caster.main.log = Some(Vec::new());
        let c = caster.trace(&ray, jit);
        for a in 0..3 {
            sum[a] += c[a];
        }
        rays.push(RayTrace {
            origin: ray.origin.to_array(),
            dir: ray.dir.to_array(),
            jitter: jit,
            events: in_ray_order(caster.main.log.take().unwrap_or_default()),
        });
    }
    PixelTrace {
        x,
        y,
        colour: sum.map(|c| (c / spp as f64) as f32),
        rays,
    }
}

/// `events` sorted by where they happen along the ray (stably: events at one place keep
/// their order), the clip interval first: the walks of several iso-surfaces' searches
/// are logged one after the other, but they are read as one ray.
fn in_ray_order(mut events: Vec<Event>) -> Vec<Event> {
    let at = |e: &Event| match *e {
        Event::Clip { .. } => f64::NEG_INFINITY,
        Event::Segment { t0, .. } | Event::Interval { t0, .. } => t0,
        Event::Sample { t, .. } | Event::Hit { t, .. } | Event::Slice { t, .. } => t,
    };
    events.sort_by(|a, b| at(a).total_cmp(&at(b)));
    events
}

/// Renders on a pool of `threads` workers (0: all cores).
pub fn render_with_threads(
    scene: &Scene,
    threads: usize,
) -> Result<Frame, rayon::ThreadPoolBuildError> {
    Ok(Renderer::new(Some(threads))?.render(scene))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{Camera, Projection};

    /// The niceness of the calling thread, from `/proc/thread-self/stat` (field 19).
    #[cfg(target_os = "linux")]
    fn own_niceness() -> i64 {
        let stat = std::fs::read_to_string("/proc/thread-self/stat").expect("stat");
        // The command name (field 2) is in parentheses and may hold spaces.
        let after = &stat[stat.rfind(')').expect("comm") + 2..];
        after
            .split(' ')
            .nth(16)
            .expect("field 19")
            .parse()
            .expect("nice")
    }

    /// The window's render workers run below the priority of the thread that made them
    /// (the UI); the CLI's run at it.
    #[cfg(target_os = "linux")]
    #[test]
    fn background_workers_run_below_normal_priority() {
        let own = own_niceness();
        let bg = Renderer::background(Some(2)).expect("pool");
        let nices: Vec<i64> = bg.install(|| rayon::broadcast(|_| own_niceness()));
        assert_eq!(nices, vec![own.max(i64::from(BACKGROUND_NICENESS)); 2]);
        let normal = Renderer::new(Some(2)).expect("pool");
        assert_eq!(
            normal.install(|| rayon::broadcast(|_| own_niceness())),
            vec![own; 2]
        );
    }
    use crate::mesh::Meshes;
    use crate::testvol;
    use crate::volume::Volume;

    /// A frame whose pixel groups start their walks below the root (or skip them) has
    /// the colours and the work counters of the same pixels traced one by one from the
    /// root, with one and with four samples per pixel (jittered rays reach the groups'
    /// edges), from outside and from inside the data.
    /// The frame's surface buffers hold, per pixel, the distance to the surface its first
    /// sample met and the colour field there (what the outline box hides behind and what
    /// `--colour-range visible` spreads the map over); misses hold infinity and NaN.
    #[test]
    fn surface_buffers_hold_the_first_hit_and_its_colour() {
        let dist = |p: [f64; 3]| {
            ((p[0] - 16.0).powi(2) + (p[1] - 16.0).powi(2) + (p[2] - 16.0).powi(2)).sqrt()
        };
        let z = |p: [f64; 3]| p[2];
        let file = testvol::nested(16, [0.0; 3], &[("d", &dist), ("z", &z)], 8);
        let view = testvol::open(&file).expect("open");
        let vol = Volume::new(&view).expect("volume");
        let meshes = Meshes::empty();
        let mut st = ViewState::default_for_volume(&vol);
        st.iso_field = "d".into();
        st.colormap.field = "z".into();
        st.iso = 6.0;
        st.width = 31;
        st.height = 31;
        st.spp = 2;
        st.camera = Camera {
            eye: [16.0, 16.0, 60.0],
            look_at: [16.0, 16.0, 16.0],
            up: [0.0, 1.0, 0.0],
            projection: Projection::Orthographic { width: 20.0 },
        };
        let scene = Scene::new(&vol, &st, &meshes).expect("scene");
        let frame = render(&scene);
        let mut hits = 0;
        for (i, (&t, &v)) in frame.depth.iter().zip(&frame.surface_values).enumerate() {
            if frame.pixel_hits[i] == 0 {
                continue;
            }
            if t.is_finite() {
                hits += 1;
                // Looking down -z from z = 60: the hit's z is 60 - t, and z is the colour.
                assert!((v - (60.0 - t)).abs() < 0.05, "pixel {i}: t {t}, z {v}");
                // The upper half of the sphere of radius 6 around z = 16 faces the camera.
                assert!(v > 15.9 && v < 22.1, "pixel {i}: z {v}");
            }
        }
        assert!(hits > 200, "{hits} hits");
        // The centre pixel sees the sphere's top at z = 22.
        let c = 15 * 31 + 15;
        assert!((frame.depth[c] - 38.0).abs() < 0.05, "{}", frame.depth[c]);
        // A corner ray misses: no distance, no value.
        assert!(frame.depth[0].is_infinite() && frame.surface_values[0].is_nan());
        let (lo, hi) = crate::colormap::visible_range(&frame.surface_values).expect("range");
        assert!(lo > 15.9 && hi < 22.1 && hi - lo > 3.0, "{lo}..{hi}");
        // `--colour-range visible`: the map is spread over that range (found with the
        // pixel centres' rays, where this frame's first samples were jittered).
        drop(scene);
        let renderer = Renderer::new(Some(1)).expect("pool");
        let scale = |r: Option<(f32, f32)>| {
            Some(ViewCommand::ColourScale {
                palette: "viridis".parse().expect("palette"),
                range: r,
                centre: None,
                log: false,
            })
        };
        let fitted = renderer
            .fit_colours_to_visible(&vol, &mut st, &meshes, scale)
            .expect("fit");
        let (flo, fhi) = fitted.expect("a range");
        assert!(
            (flo - lo).abs() < 0.2 && (fhi - hi).abs() < 0.2,
            "{flo}..{fhi}"
        );
        assert_eq!(st.colormap.range(), (flo, fhi));
        assert_eq!(st.colormap.field, "z");
        // Nothing in view: the map stays.
        st.iso = 100.0;
        let before = st.colormap.clone();
        let none = renderer
            .fit_colours_to_visible(&vol, &mut st, &meshes, scale)
            .expect("fit");
        assert_eq!((none, &st.colormap), (None, &before));
    }

    /// A frame whose groups of rays start their walks below the root, or skip them
    /// ([`Start::Nothing`]: those rays take `sample_beside_surface` where nothing else can
    /// be met), and search the meshes from where their frustum allows, has the pixels,
    /// depths and counters of every ray traced alone from the root: one, two and four
    /// samples, `exact`, `uniform` and `bisect`, from outside and from within the data,
    /// with a sphere and a clip plane that rays beside the surface meet (there the
    /// walk-less path must not be taken), and groups beside the surface whose rays cross
    /// no data, all cross it, or some do ([`Crossing`]).
    #[test]
    fn group_starts_change_no_pixel_and_no_counter() {
        let field =
            |p: [f64; 3]| (p[0] / 4.0).sin() * (p[1] / 5.0).cos() + 0.3 * (p[2] / 3.0).sin();
        let file = testvol::nested(16, [0.0; 3], &[("q", &field), ("speed", &field)], 8);
        let view = testvol::open(&file).expect("open");
        let vol = Volume::new(&view).expect("volume");
        let none = Meshes::empty();
        // A sphere above the data ([0, 32]³), seen by rays that pass over it; a clip
        // plane that keeps x > 20, behind which rays that enter the data's side y = 0
        // cross all of theirs.
        let sphere = Meshes::from_meshes(&[crate::mesh::icosphere(
            glam::DVec3::new(16.0, 16.0, 38.0),
            4.0,
            2,
        )]);
        let clip = crate::planes::Plane {
            origin: [20.0, 16.0, 16.0],
            normal: [1.0, 0.0, 0.0],
        };
        let (mut started_below, mut walked_nowhere) = (0, 0);
        let (mut sphere_seen, mut sphere_missed) = (0, 0);
        // Groups that start nowhere whose rays cross no data, all cross it, some may.
        let mut crossings = [0; 3];
        // (The last five take a value held in few places, so that rays beside the surface
        // cross data.)
        let (out, exact) = ([50.0, -30.0, 40.0], Strategy::Exact);
        let cases = [
            (out, 1, &none, None, 0.4, exact),
            ([14.0, 15.0, 16.0], 4, &none, None, 0.4, exact),
            (out, 1, &sphere, None, 0.4, exact),
            (out, 1, &none, Some(clip), 1.25, exact),
            (out, 1, &none, None, 1.25, exact),
            (out, 1, &none, None, 1.25, Strategy::Uniform),
            (out, 2, &sphere, None, 1.25, Strategy::Bisect),
            ([14.0, 15.0, 16.0], 1, &none, None, 1.25, exact),
        ];
        for (eye, spp, meshes, clip, iso, strategy) in cases {
            let mut st = ViewState::default_for_volume(&vol);
            st.width = 37;
            st.height = 29;
            st.iso = iso;
            st.spp = spp;
            st.strategy = strategy;
            st.clip = clip.into_iter().collect();
            st.camera = Camera {
                eye,
                look_at: [16.0, 16.0, 16.0],
                up: [0.0, 0.0, 1.0],
                projection: Projection::Perspective { fov_deg: 50.0 },
            };
            let scene = Scene::new(&vol, &st, meshes).expect("scene");
            let frame = render(&scene);
            let mut caster = RayCaster::new(&scene);
            let mut rgb = Vec::new();
            for y in 0..st.height {
                for x in 0..st.width {
                    let mut c = [0.0f64; 3];
                    for s in 0..spp {
                        let v = caster.sample(x, y, s);
                        for a in 0..3 {
                            c[a] += v[a];
                        }
                    }
                    rgb.push(c.map(|v| (v / f64::from(spp)) as f32));
                }
            }
            let case = format!(
                "eye {eye:?}, sphere {}, clip {clip:?}, iso {iso}, {strategy:?}",
                !meshes.is_empty()
            );
            assert!(frame.hits > 0 && frame.hits < frame.rays, "{case}");
            assert_eq!(frame.rgb, rgb, "{case}");
            assert_eq!(frame.depth, caster_depths(&scene), "{case}");
            assert_eq!(frame.stats, caster.stats(), "{case}");
            assert_eq!((frame.rays, frame.hits), (caster.rays, caster.hits));
            // The groups did start below the root somewhere, and some walked nowhere.
            let tree = scene.accel.active_tree(&vol).expect("tree");
            let f = glam::DVec3::from_array(vol.frame);
            for rect in crate::tiles::Tile::image(st.width, st.height).groups(GROUP) {
                let (x0, y0, x1, y1) = rect;
                let fr = scene.rays.frustum(x0, y0, x1, y1, f);
                let start = tree.start_in(&fr);
                started_below += usize::from(start != Start::Root);
                walked_nowhere += usize::from(start == Start::Nothing);
                if start == Start::Nothing {
                    crossings[Crossing::of(&scene, &fr, rect) as usize] += 1;
                }
                if let Some(b) = meshes.bounds() {
                    let world = scene.rays.frustum(x0, y0, x1, y1, glam::DVec3::ZERO);
                    match world.may_meet(&b.min, &b.max) {
                        true => sphere_seen += 1,
                        false => sphere_missed += 1,
                    }
                }
            }
        }
        assert!(
            started_below > 20 && walked_nowhere > 20,
            "{started_below} groups started below the root, {walked_nowhere} nowhere"
        );
        assert!(
            crossings.iter().all(|&n| n > 10),
            "groups beside the surface crossing no data, all, some: {crossings:?}"
        );
        // Groups that skipped the sphere's tree, and groups that tested it.
        assert!(
            sphere_seen > 5 && sphere_missed > 20,
            "{sphere_seen} groups may see the sphere, {sphere_missed} may not"
        );
    }

    /// The depth of the first thing each pixel's first ray meets, every ray traced alone.
    fn caster_depths(scene: &Scene) -> Vec<f32> {
        let st = scene.state;
        let mut caster = RayCaster::new(scene);
        let mut depth = Vec::new();
        for y in 0..st.height {
            for x in 0..st.width {
                caster.sample(x, y, 0);
                depth.push(caster.first.t);
            }
        }
        depth
    }
}
