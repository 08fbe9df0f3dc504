//! Sphere wake: potential flow past a sphere plus a train of tilted vortex rings.

use super::{cross, dot, normalize, scale, sub, Flow, Gradient};
use std::f64::consts::PI;

/// One vortex ring, discretised into regularised vortex particles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ring {
    pub centre: [f64; 3],
    /// Unit normal; the ring's vorticity turns right-handed about it, so the ring pushes
    /// fluid through its centre along `+normal`.
    pub normal: [f64; 3],
    pub radius: f64,
    /// Circulation Γ.
    pub(crate) circulation: f64,
    /// Rosenhead–Moore core radius σ.
    pub core: f64,
}

impl Ring {
    /// Angular velocity at the centre of the core of a straight filament with the same Γ and
    /// σ: `ω₀ = Γ / (2π σ²)`. Q in the core is close to `ω₀²`.
    #[cfg(test)]
    pub(crate) fn core_omega(&self) -> f64 {
        self.circulation / (2.0 * PI * self.core * self.core)
    }

    /// Particles spaced at most σ/2 apart along the ring (so the ring looks smooth), each
    /// carrying `α = Γ · (arc length) · tangent`.
    fn particles(&self) -> Vec<Particle> {
        let n = normalize(self.normal);
        // Any vector not parallel to n gives the first in-plane axis.
        let helper = if n[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let e1 = normalize(cross(helper, n));
        let e2 = cross(n, e1);
        let circumference = 2.0 * PI * self.radius;
        let count = ((circumference / (0.5 * self.core)).ceil() as usize).max(8);
        let arc = circumference / count as f64;
        (0..count)
            .map(|m| {
                let (s, c) = (2.0 * PI * m as f64 / count as f64).sin_cos();
                let radial = [
                    c * e1[0] + s * e2[0],
                    c * e1[1] + s * e2[1],
                    c * e1[2] + s * e2[2],
                ];
                let tangent = cross(n, radial);
                Particle {
                    position: [
                        self.centre[0] + self.radius * radial[0],
                        self.centre[1] + self.radius * radial[1],
                        self.centre[2] + self.radius * radial[2],
                    ],
                    alpha: scale(tangent, self.circulation * arc),
                    core2: self.core * self.core,
                }
            })
            .collect()
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Particle {
    position: [f64; 3],
    alpha: [f64; 3],
    core2: f64,
}

/// Uniform flow `U` along +x past a sphere plus the velocity induced by vortex rings made
/// of Rosenhead–Moore particles: `u(x) = Σ α × r / (4π (|r|² + σ²)^{3/2})`, `r = x − x_p`.
///
/// Around the sphere the flow comes from the Stokes stream function `ψ = ½ U ρ² F(r)`:
/// with no boundary layer (`boundary_layer = 0`, the sample scene) it is potential flow
/// (slip on the surface); with `δ > 0` a no-slip layer of that thickness joins it smoothly.
/// Inside the sphere the velocity is uniform, continuing the surface's tangential velocity
/// (see [`Wake::interior_velocity`]). Every term is divergence-free outside the sphere and
/// has a closed-form gradient. The rings are not advected: this is a steady snapshot with
/// wake-like structure, not a solution of the Navier–Stokes equations.
///
/// Why the sample scene has no no-slip layer: the layer's curved shear makes Q positive
/// (up to ≈ 0.36 for δ = 0.1), which would coat the sphere with the iso-0.05 surface.
#[derive(Debug, Clone, PartialEq)]
pub struct Wake {
    pub(crate) free_stream: f64,
    pub sphere_centre: [f64; 3],
    pub sphere_radius: f64,
    /// Thickness δ of the no-slip layer on the sphere (0: slip, pure potential flow).
    pub boundary_layer: f64,
    pub rings: Vec<Ring>,
    particles: Vec<Particle>,
}

impl Wake {
    pub(crate) fn new(
        free_stream: f64,
        sphere_centre: [f64; 3],
        sphere_radius: f64,
        boundary_layer: f64,
        rings: Vec<Ring>,
    ) -> Self {
        let particles = rings.iter().flat_map(Ring::particles).collect();
        Wake {
            free_stream,
            sphere_centre,
            sphere_radius,
            boundary_layer,
            rings,
            particles,
        }
    }

    /// The `wake` scene: U = 0.06 along +x, sphere of radius 0.5 at the origin, six rings
    /// between x ≈ 1 and x ≈ 4.5, alternately tilted by ±0.4 rad about axes that turn
    /// around x, radius 0.30 → 0.45, core σ = 0.08 and core angular velocity
    /// 0.75 → 0.55 (core Q ≈ 0.56 → 0.30). The rings push fluid upstream through their
    /// centres, so the wake is slower than the free stream (speeds ≈ 0.005–0.09).
    pub fn sample_scene() -> Self {
        let core = 0.08;
        let rings = (0..6)
            .map(|k| {
                let kf = k as f64;
                let phase = 1.3 * kf + 0.4;
                let centre = [1.0 + 0.7 * kf, 0.1 * phase.sin(), 0.1 * phase.cos()];
                let tilt = if k % 2 == 0 { 0.4 } else { -0.4 };
                let axis = [0.0, (0.9 * kf).cos(), (0.9 * kf).sin()];
                let normal = rotate([-1.0, 0.0, 0.0], axis, tilt);
                let omega0 = 0.75 - 0.04 * kf;
                Ring {
                    centre,
                    normal,
                    radius: 0.30 + 0.03 * kf,
                    circulation: 2.0 * PI * core * core * omega0,
                    core,
                }
            })
            .collect();
        Wake::new(0.06, [0.0; 3], 0.5, SAMPLE_BOUNDARY_LAYER, rings)
    }

    /// Radial profile of the sphere flow's Stokes stream function
    /// `ψ = ½ U ρ² F(r)` (ρ the distance from the x axis through the centre):
    /// `F = S((r − a) / δ) · (1 − a³ / r³)` with the ramp `S(t) = 1 − (1 − t)³` on [0, 1]
    /// and 1 beyond. `S(0) = 0` gives `F(a) = F'(a) = 0`, i.e. no slip on the sphere; for
    /// `r ≥ a + δ` this is exactly potential flow, joined with continuous second
    /// derivatives. Returns `(F, F', F'')` in r.
    fn profile(&self, r: f64) -> (f64, f64, f64) {
        let a3 = self.sphere_radius.powi(3);
        let p = 1.0 - a3 / (r * r * r);
        let p1 = 3.0 * a3 / r.powi(4);
        let p2 = -12.0 * a3 / r.powi(5);
        let d = self.boundary_layer;
        let t = if d > 0.0 {
            (r - self.sphere_radius) / d
        } else {
            1.0
        };
        if t >= 1.0 {
            return (p, p1, p2);
        }
        let m = 1.0 - t;
        let (s0, s1, s2) = (1.0 - m * m * m, 3.0 * m * m / d, -6.0 * m / (d * d));
        (s0 * p, s1 * p + s0 * p1, s2 * p + 2.0 * s1 * p1 + s0 * p2)
    }

    /// Velocity of the sphere flow from its stream function (so it is divergence-free for
    /// any profile): `u = U [(F + G ρ²) e_x − G x (0, y, z)]` with `G = F' / (2r)`, in
    /// coordinates `r` relative to the sphere centre.
    fn sphere_velocity(&self, r: [f64; 3]) -> [f64; 3] {
        let rr = dot(r, r).sqrt();
        let (f, f1, _) = self.profile(rr);
        let g = f1 / (2.0 * rr);
        let rho2 = r[1] * r[1] + r[2] * r[2];
        let u = self.free_stream;
        [
            u * (f + g * rho2),
            -u * g * r[0] * r[1],
            -u * g * r[0] * r[2],
        ]
    }

    /// Gradient of [`Self::sphere_velocity`]:
    /// `∂u_0/∂x_j = U (F' x_j / r + G' ρ² x_j / r + 2 G ρ_j)` and, for i = 1, 2,
    /// `∂u_i/∂x_j = −U (G' x ρ_i x_j / r + G (δ_j0 ρ_i + x δ_ij))`, with ρ_j = (0, y, z)_j
    /// and `G' = F'' / (2r) − F' / (2r²)`.
    fn sphere_gradient(&self, r: [f64; 3]) -> Gradient {
        let rr = dot(r, r).sqrt();
        let (_, f1, f2) = self.profile(rr);
        let g = f1 / (2.0 * rr);
        let g1 = f2 / (2.0 * rr) - f1 / (2.0 * rr * rr);
        let rho = [0.0, r[1], r[2]];
        let rho2 = r[1] * r[1] + r[2] * r[2];
        let u = self.free_stream;
        let x = r[0];
        let mut out = [[0.0; 3]; 3];
        for j in 0..3 {
            let nj = r[j] / rr;
            out[0][j] = u * (f1 * nj + g1 * rho2 * nj + 2.0 * g * rho[j]);
            for i in 1..3 {
                let mut v = g1 * x * rho[i] * nj;
                if j == 0 {
                    v += g * rho[i];
                }
                if i == j {
                    v += g * x;
                }
                out[i][j] = -u * v;
            }
        }
        out
    }

    /// The uniform velocity (along x) inside the sphere: `U a F'(a) / 2`, whose tangential
    /// part on the surface equals the outside flow's (1.5 U for the slip sphere, 0 with a
    /// no-slip layer). Finite differences across the surface then see only a jump in the
    /// normal component, which reads as strain (Q < 0); a zero interior under slip flow
    /// would be a vortex sheet and give a spurious skin of large positive Q.
    pub(crate) fn interior_velocity(&self) -> f64 {
        let a = self.sphere_radius;
        let (_, f1, _) = self.profile(a);
        0.5 * self.free_stream * a * f1
    }

    fn inside_sphere(&self, r: [f64; 3]) -> bool {
        dot(r, r) < self.sphere_radius * self.sphere_radius
    }
}

/// No-slip layer thickness of the `wake` scene.
pub(crate) const SAMPLE_BOUNDARY_LAYER: f64 = 0.0;

/// Rotates `v` by `angle` about the unit `axis` (Rodrigues).
fn rotate(v: [f64; 3], axis: [f64; 3], angle: f64) -> [f64; 3] {
    let k = normalize(axis);
    let (s, c) = angle.sin_cos();
    let kxv = cross(k, v);
    let kv = dot(k, v) * (1.0 - c);
    [
        v[0] * c + kxv[0] * s + k[0] * kv,
        v[1] * c + kxv[1] * s + k[1] * kv,
        v[2] * c + kxv[2] * s + k[2] * kv,
    ]
}

impl Flow for Wake {
    fn velocity(&self, p: [f64; 3]) -> [f64; 3] {
        let r = sub(p, self.sphere_centre);
        if self.inside_sphere(r) {
            return [self.interior_velocity(), 0.0, 0.0];
        }
        let mut u = self.sphere_velocity(r);
        // Vortex particles.
        let mut w = [0.0; 3];
        for part in &self.particles {
            let d = sub(p, part.position);
            let d2 = dot(d, d) + part.core2;
            let f = 1.0 / (d2 * d2.sqrt());
            let c = cross(part.alpha, d);
            w[0] += c[0] * f;
            w[1] += c[1] * f;
            w[2] += c[2] * f;
        }
        let inv4pi = 0.25 / PI;
        for i in 0..3 {
            u[i] += w[i] * inv4pi;
        }
        u
    }

    fn gradient(&self, p: [f64; 3]) -> Gradient {
        let r = sub(p, self.sphere_centre);
        if self.inside_sphere(r) {
            return [[0.0; 3]; 3];
        }
        let mut g = self.sphere_gradient(r);
        // Vortex particles: u = α × d f / 4π with f = (|d|² + σ²)^{-3/2}, so
        // ∂u_i/∂x_j = (ε_ikj α_k f − 3 (α × d)_i d_j f / (|d|² + σ²)) / 4π.
        let mut acc = [[0.0; 3]; 3];
        for part in &self.particles {
            let d = sub(p, part.position);
            let d2 = dot(d, d) + part.core2;
            let f = 1.0 / (d2 * d2.sqrt());
            let h = 3.0 * f / d2;
            let a = part.alpha;
            let c = cross(a, d);
            let m = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
            for i in 0..3 {
                for j in 0..3 {
                    acc[i][j] += m[i][j] * f - c[i] * d[j] * h;
                }
            }
        }
        let inv4pi = 0.25 / PI;
        for i in 0..3 {
            for j in 0..3 {
                g[i][j] += acc[i][j] * inv4pi;
            }
        }
        g
    }

    /// False within `radius` of the sphere surface (velocity only continuous there) and of
    /// the end of the no-slip layer (C² there, but not C³).
    fn is_smooth_near(&self, p: [f64; 3], radius: f64) -> bool {
        let r = sub(p, self.sphere_centre);
        let rr = dot(r, r).sqrt();
        let a = self.sphere_radius;
        let layer_end = a + self.boundary_layer;
        (rr - a).abs() > radius && (self.boundary_layer <= 0.0 || (rr - layer_end).abs() > radius)
    }
}

#[cfg(test)]
mod tests {
    use super::super::testutil::{check_flow, Rng};
    use super::super::{q_from_gradient, speed};
    use super::*;

    #[test]
    fn wake_gradient_matches_finite_differences_outside_the_sphere() {
        let w = Wake::sample_scene();
        let mut rng = Rng::new(21);
        let mut checked = 0;
        while checked < 150 {
            let p = rng.point([-2.0, -2.0, -2.0], [6.0, 2.0, 2.0]);
            // Stay a finite-difference step away from the sphere surface.
            if (dot(p, p).sqrt() - 0.5).abs() < 1e-3 {
                continue;
            }
            check_flow(&w, p, p, 1, checked);
            checked += 1;
        }
        // Near the ring cores, where the gradient is largest.
        for ring in &w.rings {
            let lo = sub(ring.centre, [0.5; 3]);
            let hi = [lo[0] + 1.0, lo[1] + 1.0, lo[2] + 1.0];
            check_flow(&w, lo, hi, 30, 99);
        }
    }

    #[test]
    fn slip_sphere_is_potential_flow() {
        let w = Wake::new(0.06, [0.0; 3], 0.5, 0.0, Vec::new());
        let mut rng = Rng::new(22);
        for _ in 0..100 {
            let d = normalize(rng.point([-1.0; 3], [1.0; 3]));
            let p = scale(d, 0.5 + 1e-12);
            assert!(dot(w.velocity(p), d).abs() < 1e-10);
            // Irrotational: Q = -½‖S‖² < 0 outside.
            let q = q_from_gradient(&w.gradient(scale(d, 0.7)));
            assert!(q < 0.0);
            // The dipole formula u = U e_x + (U a³ / 2) (e_x / r³ − 3 x r / r⁵).
            let p = scale(d, 0.5 + rng.next_f64());
            let r2 = dot(p, p);
            let k = 0.5 * 0.06 * 0.125;
            let u = w.velocity(p);
            for i in 0..3 {
                let e = if i == 0 { 1.0 } else { 0.0 };
                let want = 0.06 * e + k * (e / r2.powf(1.5) - 3.0 * p[0] * p[i] / r2.powf(2.5));
                assert!((u[i] - want).abs() < 1e-15, "{u:?}");
            }
        }
        check_flow(&w, [-2.0; 3], [2.0; 3], 100, 23);
        // Stagnation point upstream, 1.5 U at the equator, U far away.
        assert!(speed(&w.velocity([-0.5 - 1e-9, 0.0, 0.0])) < 1e-8);
        assert!((w.velocity([0.0, 0.5 + 1e-12, 0.0])[0] - 0.09).abs() < 1e-9);
        assert!((w.velocity([-1e4, 3.0, 0.0])[0] - 0.06).abs() < 1e-9);
        // Inside: 1.5 U along x, the surface's tangential velocity continued.
        assert_eq!(w.velocity([0.1, 0.1, 0.1]), [0.09, 0.0, 0.0]);
        let d = normalize([0.2, -0.5, 0.7]);
        let (inside, outside) = (
            w.velocity(scale(d, 0.5 - 1e-12)),
            w.velocity(scale(d, 0.5 + 1e-12)),
        );
        let tangential = |u: [f64; 3]| sub(u, scale(d, dot(u, d)));
        let jump = sub(tangential(inside), tangential(outside));
        assert!(dot(jump, jump).sqrt() < 1e-9);
    }

    #[test]
    fn finite_differences_across_the_sphere_surface_give_no_positive_q_skin() {
        // Central differences at the finest voxel size of `synth wake --n0 160`, at points
        // whose stencil straddles the surface: the normal-velocity jump reads as strain, so
        // Q ≤ 0 there (what the README states), not merely below the iso value.
        let w = Wake::sample_scene();
        let h = 0.0125;
        let mut rng = Rng::new(25);
        for _ in 0..2000 {
            let d = normalize(rng.point([-1.0; 3], [1.0; 3]));
            let p = scale(d, 0.5 + 3.0 * h * rng.next_f64());
            let q = q_from_gradient(&super::super::testutil::fd_gradient(&w, p, h));
            assert!(q <= 0.0, "FD Q {q} at {p:?}");
        }
        assert!(w.is_smooth_near([2.0, 0.0, 0.0], 0.1));
        assert!(!w.is_smooth_near([0.0, 0.5 + 0.5 * h, 0.0], h));
        assert!(!w.is_smooth_near([0.0, 0.5 - 0.5 * h, 0.0], h));
    }

    #[test]
    fn no_slip_layer_is_smooth_divergence_free_and_matches_potential_flow_outside() {
        let w = Wake::new(0.06, [0.0; 3], 0.5, 0.1, Vec::new());
        let slip = Wake::new(0.06, [0.0; 3], 0.5, 0.0, Vec::new());
        let mut rng = Rng::new(24);
        for n in 0..200 {
            let d = normalize(rng.point([-1.0; 3], [1.0; 3]));
            // No slip on the surface, and at rest inside.
            assert!(speed(&w.velocity(scale(d, 0.5 + 1e-12))) < 1e-9);
            assert_eq!(w.velocity(scale(d, 0.3)), [0.0; 3]);
            // Exact potential flow beyond the layer.
            let p = scale(d, 0.6 + rng.next_f64());
            assert_eq!(w.velocity(p), slip.velocity(p));
            // Gradient and divergence inside the layer.
            let p = scale(d, 0.5 + 1e-4 + 0.0998 * rng.next_f64());
            check_flow(&w, p, p, 1, n);
        }
        // Continuous velocity and gradient where the layer ends.
        let d = normalize([0.3, 0.8, -0.2]);
        let (a, b) = (scale(d, 0.6 - 1e-9), scale(d, 0.6 + 1e-9));
        let (ga, gb) = (w.gradient(a), w.gradient(b));
        for i in 0..3 {
            for j in 0..3 {
                assert!((ga[i][j] - gb[i][j]).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn ring_cores_have_the_advertised_q_and_the_wake_is_slow() {
        let w = Wake::sample_scene();
        for ring in &w.rings {
            // Core centre: a point on the ring.
            let n = normalize(ring.normal);
            let helper = if n[0].abs() < 0.9 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            };
            let e1 = normalize(cross(helper, n));
            let core_centre = [
                ring.centre[0] + ring.radius * e1[0],
                ring.centre[1] + ring.radius * e1[1],
                ring.centre[2] + ring.radius * e1[2],
            ];
            let q = w.q(core_centre);
            let q0 = ring.core_omega().powi(2);
            assert!(q > 0.7 * q0 && q < 1.3 * q0, "core Q {q} vs ω₀² {q0}");
            assert!((0.25..0.65).contains(&q), "{q}");
            let s = speed(&w.velocity(ring.centre));
            assert!(s > 0.005 && s < 0.06, "ring-centre speed {s}");
        }
    }
}
