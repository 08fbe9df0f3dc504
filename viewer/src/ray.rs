//! One camera ray: trace it through meshes and volume, shade what it sees, send shadow
//! rays. The frame loop ([`crate::render`]) decides which rays to cast; this module
//! decides what colour each one returns.
//!
//! A ray's colour is a pure function of the scene, the pixel, the sample index and the
//! seed: the sub-pixel offset and the interleaved-sampling offset of the first sample
//! come from a hash of those, so the same pixel gets the same colour on any thread, in
//! any order, in one frame or spread over progressive sample waves.

use glam::{DVec3, Vec3};

use crate::camera::Ray;
use crate::integrate::Accum;
use crate::mesh::MeshHit;
use crate::reconstruct::Eval;
use crate::sampling::{Event, Stats, Strategy, Tracer};
use crate::scene::Scene;
use crate::shading::{phong, Light};
use crate::transfer::Mode;
use crate::volume::NearRegions;

pub use crate::shading::Shading;

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

/// An iso-surface point as seen by a camera ray.
#[derive(Debug, Clone, Copy)]
pub struct SurfacePoint {
    pub world: DVec3,
    pub local: [f64; 3],
    /// Unit shading normal, facing the ray's origin.
    pub normal: DVec3,
    /// Reconstruction at the point (`None` only where the weights vanish).
    pub eval: Option<Eval>,
    /// Distance along the ray (`None`: measure it from `world`).
    pub t: Option<f64>,
}

/// Contour lines on slices, for surfaces coloured by the colour map: dark, so they show
/// on every palette's light end and as an edge on its dark end.
const CONTOUR_COLOUR: [f64; 3] = [0.02, 0.02, 0.02];

/// Step of shadow rays: they only need the occlusion, sampled a little coarser (exact
/// finds roots, whatever the step).
fn shadow_params_step(p: crate::sampling::Params) -> f64 {
    if p.strategy == Strategy::Exact {
        p.step
    } else {
        p.step.max(1.0)
    }
}

/// Per-thread ray casting state: the tracers (with their reusable stacks) and counters.
pub struct RayCaster<'s> {
    scene: &'s Scene<'s>,
    pub(crate) main: Tracer<'s>,
    shadow: Tracer<'s>,
    /// Camera and shadow tracers of the iso-surfaces beyond the first
    /// ([`Scene::more_surfaces`]), in their order.
    more: Vec<(Tracer<'s>, Tracer<'s>)>,
    /// Rays that hit the iso-surface (iso) or gathered opacity ≥ 0.01 (dvr).
    pub hits: u64,
    pub rays: u64,
    /// What the last traced ray met first (see [`FirstSurface`]).
    pub(crate) first: FirstSurface,
    /// Where camera rays search the meshes' tree: the root, except while the frame loop
    /// traces a group of pixels, whose frustum gives a start below it, or none when it
    /// misses every triangle's box ([`RayCaster::set_mesh_start`]).
    mesh_start: Option<u32>,
    /// Regions the shading normals of this caster's hits found their neighbour points in.
    near: NearRegions,
}

/// What a camera ray met first: the iso-surface (iso mode) or a mesh. The overlays hide
/// the outline box behind it, and "fit to what is visible" takes the colour range of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FirstSurface {
    /// Ray parameter (distance along the unit direction), infinite where nothing was met.
    pub t: f32,
    /// The colour field's value there, NaN on a mesh, where nothing was met, or in dvr.
    pub value: f32,
}

/// The part of a camera ray the volume is searched on ([`RayCaster::bounds`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct RayBounds {
    pub t_lo: f64,
    /// The first mesh's distance, or the end of what the clip planes keep.
    pub t_max: f64,
    pub mesh: Option<MeshHit>,
}

impl FirstSurface {
    pub(crate) const NONE: FirstSurface = FirstSurface {
        t: f32::INFINITY,
        value: f32::NAN,
    };
}

