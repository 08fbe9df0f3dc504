//! Progressive rendering off the caller's thread, for the interactive window.
//!
//! Each view the window asks for is a [`Job`] with a new generation number. A job first
//! renders a preview at a reduced resolution (the divisor adapts so a preview takes about
//! [`ProgressiveOptions::preview_ms`]), then the full resolution one sample wave after
//! another up to the view's `spp`. Submitting a job cancels a full-resolution frame in
//! flight (tiles check the cancel flag before every row); a preview in flight is let
//! finish, because while the user drags, every UI frame brings a new view, and
//! cancelling previews would show nothing until the drag ends. Intermediate images are
//! published as [`Update`]s; an update older than one already published is dropped, so a
//! stale frame never replaces a newer one, and full-resolution work is only ever
//! published for the newest job. The finished full-resolution image is the same,
//! pixel for pixel, as the headless [`crate::render::render`] of the same view state,
//! because both take each pixel's samples in the same order into a [`Film`] (summed wave
//! by wave here, in one pass there) and divide the same sum by the same count.
//!
//! The render thread keeps the accelerations of the last few views of the open file
//! ([`crate::accel::AccelCache`]), so that a view that only moves the camera (every frame of an orbit),
//! its preview and its full-resolution frame build no tree; the cache is the thread's own
//! and starts over when a job brings another file.
//!
//! Nothing here knows about egui: the window polls [`Progressive::latest`] and gets
//! woken through the `notify` callback.

use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::dataset::{Dataset, DatasetAccels};
use crate::fields::UnknownField;
use crate::film::Film;
use crate::mesh::Meshes;
use crate::preview_scale::PreviewScale;
use crate::render::{CancelToken, Counts, Renderer};
use crate::scene::Scene;
use crate::tiles::{tiles, TileResult};
use crate::view_state::ViewState;

/// One view to render.
#[derive(Clone)]
pub struct Job {
    pub dataset: Arc<Dataset>,
    pub meshes: Arc<Meshes>,
    pub state: ViewState,
    /// Show a reduced-resolution preview first (while the view is changing).
    pub preview: bool,
}

/// Which resolution an update shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// `1/scale` of the full resolution on each axis, one sample per pixel.
    Preview { scale: u32 },
    /// The view's own resolution.
    Full,
}

/// An image of the newest job, possibly unfinished.
#[derive(Debug, Clone)]
pub struct Update {
    pub generation: u64,
    pub level: Level,
    pub width: u32,
    pub height: u32,
    /// Linear RGB, row-major from the top left. Tiles of a full-resolution frame that
    /// are not rendered yet show the preview, scaled up.
    pub rgb: Arc<Vec<[f32; 3]>>,
    /// Sample waves finished at this level (every pixel has this many samples).
    pub samples: u32,
    /// The view's samples per pixel (the last wave's number).
    pub spp: u32,
    /// Work of this level so far.
    pub counts: Counts,
    /// Time spent rendering this level so far, ms.
    pub ms: f64,
    /// The full-resolution image with every sample: nothing more will come for this job.
    pub complete: bool,
    /// What the overlays of this image are drawn from (see [`Update::picture`]).
    pub view: Arc<ViewState>,
    /// The data's box, world coordinates.
    pub bounds: ([f64; 3], [f64; 3]),
    /// Per pixel of a full-resolution image whose first sample wave is finished, the
    /// distance to the first surface and the colour field there ([`crate::render::Frame`]).
    pub surface: Option<Arc<(Vec<f32>, Vec<f32>)>>,
}

impl Update {
    /// The picture of this image at the view's full size: 8-bit pixels (a preview scaled
    /// up) with the view's overlays, the outline hidden behind surfaces once their
    /// distances are known. What the window shows and Save image… writes.
    pub fn picture(&self) -> (u32, u32, Vec<u8>) {
        let (w, h) = (self.view.width.max(1), self.view.height.max(1));
        let mut rgb8 = if (self.width, self.height) == (w, h) {
            crate::film::to_rgb8(&self.rgb)
        } else {
            crate::film::to_rgb8(&upscale(&self.rgb, self.width, self.height, w, h))
        };
        let depth = self
            .surface
            .as_ref()
            .filter(|_| (self.width, self.height) == (w, h))
            .map(|s| s.0.as_slice());
        crate::overlay::annotate(&mut rgb8, w, h, &self.view, Some(self.bounds), depth, None);
        (w, h, rgb8)
    }
}

