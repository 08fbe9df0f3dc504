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
}