impl<'s> RayCaster<'s> {
    pub fn new(scene: &'s Scene<'s>) -> Self {
        let mut shadow_params = scene.params;
        shadow_params.step = shadow_params_step(scene.params);
        let more = scene
            .more_surfaces
            .iter()
            .map(|s| {
                let mut shadow_params = s.params;
                shadow_params.step = shadow_params_step(s.params);
                (
                    Tracer::new(scene.vol, &s.accel, s.params),
                    Tracer::new(scene.vol, &s.accel, shadow_params),
                )
            })
            .collect();
        RayCaster {
            scene,
            main: Tracer::new(scene.vol, &scene.accel, scene.params),
            shadow: Tracer::new(scene.vol, &scene.accel, shadow_params),
            more,
            hits: 0,
            rays: 0,
            first: FirstSurface::NONE,
            mesh_start: Some(0),
            near: NearRegions::default(),
        }
    }

    /// Tells the caster where the next camera rays search the meshes' tree: a
    /// [`Meshes::start_in`](crate::mesh::Meshes::start_in) of a frustum around them, so
    /// `None` where no triangle's box lies in it (they skip the tree; shadow rays still
    /// search it from the root).
    pub(crate) fn set_mesh_start(&mut self, start: Option<u32>) {
        self.mesh_start = start;
    }

    /// Work counters of every ray cast so far (camera and shadow rays).
    pub(crate) fn stats(&self) -> Stats {
        let mut s = self.main.stats;
        s += self.shadow.stats;
        for (m, sh) in &self.more {
            s += m.stats;
            s += sh.stats;
        }
        s
    }

    /// The camera ray of sample `s` of pixel (`x`, `y`) and its first-sample offset.
    /// One sample per pixel goes through the pixel centre; more are jittered.
    pub fn camera_ray(&self, x: u32, y: u32, s: u32) -> (Ray, f64) {
        let st = self.scene.state;
        let (jx, jy) = if st.spp.max(1) == 1 {
            (0.5, 0.5)
        } else {
            (jitter(x, y, s, st.seed, 1), jitter(x, y, s, st.seed, 2))
        };
        let ray = self.scene.rays.ray(x as f64 + jx, y as f64 + jy);
        // Only the sampled searches offset their first sample: `exact` iso-surfaces take
        // no jitter, and its hash is a few percent of their rays' set-up.
        let jit = match self.scene.uses_jitter() {
            true => jitter(x, y, s, st.seed, 0),
            false => 0.0,
        };
        (ray, jit)
    }

    /// Colour of sample `s` of pixel (`x`, `y`).
    #[inline]
    pub(crate) fn sample(&mut self, x: u32, y: u32, s: u32) -> [f64; 3] {
        let (ray, jit) = self.camera_ray(x, y, s);
        self.trace(&ray, jit)
    }

    /// Whether a camera ray whose walk starts nowhere ([`Start::Nothing`]: its group's
    /// frustum holds no region that can hold the iso value) and that meets no mesh (see
    /// [`RayCaster::set_mesh_start`]) can meet nothing but the background: one opaque
    /// iso-surface (whichever strategy searches it: all of them search only the active
    /// tree's leaves when it has one, and a walk that starts nowhere finds nothing) and
    /// no clip plane or slice, and no `--pixel` log. Such rays take
    /// [`RayCaster::sample_beside_surface`].
    ///
    /// [`Start::Nothing`]: crate::active::Start::Nothing
    pub(crate) fn background_beside_surface(&self) -> bool {
        let scene = self.scene;
        scene.params.tf.mode == Mode::Iso
            && scene.is_single_opaque()
            && scene.cuts.clips.is_empty()
            && self.main.log.is_none()
    }

    /// [`RayCaster::sample`] of a ray whose walk starts nowhere, in a view where
    /// [`RayCaster::background_beside_surface`] holds: the background, and the counters
    /// the walk keeps (the ray, and the one stretch of data it steps over), without the
    /// search's set-up. Three quarters of a frame's pixels beside a thin surface are such.
    /// `crossing`: whether the rays of the ray's group cross the data's bounds; only
    /// where some may and some may not is the ray made, to tell.
    pub(crate) fn sample_beside_surface(
        &mut self,
        x: u32,
        y: u32,
        s: u32,
        crossing: crate::render::Crossing,
    ) -> [f64; 3] {
        use crate::render::Crossing;
        self.rays += 1;
        self.first = FirstSurface::NONE;
        match crossing {
            Crossing::None => {}
            Crossing::All => self.main.step_over_data(),
            Crossing::Some => {
                let (ray, _) = self.camera_ray(x, y, s);
                let o = self.scene.vol.to_local(ray.origin.to_array());
                self.main
                    .step_over_all(o, ray.dir.to_array(), 0.0, f64::INFINITY);
            }
        }
        self.scene.state.background.map(f64::from)
    }

