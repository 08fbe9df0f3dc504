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
use crate::mesh::MeshHit;
use crate::reconstruct::Eval;
use crate::sampling::{Event, Stats, Strategy, Tracer};
use crate::scene::Scene;
use crate::shading::{phong, Light};
use crate::transfer::Mode;

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
}

/// Per-thread ray casting state: the tracers (with their reusable stacks) and counters.
pub struct RayCaster<'s> {
    scene: &'s Scene<'s>,
    pub(crate) main: Tracer<'s>,
    shadow: Tracer<'s>,
    /// Rays that hit the iso-surface (iso) or gathered opacity ≥ 0.01 (dvr).
    pub hits: u64,
    pub rays: u64,
    /// What the last traced ray met first (see [`FirstSurface`]).
    pub(crate) first: FirstSurface,
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

impl FirstSurface {
    pub(crate) const NONE: FirstSurface = FirstSurface {
        t: f32::INFINITY,
        value: f32::NAN,
    };
}

impl<'s> RayCaster<'s> {
    pub fn new(scene: &'s Scene<'s>) -> Self {
        let mut shadow_params = scene.params;
        if shadow_params.strategy != Strategy::Exact {
            // Shadow rays only need the occlusion, sampled a little coarser.
            shadow_params.step = shadow_params.step.max(1.0);
        }
        RayCaster {
            scene,
            main: Tracer::new(scene.vol, &scene.accel, scene.params),
            shadow: Tracer::new(scene.vol, &scene.accel, shadow_params),
            hits: 0,
            rays: 0,
            first: FirstSurface::NONE,
        }
    }

    /// Work counters of every ray cast so far (camera and shadow rays).
    pub(crate) fn stats(&self) -> Stats {
        let mut s = self.main.stats;
        s += self.shadow.stats;
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
        (ray, jitter(x, y, s, st.seed, 0))
    }

    /// Colour of sample `s` of pixel (`x`, `y`).
    #[inline]
    pub(crate) fn sample(&mut self, x: u32, y: u32, s: u32) -> [f64; 3] {
        let (ray, jit) = self.camera_ray(x, y, s);
        self.trace(&ray, jit)
    }

    /// Colour seen along one camera ray.
    pub(crate) fn trace(&mut self, ray: &Ray, jit: f64) -> [f64; 3] {
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
        self.first = FirstSurface {
            t: t_max as f32,
            value: f32::NAN,
        };
        let bg = st.background.map(f64::from);
        let behind = |w: &mut Self| match mesh_hit {
            Some(h) => w.shade_mesh(ray, &h),
            None => bg,
        };
        match scene.params.tf.mode {
            Mode::Iso => match self.surface_within(ray, t_max, jit) {
                Some(s) => {
                    self.hits += 1;
                    self.first = FirstSurface {
                        t: (s.world - ray.origin).dot(ray.dir) as f32,
                        value: match (scene.params.colour_field, s.eval) {
                            (Some(_), Some(e)) => e.colour as f32,
                            _ => f32::NAN,
                        },
                    };
                    self.shade_surface(ray, &s)
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

    /// The iso-surface point along `ray` (iso mode, the view's strategy), with its
    /// shading normal.
    pub fn surface(&mut self, ray: &Ray, jit: f64) -> Option<SurfacePoint> {
        self.surface_within(ray, f64::INFINITY, jit)
    }

    fn surface_within(&mut self, ray: &Ray, t_max: f64, jit: f64) -> Option<SurfacePoint> {
        let vol = self.scene.vol;
        let o = vol.to_local(ray.origin.to_array());
        let hit = self.main.iso(o, ray.dir.to_array(), 0.0, t_max, jit)?;
        let eval = hit.eval;
        let e = eval.unwrap_or_default();
        let gradient = match self.scene.shading {
            Shading::Smooth => vol
                .shading_gradient_near(hit.region, hit.p, self.scene.params.field)
                .unwrap_or(e.grad),
            Shading::Analytic => e.grad,
        };
        let normal = facing(gradient, ray.dir);
        if let Some(Event::Hit { normal: n, .. }) =
            self.main.log.as_mut().and_then(|l| l.last_mut())
        {
            *n = Some(normal.to_array());
        }
        Some(SurfacePoint {
            world: DVec3::from_array(vol.to_world(hit.p)),
            local: hit.p,
            normal,
            eval,
        })
    }

    /// The first surface along `ray`: the iso-surface (found with `exact` root finding,
    /// whatever the view's mode and strategy) or a mesh, as a distance along the ray.
    #[cfg(feature = "gui")]
    pub(crate) fn first_surface(&mut self, ray: &Ray) -> Option<f64> {
        let scene = self.scene;
        let mesh_t = if scene.meshes.is_empty() {
            None
        } else {
            scene.meshes.intersect(ray, 0.0, f64::INFINITY).map(|h| h.t)
        };
        let mut params = scene.params;
        params.strategy = Strategy::Exact;
        params.tf.mode = Mode::Iso;
        let mut tracer = Tracer::new(scene.vol, &scene.accel, params);
        let o = scene.vol.to_local(ray.origin.to_array());
        let t_max = mesh_t.unwrap_or(f64::INFINITY);
        let iso_t = tracer
            .iso(o, ray.dir.to_array(), 0.0, t_max, 0.5)
            .map(|hit| {
                let p = DVec3::from_array(scene.vol.to_world(hit.p));
                (p - ray.origin).dot(ray.dir)
            });
        iso_t.or(mesh_t)
    }

    fn shade_mesh(&mut self, ray: &Ray, h: &MeshHit) -> [f64; 3] {
        let st = self.scene.state;
        let p = ray.at(h.t);
        let n = if h.normal.dot(ray.dir) > 0.0 {
            -h.normal
        } else {
            h.normal
        };
        let vis = self.visibility(p, n);
        phong(h.colour, n, -ray.dir, p, &st.lights, &vis, &st.material)
            .to_array()
            .map(f64::from)
    }

    /// Phong-shaded iso-surface point.
    fn shade_surface(&mut self, ray: &Ray, s: &SurfacePoint) -> [f64; 3] {
        let scene = self.scene;
        let st = scene.state;
        let base = base_colour(scene, &s.eval.unwrap_or_default(), s.eval.is_some());
        let n = s.normal;
        let pw = s.world;
        let vis = self.visibility(pw, n);
        phong(base, n, -ray.dir, pw, &st.lights, &vis, &st.material)
            .to_array()
            .map(f64::from)
    }

    /// Shadow transmittance towards every light from world point `p` with normal `n`.
    fn visibility(&mut self, p: DVec3, n: DVec3) -> Vec<f32> {
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

fn light_visibility(scene: &Scene, shadow: &mut Tracer, p: DVec3, n: DVec3, light: &Light) -> f32 {
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
    let n = match scene.shading {
        Shading::Smooth => facing(
            scene
                .vol
                .shading_gradient(*p, scene.params.field)
                .unwrap_or(e.grad),
            ray.dir,
        ),
        Shading::Analytic => facing(e.grad, ray.dir),
    };
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
