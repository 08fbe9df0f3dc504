//! Straight vortices along the z axis: Lamb–Oseen and Burgers.

use super::{Flow, Gradient};
use std::f64::consts::PI;

/// Lamb–Oseen vortex along the z axis through the origin:
/// `u_θ(r) = Γ / (2π r) · (1 − exp(−r² / r_c²))`, no axial or radial flow.
///
/// Near the axis it turns like a solid body with angular velocity `ω₀ = Γ / (2π r_c²)`,
/// so Q on the axis is `ω₀²`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LambOseen {
    /// Circulation Γ.
    pub(crate) circulation: f64,
    /// Core radius r_c.
    pub(crate) core_radius: f64,
}

impl LambOseen {
    /// The `lamb-oseen` scene: r_c = 0.25, ω₀ = 0.7 (axis Q = 0.49), domain [-1, 1]³.
    pub(crate) fn sample_scene() -> Self {
        let core_radius = 0.25;
        LambOseen {
            circulation: 2.0 * PI * core_radius * core_radius * 0.7,
            core_radius,
        }
    }

    /// Angular velocity ω(s) = u_θ / r and its derivative dω/ds, as functions of s = r².
    fn omega(&self, s: f64) -> (f64, f64) {
        let c = self.core_radius * self.core_radius;
        let w0 = self.circulation / (2.0 * PI * c);
        let x = s / c;
        // φ(x) = (1 − e^{−x}) / x and φ'(x); a series near 0 avoids cancellation.
        let (phi, dphi) = if x < 1e-3 {
            (
                1.0 - x / 2.0 + x * x / 6.0 - x * x * x / 24.0,
                -0.5 + x / 3.0 - x * x / 8.0,
            )
        } else {
            let one_minus = -(-x).exp_m1();
            (one_minus / x, ((-x).exp() * x - one_minus) / (x * x))
        };
        (w0 * phi, w0 * dphi / c)
    }

    /// Q in closed form from the swirl profile: `Q = (u_θ / r) · du_θ/dr`.
    #[cfg(test)]
    pub(crate) fn q_exact(&self, p: [f64; 3]) -> f64 {
        let s = p[0] * p[0] + p[1] * p[1];
        let (w, dw) = self.omega(s);
        w * (w + 2.0 * s * dw)
    }
}

impl Flow for LambOseen {
    fn velocity(&self, p: [f64; 3]) -> [f64; 3] {
        let (w, _) = self.omega(p[0] * p[0] + p[1] * p[1]);
        [-w * p[1], w * p[0], 0.0]
    }

    fn gradient(&self, p: [f64; 3]) -> Gradient {
        let [x, y, _] = p;
        let (w, dw) = self.omega(x * x + y * y);
        [
            [-2.0 * x * y * dw, -w - 2.0 * y * y * dw, 0.0],
            [w + 2.0 * x * x * dw, 2.0 * x * y * dw, 0.0],
            [0.0, 0.0, 0.0],
        ]
    }
}

/// Burgers vortex: a Lamb–Oseen swirl held steady by axisymmetric strain
/// `(−α x / 2, −α y / 2, α z)`. Its Q is the swirl's Q minus `¾ α²`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Burgers {
    pub swirl: LambOseen,
    /// Strain rate α (> 0 stretches along z).
    pub strain: f64,
}

impl Burgers {
    /// The `burgers` scene: the `lamb-oseen` swirl with α = 0.2, domain [-1, 1]³.
    pub(crate) fn sample_scene() -> Self {
        Burgers {
            swirl: LambOseen::sample_scene(),
            strain: 0.2,
        }
    }

    /// Q in closed form.
    #[cfg(test)]
    pub(crate) fn q_exact(&self, p: [f64; 3]) -> f64 {
        self.swirl.q_exact(p) - 0.75 * self.strain * self.strain
    }
}

impl Flow for Burgers {
    fn velocity(&self, p: [f64; 3]) -> [f64; 3] {
        let u = self.swirl.velocity(p);
        let a = self.strain;
        [u[0] - 0.5 * a * p[0], u[1] - 0.5 * a * p[1], a * p[2]]
    }

    fn gradient(&self, p: [f64; 3]) -> Gradient {
        let mut g = self.swirl.gradient(p);
        g[0][0] -= 0.5 * self.strain;
        g[1][1] -= 0.5 * self.strain;
        g[2][2] += self.strain;
        g
    }
}

#[cfg(test)]
mod tests {
    use super::super::testutil::check_flow;
    use super::*;