    /// Colour seen along one camera ray.
    pub(crate) fn trace(&mut self, ray: &Ray, jit: f64) -> [f64; 3] {
        let scene = self.scene;
        let st = scene.state;
        self.rays += 1;
        self.first = FirstSurface::NONE;
        let bg = st.background.map(f64::from);
        let Some(RayBounds {
            t_lo,
            t_max,
            mesh: mesh_hit,
        }) = self.bounds(ray)
        else {
            return bg;
        };
        // Where no surface is met, the depth is the mesh's, or infinite (not the end of
        // the clipped interval: nothing is there).
        self.first.t = mesh_hit.map_or(f32::INFINITY, |h| h.t as f32);
        let behind = |w: &mut Self| match mesh_hit {
            Some(h) => w.shade_mesh(ray, &h),
            None => bg,
        };
        if !scene.is_single_opaque() {
            let (acc, _) = match scene.params.tf.mode {
                Mode::Iso => self.composite_iso(ray, t_lo, t_max, jit),
                Mode::Dvr => self.composite_dvr(ray, t_lo, t_max, jit),
            };
            let back = if acc.done() { [0.0; 3] } else { behind(self) };
            return acc.over(back);
        }
        match scene.params.tf.mode {
            Mode::Iso => match self.surface_of(0, ray, t_lo, t_max, jit) {
                Some(s) => {
                    self.hits += 1;
                    self.log_hit(&s, 0);
                    self.first = self.first_at(ray, &s);
                    self.shade_surface(ray, &s, None)
                }
                None => behind(self),
            },
            Mode::Dvr => {
                let acc = self.dvr_between(ray, t_lo, t_max, jit);
                if acc.alpha() >= 0.01 {
                    self.hits += 1;
                }
                let back = if acc.done() { [0.0; 3] } else { behind(self) };
                acc.over(back)
            }
        }
    }

    /// The part of `ray` the volume is searched on: what the clip planes keep of it, up to
    /// the first mesh it meets (`None`: the planes keep nothing).
    pub(crate) fn bounds(&mut self, ray: &Ray) -> Option<RayBounds> {
        let scene = self.scene;
        // The clip planes cut the ray's interval before anything is walked, so what lies
        // behind a plane is seen and empty-space skipping works as without planes.
        let (t_lo, t_hi) = if scene.cuts.clips.is_empty() {
            (0.0, f64::INFINITY)
        } else {
            let o = scene.vol.to_local(ray.origin.to_array());
            let kept = scene
                .cuts
                .interval(&o, &ray.dir.to_array(), 0.0, f64::INFINITY);
            self.main.record(Event::Clip {
                t0: kept.map_or(f64::INFINITY, |k| k.0),
                t1: kept.map_or(f64::INFINITY, |k| k.1),
            });
            kept?
        };
        let mesh = match self.mesh_start {
            Some(start) if !scene.meshes.is_empty() => {
                scene.meshes.intersect_from(start, ray, t_lo, t_hi)
            }
            _ => None,
        };
        Some(RayBounds {
            t_lo,
            t_max: mesh.map_or(t_hi, |h| h.t),
            mesh,
        })
    }

    /// Searches only the regions `owned` marks, for camera and shadow rays: one rank's
    /// share of a frame over ranks (`crate::parts`). `nodes`: the view's active tree's
    /// [`owned_nodes`](crate::active::ActiveTree::owned_nodes) for them, so that the walk
    /// steps over the other ranks' subtrees.
    pub(crate) fn restrict(&mut self, owned: &'s [bool], nodes: Option<&'s [bool]>) {
        self.main.restrict(owned, nodes);
        self.shadow.restrict(owned, nodes);
    }

