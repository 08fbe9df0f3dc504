//! Whole images: tiles in parallel with rayon, one ray per (pixel, sample), shading.
//!
//! Every pixel is a pure function of the scene, its coordinates, the sample index and
//! the seed (the sub-pixel offset and the interleaved-sampling offset of the first sample
//! come from a hash of those), and work counters are summed as integers, so the image and
//! the statistics are the same whatever the number of threads.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::camera::{Ray, RayGen};
use crate::mesh::{MeshHit, Meshes};
use crate::reconstruct::Eval;
use crate::sampling::{Event, Params, Stats, Strategy, Tracer};
use crate::shading::phong;
use crate::transfer::{Mode, Transfer};
use crate::view_state::ViewState;
use crate::volume::{Volume, VolumeError};

/// Tile edge in pixels.
pub const TILE: u32 = 16;

/// Everything a ray needs, resolved once per frame.
pub struct Scene<'a> {
    pub vol: &'a Volume<'a>,
    pub state: &'a ViewState,
    pub meshes: &'a Meshes,
    pub params: Params,
    /// Camera rays with the camera basis computed once per frame.
    pub rays: RayGen,
}

impl<'a> Scene<'a> {
    /// Resolves field names and the transfer function of `state` against `vol`.
    /// `exact` is an iso-surface strategy; in dvr mode it samples as `bisect`.
    pub fn new(
        vol: &'a Volume<'a>,
        state: &'a ViewState,
        meshes: &'a Meshes,
    ) -> Result<Self, VolumeError> {
        let field = vol.field_index(&state.iso_field)?;
        let colour_field = vol.field_index(&state.colormap.field).ok();
        let strategy = effective_strategy(state.mode, state.strategy);
        let params = Params {
            strategy,
            step: state.step,
            tf: Transfer {
                mode: state.mode,
                iso: state.iso,
                sigma: state.transfer.sigma,
                peak: state.transfer.peak,
                k: state.transfer.k,
            },
            field,
            colour_field,
            // The seed report's opacities are per sample at step 0.5·dx of the finest grid.
            delta0: 0.5 * vol.finest_w,
            clip: None,
        };
        let mut params = params;
        params.clip_to_active(vol);
        Ok(Scene {
            vol,
            state,
            meshes,
            params,
            rays: state.camera.ray_generator(state.width, state.height),
        })
    }
}

/// The strategy actually used: `exact` in dvr mode samples as `bisect`.
pub fn effective_strategy(mode: Mode, strategy: Strategy) -> Strategy {
    match (mode, strategy) {
        (Mode::Dvr, Strategy::Exact) => Strategy::Bisect,
        _ => strategy,
    }
}

/// A rendered image (linear RGB in 0..=1 per pixel, row-major from the top-left).
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[f32; 3]>,
    pub stats: Stats,
    pub rays: u64,
    /// Rays that hit the iso-surface (iso) or gathered opacity ≥ 0.01 (dvr).
    pub hits: u64,
}

/// Per-thread state of a tile.
struct Worker<'s> {
    scene: &'s Scene<'s>,
    main: Tracer<'s>,
    shadow: Tracer<'s>,
    hits: u64,
    rays: u64,
}

/// splitmix64 finaliser.
#[inline]
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Uniform number in `[0, 1)` from (pixel, sample, seed, purpose).
#[inline]
pub fn jitter(x: u32, y: u32, sample: u32, seed: u64, purpose: u64) -> f64 {
    let h = mix(seed ^ mix(((x as u64) << 32 | y as u64) ^ mix((sample as u64) << 8 | purpose)));
    (h >> 11) as f64 / (1u64 << 53) as f64
}

impl<'s> Worker<'s> {
    fn new(scene: &'s Scene<'s>) -> Self {
        let mut shadow_params = scene.params;
        if shadow_params.strategy != Strategy::Exact {
            // Shadow rays only need the occlusion, sampled a little coarser.
            shadow_params.step = shadow_params.step.max(1.0);
        }
        Worker {
            scene,
            main: Tracer::new(scene.vol, scene.params),
            shadow: Tracer::new(scene.vol, shadow_params),
            hits: 0,
            rays: 0,
        }
    }

    /// Colour of pixel (x, y), averaged over `spp` jittered rays.
    fn pixel(&mut self, x: u32, y: u32) -> [f32; 3] {
        let st = self.scene.state;
        let spp = st.spp.max(1);
        let mut sum = [0.0f64; 3];
        for s in 0..spp {
            let (jx, jy) = if spp == 1 {
                (0.5, 0.5)
            } else {
                (jitter(x, y, s, st.seed, 1), jitter(x, y, s, st.seed, 2))
            };
            let ray = self.scene.rays.ray(x as f64 + jx, y as f64 + jy);
            let c = self.trace(&ray, jitter(x, y, s, st.seed, 0));
            for a in 0..3 {
                sum[a] += c[a];
            }
        }
        sum.map(|c| (c / spp as f64) as f32)
    }