    #[test]
    fn lamb_oseen_gradient_matches_finite_differences() {
        let f = LambOseen::sample_scene();
        check_flow(&f, [-1.0; 3], [1.0; 3], 200, 1);
        // Close to the axis, where the series branch is used.
        check_flow(&f, [-0.005; 3], [0.005; 3], 50, 2);
    }

    #[test]
    fn burgers_gradient_matches_finite_differences() {
        check_flow(&Burgers::sample_scene(), [-1.0; 3], [1.0; 3], 200, 3);
    }

    #[test]
    fn lamb_oseen_q_on_axis_and_far_away() {
        let f = LambOseen::sample_scene();
        assert!((f.q([0.0, 0.0, 0.3]) - 0.49).abs() < 1e-12);
        // Q changes sign outside the core: strain dominates at r ≫ r_c.
        assert!(f.q([0.6, 0.0, 0.0]) < 0.0);
        let mut rng = super::super::testutil::Rng::new(4);
        for _ in 0..100 {
            let p = rng.point([-1.0; 3], [1.0; 3]);
            assert!((f.q(p) - f.q_exact(p)).abs() < 1e-12);
        }
    }

    /// Lamb–Oseen: ω_z = (1/r) d(r u_θ)/dr = 2 ω₀ exp(−r²/r_c²); in a plane flow λ2 = −Q;
    /// u ⟂ ω, so no helicity.
    #[test]
    fn lamb_oseen_vorticity_lambda2_and_helicity_in_closed_form() {
        let f = LambOseen::sample_scene();
        let c = f.core_radius * f.core_radius;
        let w0 = f.circulation / (2.0 * PI * c);
        let mut rng = super::super::testutil::Rng::new(6);
        for _ in 0..200 {
            let p = rng.point([-1.0; 3], [1.0; 3]);
            let s = p[0] * p[0] + p[1] * p[1];
            let wz = 2.0 * w0 * (-s / c).exp();
            assert!((f.vorticity(p) - wz).abs() < 1e-12, "{p:?}");
            assert!((f.lambda2(p) + f.q_exact(p)).abs() < 1e-7, "{p:?}");
            assert_eq!(f.helicity(p), 0.0);
        }
        // On the axis: solid-body rotation, λ2 = −ω₀², vorticity 2ω₀, zero velocity.
        let axis = [0.0, 0.0, 0.4];
        assert!((f.lambda2(axis) + w0 * w0).abs() < 1e-12);
        assert!((f.vorticity(axis) - 2.0 * w0).abs() < 1e-12);
        assert_eq!(f.helicity(axis), 0.0);
    }

    /// Burgers: the strain is irrotational (same vorticity as the swirl); on the axis S and Ω
    /// commute, S² + Ω² = diag(α²/4 − ω₀², α²/4 − ω₀², α²) and λ2 = α²/4 − ω₀²; the axial
    /// flow along ω gives helicity sign(z) on the axis.
    #[test]
    fn burgers_vorticity_lambda2_and_helicity_in_closed_form() {
        let f = Burgers::sample_scene();
        let c = f.swirl.core_radius * f.swirl.core_radius;
        let w0 = f.swirl.circulation / (2.0 * PI * c);
        let a = f.strain;
        let mut rng = super::super::testutil::Rng::new(8);
        for _ in 0..100 {
            let p = rng.point([-1.0; 3], [1.0; 3]);
            assert!((f.vorticity(p) - f.swirl.vorticity(p)).abs() < 1e-12);
            let h = f.helicity(p);
            assert!((-1.0..=1.0).contains(&h) && h * p[2] >= 0.0, "{p:?}: {h}");
        }
        for z in [-0.5, 0.3] {
            let p = [0.0, 0.0, z];
            assert!((f.lambda2(p) - (0.25 * a * a - w0 * w0)).abs() < 1e-12);
            assert!((f.helicity(p) - z.signum()).abs() < 1e-12);
        }
        assert_eq!(f.helicity([0.0; 3]), 0.0);
        // Far from the core the strain wins: λ2 > 0.
        assert!(f.lambda2([0.9, 0.0, 0.0]) > 0.0);
    }

    #[test]
    fn burgers_q_is_shifted_by_three_quarters_alpha_squared() {
        let f = Burgers::sample_scene();
        let mut rng = super::super::testutil::Rng::new(5);
        for _ in 0..100 {
            let p = rng.point([-1.0; 3], [1.0; 3]);
            assert!((f.q(p) - f.q_exact(p)).abs() < 1e-12);
            assert!((f.q(p) - f.swirl.q(p) + 0.03).abs() < 1e-12);
        }
    }
}
