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
    pub circulation: f64,
    /// Rosenhead–Moore core radius σ.
    pub core: f64,
}

impl Ring {
    /// Angular velocity at the centre of the core of a straight filament with the same Γ and
    /// σ: `ω₀ = Γ / (2π σ²)`. Q in the core is close to `ω₀²`.
    pub fn core_omega(&self) -> f64 {
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

/// Uniform flow `U` along +x past a solid sphere (potential flow, zero velocity inside the
/// sphere) plus the velocity induced by vortex rings made of Rosenhead–Moore particles:
/// `u(x) = Σ α × r / (4π (|r|² + σ²)^{3/2})`, `r = x − x_p`.
///
/// Every term is divergence-free and has a closed-form gradient. The rings are not
/// advected: this is a steady snapshot with wake-like structure, not a solution of the
/// Navier–Stokes equations.
#[derive(Debug, Clone, PartialEq)]
pub struct Wake {
    pub free_stream: f64,
    pub sphere_centre: [f64; 3],
    pub sphere_radius: f64,
    pub rings: Vec<Ring>,
    particles: Vec<Particle>,
}

impl Wake {
    pub fn new(
        free_stream: f64,
        sphere_centre: [f64; 3],
        sphere_radius: f64,
        rings: Vec<Ring>,
    ) -> Self {
        let particles = rings.iter().flat_map(Ring::particles).collect();
        Wake {
            free_stream,
            sphere_centre,
            sphere_radius,
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
        Wake::new(0.06, [0.0; 3], 0.5, rings)
    }

    /// Number of vortex particles.
    pub fn particle_count(&self) -> usize {
        self.particles.len()
    }

    fn inside_sphere(&self, r: [f64; 3]) -> bool {
        dot(r, r) < self.sphere_radius * self.sphere_radius
    }
}

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
            return [0.0; 3];
        }
        // Potential flow: φ = U x (1 + a³ / (2 r³)).
        let r2 = dot(r, r);
        let inv_r = 1.0 / r2.sqrt();
        let inv_r3 = inv_r * inv_r * inv_r;
        let inv_r5 = inv_r3 * inv_r * inv_r;
        let k = 0.5 * self.free_stream * self.sphere_radius.powi(3);
        let mut u = [
            self.free_stream + k * (inv_r3 - 3.0 * r[0] * r[0] * inv_r5),
            -k * 3.0 * r[0] * r[1] * inv_r5,
            -k * 3.0 * r[0] * r[2] * inv_r5,
        ];
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
        // Potential flow: u_i = U δ_i0 + k (δ_i0 / r³ − 3 x r_i / r⁵), so
        // ∂u_i/∂x_j = k (−3 δ_i0 r_j / r⁵ − 3 (δ_0j r_i + x δ_ij) / r⁵ + 15 x r_i r_j / r⁷).
        let r2 = dot(r, r);
        let inv_r2 = 1.0 / r2;
        let inv_r5 = inv_r2 * inv_r2 * inv_r2.sqrt();
        let k = 0.5 * self.free_stream * self.sphere_radius.powi(3);
        let x = r[0];
        let mut g = [[0.0; 3]; 3];
        for (i, row) in g.iter_mut().enumerate() {
            for (j, gij) in row.iter_mut().enumerate() {
                let mut v = 15.0 * x * r[i] * r[j] * inv_r2;
                if i == 0 {
                    v -= 3.0 * r[j];
                }
                if j == 0 {
                    v -= 3.0 * r[i];
                }
                if i == j {
                    v -= 3.0 * x;
                }
                *gij = k * v * inv_r5;
            }
        }
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
    fn sphere_potential_flow_has_no_normal_velocity_and_negative_q() {
        let w = Wake::new(0.06, [0.0; 3], 0.5, Vec::new());
        let mut rng = Rng::new(22);
        for _ in 0..100 {
            let d = normalize(rng.point([-1.0; 3], [1.0; 3]));
            let p = scale(d, 0.5 + 1e-12);
            assert!(dot(w.velocity(p), d).abs() < 1e-10);
            // Irrotational: Q = -½‖S‖² < 0 outside.
            let q = q_from_gradient(&w.gradient(scale(d, 0.7)));
            assert!(q < 0.0);
        }
        // Stagnation point upstream, 1.5 U at the equator, U far away.
        assert!(speed(w.velocity([-0.5 - 1e-9, 0.0, 0.0])) < 1e-8);
        assert!((w.velocity([0.0, 0.5 + 1e-12, 0.0])[0] - 0.09).abs() < 1e-9);
        assert!((w.velocity([-1e4, 3.0, 0.0])[0] - 0.06).abs() < 1e-9);
        assert_eq!(w.velocity([0.1, 0.1, 0.1]), [0.0; 3]);
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
            let s = speed(w.velocity(ring.centre));
            assert!(s > 0.005 && s < 0.06, "ring-centre speed {s}");
        }
    }
}