    /// Colour seen along one camera ray.
    fn trace(&mut self, ray: &Ray, jit: f64) -> [f64; 3] {
        let scene = self.scene;
        let st = scene.state;
        let vol = scene.vol;
        self.rays += 1;
        let o = vol.to_local(ray.origin.to_array());
        let d = ray.dir.to_array();
        let mesh_hit = if scene.meshes.is_empty() {
            None
        } else {
            scene.meshes.intersect(ray, 0.0, f64::INFINITY)
        };
        let t_max = mesh_hit.map_or(f64::INFINITY, |h| h.t);
        let bg = st.background.map(f64::from);
        let behind = |w: &mut Self| match mesh_hit {
            Some(h) => w.shade_mesh(ray, &h),
            None => bg,
        };
        match scene.params.tf.mode {
            Mode::Iso => match self.main.iso(o, d, 0.0, t_max, jit) {
                Some(hit) => {
                    self.hits += 1;
                    let e = hit.eval.unwrap_or_default();
                    self.shade_surface(ray, &hit.p, &e, hit.eval.is_some())
                }
                None => behind(self),
            },
            Mode::Dvr => {
                let shadows = st.shadows;
                let (main, shadow) = (&mut self.main, &mut self.shadow);
                let acc = main.dvr(o, d, 0.0, t_max, jit, &mut |p, e| {
                    shade_sample(scene, shadow, shadows, ray, p, e)
                });
                if acc.alpha() >= 0.01 {
                    self.hits += 1;
                }
                let back = if acc.done() { [0.0; 3] } else { behind(self) };
                acc.over(back)
            }
        }
    }

    fn shade_mesh(&mut self, ray: &Ray, h: &MeshHit) -> [f64; 3] {
        let st = self.scene.state;
        let p = ray.at(h.t);
        let n = if h.normal.dot(ray.dir) > 0.0 {
            -h.normal
        } else {
            h.normal
        };
        let vis = self.visibility(p, n, true);
        phong(h.colour, n, -ray.dir, p, &st.lights, &vis, &st.material)
            .to_array()
            .map(f64::from)
    }

    /// Phong-shaded iso-surface point (local `p`).
    fn shade_surface(&mut self, ray: &Ray, p: &[f64; 3], e: &Eval, has_eval: bool) -> [f64; 3] {
        let scene = self.scene;
        let st = scene.state;
        let base = base_colour(scene, e, has_eval);
        let n = normal(e, ray.dir);
        let pw = DVec3::from_array(scene.vol.to_world(*p));
        let vis = self.visibility(pw, n, false);
        phong(base, n, -ray.dir, pw, &st.lights, &vis, &st.material)
            .to_array()
            .map(f64::from)
    }

    /// Shadow transmittance towards every light from world point `p` with normal `n`.
    fn visibility(&mut self, p: DVec3, n: DVec3, _on_mesh: bool) -> Vec<f32> {
        let scene = self.scene;
        let st = scene.state;
        if !st.shadows {
            return Vec::new();
        }
        st.lights
            .iter()
            .map(|l| light_visibility(scene, &mut self.shadow, p, n, l))
            .collect()
    }
}

fn light_visibility(
    scene: &Scene,
    shadow: &mut Tracer,
    p: DVec3,
    n: DVec3,
    light: &crate::shading::Light,
) -> f32 {
    let (l, dist) = light.towards(p);
    if n.dot(l) <= 0.0 {
        return 1.0; // phong ignores lights behind the surface anyway
    }
    let eps = 1e-3 * scene.vol.finest_w;
    let origin = p + eps * n;
    let ray = Ray { origin, dir: l };
    if !scene.meshes.is_empty() && scene.meshes.occluded(&ray, 0.0, dist) {
        return 0.0;
    }
    let o = scene.vol.to_local(origin.to_array());
    let d = l.to_array();
    let t_max = if dist.is_finite() {
        dist
    } else {
        f64::INFINITY
    };
    match scene.params.tf.mode {
        Mode::Iso => {
            if shadow.iso_occluded(o, d, 0.0, t_max) {
                0.0
            } else {
                1.0
            }
        }
        Mode::Dvr => shadow.transmittance(o, d, 0.0, t_max) as f32,
    }
}

/// Unit normal from the gradient, facing the viewer; the view direction when the
/// gradient vanishes.
fn normal(e: &Eval, dir: DVec3) -> DVec3 {
    let g = DVec3::from_array(e.grad);
    let len = g.length();
    if !(len > 0.0 && len.is_finite()) {
        return -dir;
    }
    let n = g / len;
    if n.dot(dir) > 0.0 {
        -n
    } else {
        n
    }
}