    /// The regions whose values this caster's rays read since it was restricted.
    pub(crate) fn touched(&self) -> impl Iterator<Item = u32> + '_ {
        self.main
            .touched
            .iter()
            .chain(&self.shadow.touched)
            .copied()
    }

    /// The first crossing of the view's first iso-surface along `ray` within `bounds`,
    /// with its shading normal (in the regions the caster is restricted to).
    pub(crate) fn first_crossing(
        &mut self,
        ray: &Ray,
        bounds: &RayBounds,
        jit: f64,
    ) -> Option<SurfacePoint> {
        self.surface_of(0, ray, bounds.t_lo, bounds.t_max, jit)
    }

    /// Dvr of `ray` within `bounds` through the regions the caster is restricted to, as
    /// runs (see [`Tracer::dvr_runs`]); shadows are not cast (a view over ranks has none).
    pub(crate) fn dvr_runs(
        &mut self,
        ray: &Ray,
        bounds: &RayBounds,
        jit: f64,
        runs: &mut Vec<(f64, Accum)>,
    ) {
        let scene = self.scene;
        let o = scene.vol.to_local(ray.origin.to_array());
        let d = ray.dir.to_array();
        let (main, shadow, more, near) = (
            &mut self.main,
            &mut self.shadow,
            &mut self.more,
            &mut self.near,
        );
        main.dvr_runs(
            o,
            d,
            bounds.t_lo,
            bounds.t_max,
            jit,
            &mut |p, e| shade_sample(scene, (shadow, more, near), false, ray, p, e),
            runs,
        );
    }

    /// Whether the view's first iso-surface lies on the volume part of a shadow ray.
    pub(crate) fn shadow_occluded(&mut self, q: &VolumeShadow) -> bool {
        self.shadow.iso_occluded(q.o, q.d, q.t0, q.t1)
    }

    /// Logs (`--pixel`) that surface `i` is drawn at `s`; the surface is named when the
    /// view has several.
    fn log_hit(&mut self, s: &SurfacePoint, i: usize) {
        let several = !self.scene.more_surfaces.is_empty();
        self.main.record(Event::Hit {
            t: s.t.unwrap_or(f64::NAN),
            value: s.eval.map(|e| e.value),
            normal: Some(s.normal.to_array()),
            surface: several.then_some(i as u32),
        });
    }

    /// What [`FirstSurface`] records of an iso-surface point.
    pub(crate) fn first_at(&self, ray: &Ray, s: &SurfacePoint) -> FirstSurface {
        FirstSurface {
            t: (s.world - ray.origin).dot(ray.dir) as f32,
            value: match (self.scene.params.colour_field, s.eval) {
                (Some(_), Some(e)) => e.colour as f32,
                _ => f32::NAN,
            },
        }
    }

    /// Dvr along `ray` for `t ∈ [t0, t1]`, composited front to back.
    fn dvr_between(&mut self, ray: &Ray, t0: f64, t1: f64, jit: f64) -> Accum {
        let scene = self.scene;
        let o = scene.vol.to_local(ray.origin.to_array());
        let d = ray.dir.to_array();
        let shadows = scene.state.shadows;
        let (main, shadow, more, near) = (
            &mut self.main,
            &mut self.shadow,
            &mut self.more,
            &mut self.near,
        );
        main.dvr(o, d, t0, t1, jit, &mut |p, e| {
            shade_sample(scene, (shadow, more, near), shadows, ray, p, e)
        })
    }

    /// Iso mode with several surfaces, translucent ones or slices: every iso-surface
    /// crossing and slice along `[t0, t1]`, composited in ray order until the ray is
    /// opaque. Returns the colour so far and whether any iso-surface was met.
    fn composite_iso(&mut self, ray: &Ray, t0: f64, t1: f64, jit: f64) -> (Accum, bool) {
        let scene = self.scene;
        let n = 1 + scene.more_surfaces.len();
        let mut acc = Accum::default();
        // The next crossing of each surface. An opaque one ends the ray, so the surfaces
        // after it are only searched up to it.
        let mut next: [Option<SurfacePoint>; crate::view_state::MAX_ISO_SURFACES] =
            [None; crate::view_state::MAX_ISO_SURFACES];
        let mut bound = t1;
        for (i, slot) in next.iter_mut().enumerate().take(n) {
            *slot = self.surface_of(i, ray, t0, bound, jit);
            if let Some(s) = slot {
                if self.style(i).opacity >= 1.0 {
                    bound = bound.min(self.t_of(ray, s));
                }
            }
        }
        let mut slices = self.slice_crossings(ray, t0, t1);
        let mut hit = false;
        let mut first = true;
        // A crossing is searched again just past the last one: a hundred-thousandth of
        // the finest cell, far below any other crossing's distance at float precision.
        let eps = 1e-5 * scene.vol.finest_w;
        loop {
            let surface = (0..n)
                .filter_map(|i| next[i].map(|s| (self.t_of(ray, &s), i)))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let slice = slices.first().copied();
            match (surface, slice) {
                (None, None) => break,
                (Some((t, i)), sl) if sl.is_none_or(|(ts, _)| t <= ts) => {
                    let Some(s) = next[i].take() else { break };
                    hit = true;
                    if first {
                        self.first = self.first_at(ray, &s);
                        first = false;
                    }
                    self.log_hit(&s, i);
                    let style = self.style(i);
                    let c = self.shade_surface(ray, &s, style.colour);
                    acc.add(c, style.opacity);
                    if acc.done() {
                        break;
                    }
                    next[i] = self.surface_of(i, ray, t + eps, bound, jit);
                }
                (_, Some((ts, j))) => {
                    slices.remove(0);
                    if let Some((c, value)) = self.slice_colour(ray, ts, j) {
                        if first {
                            self.first = FirstSurface {
                                t: ts as f32,
                                value: value as f32,
                            };
                            first = false;
                        }
                        acc.add(c, scene.cuts.slices[j].opacity);
                        if acc.done() {
                            break;
                        }
                    }
                }
                (Some(_), None) => unreachable!("handled by the first arm"),
            }
        }
        if hit {
            self.hits += 1;
        }
        (acc, hit)
    }

    /// Dvr with slices: the band composited piece by piece between the slices.
    fn composite_dvr(&mut self, ray: &Ray, t0: f64, t1: f64, jit: f64) -> (Accum, bool) {
        let scene = self.scene;
        let mut acc = Accum::default();
        let mut from = t0;
        for (ts, j) in self.slice_crossings(ray, t0, t1) {
            acc.then(&self.dvr_between(ray, from, ts, jit));
            from = ts;
            if acc.done() {
                break;
            }
            if let Some((c, value)) = self.slice_colour(ray, ts, j) {
                if self.first.value.is_nan() && self.first.t >= ts as f32 {
                    self.first = FirstSurface {
                        t: ts as f32,
                        value: value as f32,
                    };
                }
                acc.add(c, scene.cuts.slices[j].opacity);
                if acc.done() {
                    break;
                }
            }
        }
        if !acc.done() {
            acc.then(&self.dvr_between(ray, from, t1, jit));
        }
        let hit = acc.alpha() >= 0.01;
        if hit {
            self.hits += 1;
        }
        (acc, hit)
    }

    /// Where `ray` meets the view's slices within `(t0, t1)`, nearest first.
    fn slice_crossings(&self, ray: &Ray, t0: f64, t1: f64) -> Vec<(f64, usize)> {
        let vol = self.scene.vol;
        let o = vol.to_local(ray.origin.to_array());
        let d = ray.dir.to_array();
        let mut v: Vec<(f64, usize)> = self
            .scene
            .cuts
            .slices
            .iter()
            .enumerate()
            .filter_map(|(j, s)| {
                let t = s.plane.crossing(&o, &d)?;
                // A slice that clips lies at the start of the interval it leaves.
                (t >= t0 && t < t1).then_some((t, j))
            })
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        v
    }

    /// The colour of slice `j` where `ray` meets it at `t`, and the colour field's value
    /// there: the reconstruction `probe` gives at that point (so a slice across a level
    /// boundary has no crack), through the colour map, with the iso values' contour lines
    /// when asked. `None` outside the data (nothing is drawn there).
    fn slice_colour(&mut self, ray: &Ray, t: f64, j: usize) -> Option<([f64; 3], f64)> {
        let scene = self.scene;
        let vol = scene.vol;
        let slice = scene.cuts.slices[j];
        let o = vol.to_local(ray.origin.to_array());
        let p: [f64; 3] = std::array::from_fn(|a| o[a] + t * ray.dir[a]);
        let region = vol.region_at(p)?;
        let colour_field = scene.params.colour_field;
        let e = vol.eval(region as usize, p, scene.params.field, colour_field)?;
        self.main.stats.samples += 1;
        let value = if colour_field.is_some() {
            e.colour
        } else {
            e.value
        };
        self.main.record(Event::Slice {
            t,
            slice: j as u32,
            value,
        });
        let mut c = scene.state.colormap.colour(value as f32).map(f64::from);
        if slice.contours {
            // Distance to each iso value's contour, in the plane: the value's offset over
            // the in-plane gradient. Lines about one and a half pixels wide.
            let n = slice.plane.n;
            let g = e.grad;
            let gn = g[0] * n[0] + g[1] * n[1] + g[2] * n[2];
            let gp = (0..3)
                .map(|a| (g[a] - gn * n[a]).powi(2))
                .sum::<f64>()
                .sqrt();
            let px = scene.rays.pixel_size_at(t).max(f64::MIN_POSITIVE);
            for i in 0..1 + scene.more_surfaces.len() {
                let iso = if i == 0 {
                    scene.params.tf.iso
                } else {
                    scene.more_surfaces[i - 1].params.tf.iso
                };
                let dist = (e.value - iso).abs() / gp;
                let cover = (1.25 - dist / px).clamp(0.0, 1.0);
                if cover > 0.0 {
                    let line = self
                        .style(i)
                        .colour
                        .map_or(CONTOUR_COLOUR, |c| c.map(f64::from));
                    c = std::array::from_fn(|a| c[a] + cover * (line[a] - c[a]));
                }
            }
        }
        Some((c, value))
    }

    /// How surface `i` (0: the view's first) is drawn.
    fn style(&self, i: usize) -> crate::scene::SurfaceStyle {
        if i == 0 {
            self.scene.first_style
        } else {
            self.scene.more_surfaces[i - 1].style
        }
    }

    /// Distance along `ray` to a surface point.
    fn t_of(&self, ray: &Ray, s: &SurfacePoint) -> f64 {
        s.t.unwrap_or_else(|| (s.world - ray.origin).dot(ray.dir))
    }

    /// The iso-surface point along `ray` (iso mode, the view's strategy, the first
    /// surface), with its shading normal, on the part of the ray the clip planes keep.
    pub fn surface(&mut self, ray: &Ray, jit: f64) -> Option<SurfacePoint> {
        let vol = self.scene.vol;
        let o = vol.to_local(ray.origin.to_array());
        let (t0, t1) = self
            .scene
            .cuts
            .interval(&o, &ray.dir.to_array(), 0.0, f64::INFINITY)?;
        self.surface_of(0, ray, t0, t1, jit)
    }

    /// The first crossing of iso-surface `i` (0: the view's first) along `ray` for
    /// `t ∈ [t0, t1]`, with its shading normal.
    fn surface_of(
        &mut self,
        i: usize,
        ray: &Ray,
        t0: f64,
        t1: f64,
        jit: f64,
    ) -> Option<SurfacePoint> {
        let scene = self.scene;
        let vol = scene.vol;
        let o = vol.to_local(ray.origin.to_array());
        let tracer = if i == 0 {
            &mut self.main
        } else {
            // The extra surfaces' tracers log where the main one does (`--pixel`).
            let logging = self.main.log.is_some();
            let t = &mut self.more[i - 1].0;
            if logging && t.log.is_none() {
                t.log = Some(Vec::new());
            }
            t
        };
        let hit = tracer.iso(o, ray.dir.to_array(), t0, t1, jit);
        // The tracer logged its walk and the hit it found; the hit is logged again when
        // it is drawn ([`RayCaster::log_hit`]), since a crossing found behind an opaque
        // one is never drawn.
        let mut events = tracer.log.take();
        if hit.is_some() {
            if let Some(Event::Hit { .. }) = events.as_ref().and_then(|e| e.last()) {
                events.as_mut().map(Vec::pop);
            }
        }
        if i == 0 {
            self.main.log = events;
        } else if let (Some(events), Some(log)) = (events, self.main.log.as_mut()) {
            log.extend(events);
        }
        let hit = hit?;
        let eval = hit.eval;
        let e = eval.unwrap_or_default();
        let gradient = match scene.shading {
            Shading::Smooth => vol
                .shading_gradient_near(hit.region, hit.p, scene.params.field, &mut self.near)
                .unwrap_or(e.grad),
            Shading::Analytic => e.grad,
        };
        let normal = facing(gradient, ray.dir);
        Some(SurfacePoint {
            world: DVec3::from_array(vol.to_world(hit.p)),
            local: hit.p,
            normal,
            eval,
            t: Some(hit.t),
        })
    }

    /// The first surface along `ray`: the iso-surface (found with `exact` root finding,
    /// whatever the view's mode and strategy) or a mesh, as a distance along the ray.
    #[cfg(feature = "gui")]
    pub(crate) fn first_surface(&mut self, ray: &Ray) -> Option<f64> {
        let scene = self.scene;
        let o = scene.vol.to_local(ray.origin.to_array());
        let (t_lo, t_hi) = scene
            .cuts
            .interval(&o, &ray.dir.to_array(), 0.0, f64::INFINITY)?;
        let mesh_t = if scene.meshes.is_empty() {
            None
        } else {
            scene.meshes.intersect(ray, t_lo, t_hi).map(|h| h.t)
        };
        let mut params = scene.params;
        params.strategy = Strategy::Exact;
        params.tf.mode = Mode::Iso;
        let mut tracer = Tracer::new(scene.vol, &scene.accel, params);
        let t_max = mesh_t.unwrap_or(t_hi);
        let iso_t = tracer
            .iso(o, ray.dir.to_array(), t_lo, t_max, 0.5)
            .map(|hit| {
                let p = DVec3::from_array(scene.vol.to_world(hit.p));
                (p - ray.origin).dot(ray.dir)
            });
        iso_t.or(mesh_t)
    }

    fn shade_mesh(&mut self, ray: &Ray, h: &MeshHit) -> [f64; 3] {
        let (p, n) = mesh_point(ray, h);
        let vis = self.visibility(p, n);
        lit(self.scene, h.colour, n, ray, p, &vis)
    }

    /// Phong-shaded iso-surface point, in `colour` or the colour map's.
    fn shade_surface(&mut self, ray: &Ray, s: &SurfacePoint, colour: Option<[f32; 3]>) -> [f64; 3] {
        let base = surface_base(self.scene, s, colour);
        let vis = self.visibility(s.world, s.normal);
        lit(self.scene, base, s.normal, ray, s.world, &vis)
    }

    /// Shadow transmittance towards every light from world point `p` with normal `n`.
    fn visibility(&mut self, p: DVec3, n: DVec3) -> Vec<f32> {
        let scene = self.scene;
        let st = scene.state;
        if !st.shadows {
            return Vec::new();
        }
        let (shadow, more) = (&mut self.shadow, &mut self.more);
        st.lights
            .iter()
            .map(|l| light_visibility(scene, shadow, more, p, n, l))
            .collect()
    }
}