/// Tuning of [`Progressive`].
#[derive(Debug, Clone)]
pub struct ProgressiveOptions {
    /// Render threads (`None`: one per core).
    pub threads: Option<usize>,
    /// Time a preview should take, ms; the preview divisor adapts to it
    /// ([`PreviewScale`]). 30 ms with the UI's own frame beside it on two cores keeps 30
    /// previews a second or more on the benchmark views.
    pub preview_ms: f64,
    /// Smallest preview divisor (3: a third of the resolution on each axis). At 4
    /// previews never got finer than a quarter on the benchmark views; at 3 with 30 ms
    /// their median is a third (BENCHMARKS.md, the window).
    pub min_scale: u32,
    pub max_scale: u32,
    /// Unfinished full-resolution frames are published at most this often, ms.
    pub publish_ms: f64,
}

impl Default for ProgressiveOptions {
    fn default() -> Self {
        ProgressiveOptions {
            threads: None,
            preview_ms: 30.0,
            min_scale: 3,
            max_scale: 16,
            publish_ms: 60.0,
        }
    }
}

struct Pending {
    generation: u64,
    job: Job,
    cancel: CancelToken,
}

struct Inner {
    /// Generation of the newest submitted job.
    generation: u64,
    cancel: CancelToken,
    pending: Option<Pending>,
    latest: Option<Update>,
    /// Generation of the newest update published.
    published: u64,
    /// The job in flight is rendering its preview (not cancelled by a new job).
    in_preview: bool,
    /// Generation of the last completed job.
    completed: u64,
    error: Option<(u64, String)>,
    busy: bool,
    scale: PreviewScale,
    shutdown: bool,
}

struct Shared {
    inner: Mutex<Inner>,
    /// Signals a new job (to the worker) and a new update (to waiters).
    changed: Condvar,
    notify: Box<dyn Fn() + Send + Sync>,
    options: ProgressiveOptions,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Publishes `u` unless a newer image was published already (previews) or a newer
    /// job was submitted (full resolution); returns whether it was published.
    fn publish(&self, u: Update) -> bool {
        let mut g = self.lock();
        let newest_job = g.generation == u.generation;
        let is_preview = matches!(u.level, Level::Preview { .. });
        if u.generation < g.published || !(newest_job || is_preview) {
            return false;
        }
        g.published = u.generation;
        if u.complete {
            g.completed = u.generation;
        }
        g.latest = Some(u);
        drop(g);
        self.changed.notify_all();
        (self.notify)();
        true
    }
}

/// Why the render threads could not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error("starting the render pool: {0}")]
    Pool(#[from] rayon::ThreadPoolBuildError),
    #[error("starting the render thread: {0}")]
    Thread(std::io::Error),
}

/// A render thread that turns submitted views into a stream of ever better images.
pub struct Progressive {
    shared: Arc<Shared>,
    worker: Option<JoinHandle<()>>,
    threads: usize,
}

impl Progressive {
    /// Starts the render thread and its pool. `notify` is called (from a render thread)
    /// whenever a new update is ready, e.g. to wake the UI.
    pub fn new(
        options: ProgressiveOptions,
        notify: Box<dyn Fn() + Send + Sync>,
    ) -> Result<Progressive, StartError> {
        // The window's frames come first: its renders run below its priority.
        let renderer = Renderer::background(options.threads)?;
        let threads = renderer.threads();
        let scale = PreviewScale::new(options.min_scale, options.max_scale, options.preview_ms);
        let shared = Arc::new(Shared {
            inner: Mutex::new(Inner {
                generation: 0,
                cancel: CancelToken::new(),
                pending: None,
                latest: None,
                published: 0,
                in_preview: false,
                completed: 0,
                error: None,
                busy: false,
                scale,
                shutdown: false,
            }),
            changed: Condvar::new(),
            notify,
            options,
        });
        let s = Arc::clone(&shared);
        let worker = std::thread::Builder::new()
            .name("qbricks-progressive".into())
            .spawn(move || worker_loop(&s, &renderer))
            .map_err(StartError::Thread)?;
        Ok(Progressive {
            shared,
            worker: Some(worker),
            threads,
        })
    }

    pub fn threads(&self) -> usize {
        self.threads
    }

    /// Starts rendering `job`, cancelling the frame in flight. Returns its generation.
    pub fn submit(&self, job: Job) -> u64 {
        let mut g = self.shared.lock();
        if !g.in_preview {
            g.cancel.cancel();
        }
        g.generation += 1;
        g.cancel = CancelToken::new();
        g.pending = Some(Pending {
            generation: g.generation,
            job,
            cancel: g.cancel.clone(),
        });
        let generation = g.generation;
        drop(g);
        self.shared.changed.notify_all();
        generation
    }

