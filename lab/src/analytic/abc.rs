//! Arnold–Beltrami–Childress flow.

use super::{Flow, Gradient};
use std::f64::consts::PI;

/// ABC flow scaled by `amplitude` with wave number `k`:
/// `u = a · (A sin kz + C cos ky, B sin kx + A cos kz, C sin ky + B cos kx)`.
/// A Beltrami field: its vorticity is `k · u`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Abc {
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub k: f64,
    pub amplitude: f64,
}

impl Abc {
    /// The `abc` scene: classical A = 1, B = √(2/3), C = √(1/3), k = π (one period over the
    /// domain [-1, 1]³), amplitude 0.2.
    pub(crate) fn sample_scene() -> Self {
        Abc {
            a: 1.0,
            b: (2.0f64 / 3.0).sqrt(),
            c: (1.0f64 / 3.0).sqrt(),
            k: PI,
            amplitude: 0.2,
        }
    }
}

impl Flow for Abc {
    fn velocity(&self, p: [f64; 3]) -> [f64; 3] {
        let (sx, cx) = (self.k * p[0]).sin_cos();
        let (sy, cy) = (self.k * p[1]).sin_cos();
        let (sz, cz) = (self.k * p[2]).sin_cos();
        let m = self.amplitude;
        [
            m * (self.a * sz + self.c * cy),
            m * (self.b * sx + self.a * cz),
            m * (self.c * sy + self.b * cx),
        ]
    }

    fn gradient(&self, p: [f64; 3]) -> Gradient {
        let (sx, cx) = (self.k * p[0]).sin_cos();
        let (sy, cy) = (self.k * p[1]).sin_cos();
        let (sz, cz) = (self.k * p[2]).sin_cos();
        let m = self.amplitude * self.k;
        [
            [0.0, -m * self.c * sy, m * self.a * cz],
            [m * self.b * cx, 0.0, -m * self.a * sz],
            [-m * self.b * sx, m * self.c * cy, 0.0],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::super::testutil::{check_flow, Rng};
    use super::*;

    #[test]
    fn abc_gradient_matches_finite_differences() {
        check_flow(&Abc::sample_scene(), [-1.0; 3], [1.0; 3], 200, 11);
    }

    #[test]
    fn abc_vorticity_is_k_times_velocity() {
        let f = Abc::sample_scene();
        let mut rng = Rng::new(12);
        for _ in 0..50 {
            let p = rng.point([-1.0; 3], [1.0; 3]);
            let g = f.gradient(p);
            let w = [g[2][1] - g[1][2], g[0][2] - g[2][0], g[1][0] - g[0][1]];
            let u = f.velocity(p);
            for i in 0..3 {
                assert!((w[i] - f.k * u[i]).abs() < 1e-12);
            }
        }
    }

    /// The textbook ABC flow (A = B = C = 1, period 2π) is a Beltrami flow with ω = u, so
    /// its vorticity magnitude is its speed and its normalised helicity 1; mirrored (k < 0)
    /// ω = −u and the helicity is −1. The measures are the bake's, on the exact gradient.
    #[test]
    fn abc_vorticity_equals_velocity_and_helicity_is_plus_or_minus_one() {
        let unit = Abc {
            a: 1.0,
            b: 1.0,
            c: 1.0,
            k: 1.0,
            amplitude: 1.0,
        };
        let mirrored = Abc { k: -1.0, ..unit };
        let mut rng = Rng::new(13);
        for _ in 0..200 {
            let p = rng.point([-PI; 3], [PI; 3]);
            let u = unit.velocity(p);
            let w = preprocess::measures::vorticity(&unit.gradient(p));
            for i in 0..3 {
                assert!((w[i] - u[i]).abs() < 1e-14, "{p:?}: ω {w:?} u {u:?}");
            }
            let s = super::super::speed(&u);
            assert!((unit.vorticity(p) - s).abs() < 1e-14);
            assert!(
                (unit.helicity(p) - 1.0).abs() < 1e-14,
                "{}",
                unit.helicity(p)
            );
            assert!((mirrored.helicity(p) + 1.0).abs() < 1e-14);
            // The lab's scene: ω = k u with k = π.
            let f = Abc::sample_scene();
            let s = super::super::speed(&f.velocity(p));
            assert!((f.vorticity(p) - f.k * s).abs() < 1e-13);
            assert!((f.helicity(p) - 1.0).abs() < 1e-13);
        }
    }
}