/// How much of `light` reaches world point `p` (normal `n`): meshes and opaque
/// iso-surfaces block it, a translucent surface lets `1 − opacity` through (once per
/// surface), dvr attenuates it; what the clip planes remove casts no shadow.
fn light_visibility(
    scene: &Scene,
    shadow: &mut Tracer,
    more: &mut [(Tracer, Tracer)],
    p: DVec3,
    n: DVec3,
    light: &Light,
) -> f32 {
    let q = match shadow_ray(scene, p, n, light) {
        ShadowRay::Settled(v) => return v,
        ShadowRay::Volume(q) => q,
    };
    let (o, d, t0, t1) = (q.o, q.d, q.t0, q.t1);
    match scene.params.tf.mode {
        Mode::Iso => {
            let mut through = first_surface_through(scene, shadow.iso_occluded(o, d, t0, t1));
            for ((_, sh), s) in more.iter_mut().zip(&scene.more_surfaces) {
                if through <= 0.0 {
                    break;
                }
                if sh.iso_occluded(o, d, t0, t1) {
                    through *= 1.0 - s.style.opacity;
                }
            }
            through as f32
        }
        Mode::Dvr => shadow.transmittance(o, d, t0, t1) as f32,
    }
}

/// A shadow ray, as far as it is known without the volume.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum ShadowRay {
    /// The light's visibility: the light is behind the surface, the clip planes remove the
    /// whole ray, or a mesh blocks it.
    Settled(f32),
    /// It depends on what the volume holds along this stretch.
    Volume(VolumeShadow),
}