    /// The newest image, if one has come since the last call. Generations never go
    /// back: an image is never older than one returned before.
    pub fn latest(&self) -> Option<Update> {
        self.shared.lock().latest.take()
    }

    /// Why the newest job could not render, if it failed.
    pub fn error(&self) -> Option<String> {
        let g = self.shared.lock();
        g.error
            .as_ref()
            .filter(|(gen, _)| *gen == g.generation)
            .map(|(_, m)| m.clone())
    }

    /// Whether the newest job has finished (or failed) and nothing is being rendered.
    pub fn idle(&self) -> bool {
        let g = self.shared.lock();
        g.pending.is_none() && !g.busy
    }

    /// Current preview divisor.
    pub fn preview_scale(&self) -> u32 {
        self.shared.lock().scale.scale()
    }

    /// Blocks until job `generation` has completed (or failed, or was superseded), or
    /// `timeout` passed. Returns whether it completed. For tests and scripted runs.
    pub fn wait_complete(&self, generation: u64, timeout: Duration) -> bool {
        let end = Instant::now() + timeout;
        let mut g = self.shared.lock();
        loop {
            if g.completed >= generation {
                return g.completed == generation;
            }
            let failed = g.error.as_ref().is_some_and(|(gen, _)| *gen >= generation);
            if failed || g.generation > generation {
                return false;
            }
            let now = Instant::now();
            if now >= end {
                return false;
            }
            g = self
                .shared
                .changed
                .wait_timeout(g, end - now)
                .map(|(g, _)| g)
                .unwrap_or_else(|e| e.into_inner().0);
        }
    }
}

