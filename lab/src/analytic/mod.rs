//! Closed-form flows with exact velocity gradients (and so exact Q, λ2, vorticity and
//! helicity).
//!
//! These are the ground truth for accuracy tests and the source of the synthetic VDB scenes
//! written by `qbricks-lab synth` (see [`crate::synth`]). Every flow gives its velocity and
//! its velocity gradient in closed form at any point; Q, λ2, the vorticity and the helicity
//! follow from the gradient through [`preprocess::measures`], the functions the bake uses.
//!
//! | scene name | flow | what it is for |
//! |---|---|---|
//! | `wake` | [`Wake`] on nested boxes | the sample scene: a sphere in uniform flow with a train of tilted vortex rings behind it |
//! | `wake-single` | [`Wake`] on one grid | the same flow at a single resolution |
//! | `lamb-oseen` | [`LambOseen`] | a straight Gaussian vortex; Q known in closed form |
//! | `burgers` | [`Burgers`] | Lamb–Oseen plus axisymmetric strain; Q = Q_Lamb–Oseen − ¾α² |
//! | `abc` | [`Abc`] | Arnold–Beltrami–Childress flow (vorticity = k · velocity) |
//! | `lamb-oseen-nested`, `burgers-nested`, `abc-nested` | the same flows on nested boxes | accuracy across level boundaries |
//! | `ring-plume` | [`RingPlume`] per frame | a rising vortex ring with a smoke plume: a small frame sequence |

// Tensor formulas read best with explicit indices.
#![allow(clippy::needless_range_loop)]

mod abc;
mod plume;
mod vortex;
mod wake;

pub use abc::Abc;
pub use plume::RingPlume;
pub use vortex::{Burgers, LambOseen};
pub use wake::{Ring, Wake};

/// Velocity gradient: `g[i][j] = ∂u_i/∂x_j`.
pub(crate) type Gradient = [[f64; 3]; 3];

/// A steady velocity field given in closed form.
pub trait Flow: Send + Sync {
    /// Velocity at world-space point `p`.
    fn velocity(&self, p: [f64; 3]) -> [f64; 3];
    /// Velocity gradient at `p`, `g[i][j] = ∂u_i/∂x_j`.
    fn gradient(&self, p: [f64; 3]) -> Gradient;
    /// Q-criterion at `p`.
    fn q(&self, p: [f64; 3]) -> f64 {
        measures::q(&self.gradient(p))
    }
    /// Vorticity magnitude `|∇ × u|` at `p`.
    fn vorticity(&self, p: [f64; 3]) -> f64 {
        measures::vorticity_magnitude(&self.gradient(p))
    }
    /// λ2 at `p`: the middle eigenvalue of `S² + Ω²`, negative in vortex cores.
    fn lambda2(&self, p: [f64; 3]) -> f64 {
        measures::lambda2(&self.gradient(p))
    }
    /// Normalised helicity `u · ω / (|u| |ω|)` at `p`.
    fn helicity(&self, p: [f64; 3]) -> f64 {
        measures::helicity(&self.velocity(p), &self.gradient(p))
    }
    /// Every exact measure at `p` from one velocity and one gradient evaluation (the wake's
    /// cost a sum over all its vortex particles each).
    fn exact(&self, p: [f64; 3]) -> Exact {
        let u = self.velocity(p);
        let g = self.gradient(p);
        Exact {
            q: measures::q(&g),
            speed: speed(&u),
            vorticity: measures::vorticity_magnitude(&g),
            lambda2: measures::lambda2(&g),
            helicity: measures::helicity(&u, &g),
        }
    }
    /// Whether the velocity is smooth (at least C²) in the ball of `radius` around `p`, so
    /// that finite-difference stencils of that reach converge there. Accuracy tests use it
    /// to stay away from surfaces where a flow is only continuous (the wake's sphere).
    fn is_smooth_near(&self, _p: [f64; 3], _radius: f64) -> bool {
        true
    }
}

/// The exact values of the baked fields at a point ([`Flow::exact`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Exact {
    pub q: f64,
    pub speed: f64,
    pub vorticity: f64,
    pub lambda2: f64,
    pub helicity: f64,
}

/// The exact Q, λ2, vorticity, helicity and speed of a flow use the same formulas as the
/// baked fields (on the closed-form gradient instead of the stencil's), so a difference
/// between them is the discretisation's, never a second formula's.
pub use preprocess::derive::speed;
use preprocess::measures;
#[cfg(test)]
use preprocess::measures::q as q_from_gradient;

/// Names accepted by [`scene`], in documentation order.
pub(crate) const SCENE_NAMES: [&str; 9] = [
    "wake",
    "wake-single",
    "lamb-oseen",
    "burgers",
    "abc",
    "ring-plume",
    "lamb-oseen-nested",
    "burgers-nested",
    "abc-nested",
];

/// The flow of a named scene ([`SCENE_NAMES`]), or `None` for an unknown name. `wake` and
/// `wake-single` are the same flow, and so are `lamb-oseen` and `lamb-oseen-nested` (and
/// the other `-nested` scenes); they differ only in how [`crate::synth`] samples it.
pub fn scene(name: &str) -> Option<Box<dyn Flow + Send + Sync>> {
    scene_at(name, 1)
}