/// The stretch `o + t d`, `t ∈ (t0, t1)` (local frame) of a shadow ray inside the clip
/// planes and before the light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct VolumeShadow {
    pub o: [f64; 3],
    pub d: [f64; 3],
    pub t0: f64,
    pub t1: f64,
}

/// The shadow ray from world point `p` (normal `n`) towards `light`: what meshes, clip
/// planes and the light's side settle, else the stretch the volume decides.
pub(crate) fn shadow_ray(scene: &Scene, p: DVec3, n: DVec3, light: &Light) -> ShadowRay {
    let (l, dist) = light.towards(p);
    if n.dot(l) <= 0.0 {
        return ShadowRay::Settled(1.0); // phong ignores lights behind the surface anyway
    }
    let eps = 1e-3 * scene.vol.finest_w;
    let origin = p + eps * n;
    let ray = Ray { origin, dir: l };
    let o = scene.vol.to_local(origin.to_array());
    let d = l.to_array();
    let t_max = if dist.is_finite() {
        dist
    } else {
        f64::INFINITY
    };
    let Some((t0, t1)) = scene.cuts.interval(&o, &d, 0.0, t_max) else {
        return ShadowRay::Settled(1.0);
    };
    if !scene.meshes.is_empty() && scene.meshes.occluded(&ray, t0, t1) {
        return ShadowRay::Settled(0.0);
    }
    ShadowRay::Volume(VolumeShadow { o, d, t0, t1 })
}