impl Drop for Progressive {
    fn drop(&mut self) {
        {
            let mut g = self.shared.lock();
            g.shutdown = true;
            g.cancel.cancel();
        }
        self.shared.changed.notify_all();
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}

fn worker_loop(shared: &Shared, renderer: &Renderer) {
    let mut accels = DatasetAccels::default();
    loop {
        let pending = {
            let mut g = shared.lock();
            loop {
                if g.shutdown {
                    return;
                }
                if let Some(p) = g.pending.take() {
                    g.busy = true;
                    break p;
                }
                g = shared.changed.wait(g).unwrap_or_else(|e| e.into_inner());
            }
        };
        let generation = pending.generation;
        if let Err(e) = run_job(shared, renderer, &mut accels, pending) {
            shared.lock().error = Some((generation, e.to_string()));
            shared.changed.notify_all();
            (shared.notify)();
        }
        shared.lock().busy = false;
        shared.changed.notify_all();
    }
}

/// Nearest-neighbour upscale of a `pw`×`ph` image to `w`×`h`.
fn upscale(src: &[[f32; 3]], pw: u32, ph: u32, w: u32, h: u32) -> Vec<[f32; 3]> {
    let mut out = Vec::with_capacity(w as usize * h as usize);
    for y in 0..h {
        let sy = ((u64::from(y) * u64::from(ph)) / u64::from(h.max(1))) as u32;
        for x in 0..w {
            let sx = ((u64::from(x) * u64::from(pw)) / u64::from(w.max(1))) as u32;
            out.push(src[(sy.min(ph - 1) * pw + sx.min(pw - 1)) as usize]);
        }
    }
    out
}

fn run_job(
    shared: &Shared,
    renderer: &Renderer,
    accels: &mut DatasetAccels,
    p: Pending,
) -> Result<(), UnknownField> {
    let Pending {
        generation,
        job,
        cancel,
    } = p;
    if !accels.holds(&job.dataset) {
        shared.lock().scale.forget();
    }
    let cache = accels.of(&job.dataset);
    let opts = &shared.options;
    let state = &job.state;
    let vol = job.dataset.volume();
    let (w, h) = (state.width.max(1), state.height.max(1));
    let view = Arc::new(state.clone());
    let bounds = crate::overlay::data_bounds(vol);
    let since = |t: Instant| t.elapsed().as_secs_f64() * 1e3;

    // Preview: a fraction of the resolution, one sample per pixel.
    let mut backdrop: Option<Vec<[f32; 3]>> = None;
    if job.preview {
        let scale = {
            let mut g = shared.lock();
            g.in_preview = true;
            g.scale.scale()
        };
        let mut ps = state.clone();
        ps.width = w.div_ceil(scale).max(1);
        ps.height = h.div_ceil(scale).max(1);
        ps.spp = 1;
        let scene = Scene::cached(vol, &ps, &job.meshes, cache)?;
        let t = Instant::now();
        let acc = Mutex::new((Film::one_pass(ps.width, ps.height), Counts::default()));
        let sink = |r: TileResult| {
            let mut g = acc.lock().unwrap_or_else(|e| e.into_inner());
            g.0.add(&r);
            g.1.add(&r);
        };
        let done = renderer.render_tiles(&scene, &tiles(ps.width, ps.height), 0..1, &cancel, &sink);
        let superseded = {
            let mut g = shared.lock();
            g.in_preview = false;
            g.pending.is_some()
        };
        if !done {
            return Ok(());
        }
        let ms = since(t);
        let (film, counts) = acc.into_inner().unwrap_or_else(|e| e.into_inner());
        let rgb = film.into_parts().rgb;
        backdrop = Some(upscale(&rgb, ps.width, ps.height, w, h));
        // Keep the preview near its time budget.
        let pixels = u64::from(ps.width) * u64::from(ps.height);
        shared.lock().scale.record(w, h, pixels, ms);
        shared.publish(Update {
            generation,
            level: Level::Preview { scale },
            width: ps.width,
            height: ps.height,
            rgb: Arc::new(rgb),
            samples: 1,
            spp: 1,
            counts,
            ms,
            complete: false,
            view: Arc::clone(&view),
            bounds,
            surface: None,
        });
        if superseded {
            // A newer view is waiting: its preview matters more than this full frame.
            return Ok(());
        }
    }

    // Full resolution, one sample wave after another.
    let scene = Scene::cached(vol, state, &job.meshes, cache)?;
    let spp = state.spp.max(1);
    let all = tiles(w, h);
    let t = Instant::now();
    struct Acc {
        film: Film,
        counts: Counts,
        display: Vec<[f32; 3]>,
        last_publish: Instant,
        /// The film's surface buffers once the first wave is in.
        surface: Option<Arc<(Vec<f32>, Vec<f32>)>>,
    }
    let acc = Mutex::new(Acc {
        film: Film::new(w, h),
        counts: Counts::default(),
        display: backdrop.unwrap_or_else(|| vec![state.background; w as usize * h as usize]),
        last_publish: Instant::now(),
        surface: None,
    });
    for s in 0..spp {
        let sink = |r: TileResult| {
            let mut g = acc.lock().unwrap_or_else(|e| e.into_inner());
            g.film.add(&r);
            g.counts.add(&r);
            let tl = r.tile;
            for y in tl.y0..tl.y1 {
                for x in tl.x0..tl.x1 {
                    let i = (y * w + x) as usize;
                    if let Some(c) = g.film.pixel(i) {
                        g.display[i] = c;
                    }
                }
            }
            if g.last_publish.elapsed().as_secs_f64() * 1e3 >= opts.publish_ms {
                g.last_publish = Instant::now();
                let u = Update {
                    generation,
                    level: Level::Full,
                    width: w,
                    height: h,
                    rgb: Arc::new(g.display.clone()),
                    samples: s,
                    spp,
                    counts: g.counts,
                    ms: since(t),
                    complete: false,
                    view: Arc::clone(&view),
                    bounds,
                    surface: g.surface.clone(),
                };
                drop(g);
                shared.publish(u);
            }
        };
        if !renderer.render_tiles(&scene, &all, s..s + 1, &cancel, &sink) {
            return Ok(());
        }
        let mut g = acc.lock().unwrap_or_else(|e| e.into_inner());
        g.last_publish = Instant::now();
        if s == 0 {
            g.surface = Some(Arc::new((
                g.film.depth().to_vec(),
                g.film.surface_values().to_vec(),
            )));
        }
        let complete = s + 1 == spp;
        let rgb = if complete {
            g.film.resolve()
        } else {
            g.display.clone()
        };
        let u = Update {
            generation,
            level: Level::Full,
            width: w,
            height: h,
            rgb: Arc::new(rgb),
            samples: s + 1,
            spp,
            counts: g.counts,
            ms: since(t),
            complete,
            view: Arc::clone(&view),
            bounds,
            surface: g.surface.clone(),
        };
        drop(g);
        if !shared.publish(u) {
            return Ok(());
        }
    }
    Ok(())
}