fn base_colour(scene: &Scene, e: &Eval, has_eval: bool) -> Vec3 {
    match (scene.params.colour_field, has_eval) {
        (Some(_), true) => Vec3::from_array(scene.state.colormap.colour(e.colour as f32)),
        _ => Vec3::splat(0.8),
    }
}

/// Colour of a visible dvr sample at local `p`.
fn shade_sample(
    scene: &Scene,
    shadow: &mut Tracer,
    shadows: bool,
    ray: &Ray,
    p: &[f64; 3],
    e: &Eval,
) -> [f64; 3] {
    let st = scene.state;
    let base = base_colour(scene, e, true);
    let g = DVec3::from_array(e.grad);
    if g.length() <= 0.0 || g.is_nan() {
        return base.to_array().map(f64::from);
    }
    let n = normal(e, ray.dir);
    let pw = DVec3::from_array(scene.vol.to_world(*p));
    let vis: Vec<f32> = if shadows {
        st.lights
            .iter()
            .map(|l| light_visibility(scene, shadow, pw, n, l))
            .collect()
    } else {
        Vec::new()
    };
    phong(base, n, -ray.dir, pw, &st.lights, &vis, &st.material)
        .to_array()
        .map(f64::from)
}

/// Renders the whole image on the current rayon pool.
pub fn render(scene: &Scene) -> Frame {
    let (w, h) = (scene.state.width, scene.state.height);
    let tiles_x = w.div_ceil(TILE);
    let tiles_y = h.div_ceil(TILE);
    let tiles: Vec<(u32, u32)> = (0..tiles_y)
        .flat_map(|ty| (0..tiles_x).map(move |tx| (tx, ty)))
        .collect();
    let done: Vec<(Vec<[f32; 3]>, Stats, u64, u64)> = tiles
        .par_iter()
        .map(|&(tx, ty)| {
            let mut worker = Worker::new(scene);
            let x0 = tx * TILE;
            let y0 = ty * TILE;
            let x1 = (x0 + TILE).min(w);
            let y1 = (y0 + TILE).min(h);
            let mut px = Vec::with_capacity(((x1 - x0) * (y1 - y0)) as usize);
            for y in y0..y1 {
                for x in x0..x1 {
                    px.push(worker.pixel(x, y));
                }
            }
            let mut stats = worker.main.stats;
            stats += worker.shadow.stats;
            (px, stats, worker.rays, worker.hits)
        })
        .collect();
    let mut rgb = vec![[0.0f32; 3]; w as usize * h as usize];
    let mut stats = Stats::default();
    let (mut rays, mut hits) = (0, 0);
    for (&(tx, ty), (px, s, r, hi)) in tiles.iter().zip(done) {
        let x0 = tx * TILE;
        let y0 = ty * TILE;
        let tw = (x0 + TILE).min(w) - x0;
        for (i, c) in px.into_iter().enumerate() {
            let x = x0 + i as u32 % tw;
            let y = y0 + i as u32 / tw;
            rgb[(y * w + x) as usize] = c;
        }
        stats += s;
        rays += r;
        hits += hi;
    }
    Frame {
        width: w,
        height: h,
        rgb,
        stats,
        rays,
        hits,
    }
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
pub fn trace_pixel(scene: &Scene, x: u32, y: u32) -> PixelTrace {
    let st = scene.state;
    let mut worker = Worker::new(scene);
    let spp = st.spp.max(1);
    let mut rays = Vec::new();
    let mut sum = [0.0f64; 3];
    for s in 0..spp {
        let (jx, jy) = if spp == 1 {
            (0.5, 0.5)
        } else {
            (jitter(x, y, s, st.seed, 1), jitter(x, y, s, st.seed, 2))
        };
        let ray = scene.rays.ray(x as f64 + jx, y as f64 + jy);
        let jit = jitter(x, y, s, st.seed, 0);
        worker.main.log = Some(Vec::new());
        let c = worker.trace(&ray, jit);
        for a in 0..3 {
            sum[a] += c[a];
        }
        rays.push(RayTrace {
            origin: ray.origin.to_array(),
            dir: ray.dir.to_array(),
            jitter: jit,
            events: worker.main.log.take().unwrap_or_default(),
        });
    }
    PixelTrace {
        x,
        y,
        colour: sum.map(|c| (c / spp as f64) as f32),
        rays,
    }
}

/// Renders on a pool of `threads` workers (0: all cores).
pub fn render_with_threads(
    scene: &Scene,
    threads: usize,
) -> Result<Frame, rayon::ThreadPoolBuildError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    Ok(pool.install(|| render(scene)))
}