/// What the view's first iso-surface lets through to a shadow ray that crosses it
/// (`occluded`) or not.
pub(crate) fn first_surface_through(scene: &Scene, occluded: bool) -> f64 {
    if occluded {
        1.0 - scene.first_style.opacity
    } else {
        1.0
    }
}

/// Where a camera ray meets a mesh, and the mesh's normal there facing the ray.
pub(crate) fn mesh_point(ray: &Ray, h: &MeshHit) -> (DVec3, DVec3) {
    let p = ray.at(h.t);
    let n = if h.normal.dot(ray.dir) > 0.0 {
        -h.normal
    } else {
        h.normal
    };
    (p, n)
}

/// The colour of a surface of colour `base` at world point `p` (unit normal `n`) seen along
/// `ray`, lit by the view's lights with shadow transmittances `vis`.
pub(crate) fn lit(
    scene: &Scene,
    base: Vec3,
    n: DVec3,
    ray: &Ray,
    p: DVec3,
    vis: &[f32],
) -> [f64; 3] {
    let st = scene.state;
    phong(base, n, -ray.dir, p, &st.lights, vis, &st.material)
        .to_array()
        .map(f64::from)
}

/// The unlit colour of iso-surface point `s`: `colour`, or the colour map's.
fn surface_base(scene: &Scene, s: &SurfacePoint, colour: Option<[f32; 3]>) -> Vec3 {
    match colour {
        Some(c) => Vec3::from_array(c),
        None => base_colour(scene, s.eval.map(|e| e.colour)),
    }
}