/// As [`scene`], at frame `frame` (1-based) for the time-dependent `ring-plume`; the other
/// scenes are steady and ignore it.
pub(crate) fn scene_at(name: &str, frame: u64) -> Option<Box<dyn Flow + Send + Sync>> {
    if name == "ring-plume" {
        return Some(Box::new(RingPlume::frame(frame)));
    }
    match name {
        "wake" | "wake-single" => Some(Box::new(Wake::sample_scene())),
        "lamb-oseen" | "lamb-oseen-nested" => Some(Box::new(LambOseen::sample_scene())),
        "burgers" | "burgers-nested" => Some(Box::new(Burgers::sample_scene())),
        "abc" | "abc-nested" => Some(Box::new(Abc::sample_scene())),
        "ring-plume" => Some(Box::new(RingPlume::frame(1))),
        _ => None,
    }
}

// Small vector helpers shared by the flows.

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub(crate) fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        scale(a, 1.0 / n)
    } else {
        a
    }
}

#[cfg(test)]
pub(crate) mod testutil {
    use super::{Flow, Gradient};

    /// Deterministic pseudo-random numbers in [0, 1) (xorshift64*).
    pub(crate) struct Rng(u64);

    impl Rng {
        pub(crate) fn new(seed: u64) -> Self {
            Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
        }
        pub(crate) fn next_f64(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            let v = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
            (v >> 11) as f64 / (1u64 << 53) as f64
        }
        pub(crate) fn point(&mut self, lo: [f64; 3], hi: [f64; 3]) -> [f64; 3] {
            [
                lo[0] + (hi[0] - lo[0]) * self.next_f64(),
                lo[1] + (hi[1] - lo[1]) * self.next_f64(),
                lo[2] + (hi[2] - lo[2]) * self.next_f64(),
            ]
        }
    }

    /// Central finite-difference gradient of the velocity with step `h`.
    pub(crate) fn fd_gradient(flow: &dyn Flow, p: [f64; 3], h: f64) -> Gradient {
        let mut g = [[0.0; 3]; 3];
        for j in 0..3 {
            let mut a = p;
            let mut b = p;
            a[j] += h;
            b[j] -= h;
            let ua = flow.velocity(a);
            let ub = flow.velocity(b);
            for i in 0..3 {
                g[i][j] = (ua[i] - ub[i]) / (2.0 * h);
            }
        }
        g
    }

    /// Largest |a - b| over the nine entries, relative to `max(1e-12, max |a|)`.
    pub(crate) fn max_rel_diff(a: &Gradient, b: &Gradient) -> f64 {
        let mut scale = 1e-12f64;
        let mut diff = 0.0f64;
        for i in 0..3 {
            for j in 0..3 {
                scale = scale.max(a[i][j].abs());
                diff = diff.max((a[i][j] - b[i][j]).abs());
            }
        }
        diff / scale
    }

    /// Checks gradient against central differences and divergence at `n` random points.
    pub(crate) fn check_flow(flow: &dyn Flow, lo: [f64; 3], hi: [f64; 3], n: usize, seed: u64) {
        let mut rng = Rng::new(seed);
        for _ in 0..n {
            let p = rng.point(lo, hi);
            let g = flow.gradient(p);
            let fd = fd_gradient(flow, p, 1e-5);
            let rel = max_rel_diff(&g, &fd);
            assert!(
                rel < 1e-5,
                "gradient at {p:?}: {g:?} vs fd {fd:?} (rel {rel})"
            );
            let div = g[0][0] + g[1][1] + g[2][2];
            let gmax = g.iter().flatten().fold(1e-12f64, |m, v| m.max(v.abs()));
            assert!(
                div.abs() < 1e-10 * gmax.max(1.0),
                "divergence {div} at {p:?}"
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn q_of_solid_rotation_is_omega_squared() {
        // u = ω × x with ω = (0, 0, w): g = [[0, -w, 0], [w, 0, 0], [0, 0, 0]].
        let w = 0.7;
        let g = [[0.0, -w, 0.0], [w, 0.0, 0.0], [0.0, 0.0, 0.0]];
        let q = q_from_gradient(&g);
        assert!((q - w * w).abs() < 1e-15, "{q}");
    }

    #[test]
    fn q_of_pure_strain_is_negative() {
        let a = 0.3;
        let g = [[a, 0.0, 0.0], [0.0, -a, 0.0], [0.0, 0.0, 0.0]];
        let q = q_from_gradient(&g);
        assert!((q + a * a).abs() < 1e-15, "{q}");
        // Simple shear: rotation and strain balance.
        let g = [[0.0, a, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]];
        assert!(q_from_gradient(&g).abs() < 1e-15);
    }

    #[test]
    fn q_equals_minus_half_trace_of_g_squared() {
        let mut rng = testutil::Rng::new(7);
        for _ in 0..20 {
            let mut g = [[0.0; 3]; 3];
            for row in g.iter_mut() {
                for v in row.iter_mut() {
                    *v = rng.next_f64() * 2.0 - 1.0;
                }
            }
            let mut tr = 0.0;
            for i in 0..3 {
                for j in 0..3 {
                    tr += g[i][j] * g[j][i];
                }
            }
            assert!((q_from_gradient(&g) + 0.5 * tr).abs() < 1e-12);
        }
    }

    #[test]
    fn every_scene_name_resolves() {
        for name in SCENE_NAMES {
            let flow = scene(name).expect(name);
            let u = flow.velocity([0.1, 0.2, 0.3]);
            assert!(u.iter().all(|v| v.is_finite()), "{name}");
        }
        assert!(scene("nope").is_none());
    }
}