/// Unit normal from a gradient, facing the viewer; the view direction when the
/// gradient vanishes.
fn facing(grad: [f64; 3], dir: DVec3) -> DVec3 {
    let g = DVec3::from_array(grad);
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

/// The colour map's colour of the colour field's value `colour` (`None`: the
/// reconstruction had no weights there), or grey without a colour field.
pub(crate) fn base_colour(scene: &Scene, colour: Option<f64>) -> Vec3 {
    match (scene.params.colour_field, colour) {
        (Some(_), Some(c)) => Vec3::from_array(scene.state.colormap.colour(c as f32)),
        _ => Vec3::splat(0.8),
    }
}

/// Colour of a visible dvr sample at local `p`.
fn shade_sample(
    scene: &Scene,
    (shadow, more, near): (&mut Tracer, &mut [(Tracer, Tracer)], &mut NearRegions),
    shadows: bool,
    ray: &Ray,
    p: &[f64; 3],
    e: &Eval,
) -> [f64; 3] {
    let st = scene.state;
    let base = base_colour(scene, Some(e.colour));
    let g = DVec3::from_array(e.grad);
    if g.length() <= 0.0 || g.is_nan() {
        return base.to_array().map(f64::from);
    }
    let n = match scene.shading {
        Shading::Smooth => facing(
            scene
                .vol
                .shading_gradient_near(None, *p, scene.params.field, near)
                .unwrap_or(e.grad),
            ray.dir,
        ),
        Shading::Analytic => facing(e.grad, ray.dir),
    };
    let pw = DVec3::from_array(scene.vol.to_world(*p));
    let vis: Vec<f32> = if shadows {
        st.lights
            .iter()
            .map(|l| light_visibility(scene, shadow, more, pw, n, l))
            .collect()
    } else {
        Vec::new()
    };
    phong(base, n, -ray.dir, pw, &st.lights, &vis, &st.material)
        .to_array()
        .map(f64::from)
}
