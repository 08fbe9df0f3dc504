//! A rising vortex ring carrying a smoke plume: the frames of a small "simulation cache".

use super::{Flow, Gradient, Ring, Wake};
use std::f64::consts::PI;

/// Seconds between frames of the `ring-plume` scene.
pub(crate) const FRAME_SECONDS: f64 = 4.0;

/// One frame of a vortex ring rising along +z through still fluid, with a smoke density
/// that the ring has rolled up into its core plus the trail it leaves below.
///
/// The velocity is the ring's own (Rosenhead–Moore particles, the same sum as
/// [`Wake`] with no free stream and no sphere), so gradient and Q are exact. Frame `f` shows
/// the ring at time `t = (f − 1)·`[`FRAME_SECONDS`]: its centre has risen by the
/// self-induced speed `V = Γ / (4πR) (ln(8R/σ) − ¼)` times t, its radius grows slowly and
/// its axis wobbles a little, as a real ring's would. Between frames this is a kinematic
/// model (not a Navier–Stokes solution); within a frame the field is divergence-free.
#[derive(Debug, Clone)]
pub struct RingPlume {
    pub ring: Ring,
    /// Height of the smoke source (bottom of the trail).
    pub(crate) source_z: f64,
    flow: Wake,
}

impl RingPlume {
    /// Frame `frame` (1-based) of the `ring-plume` scene on [-1, 1]³.
    pub fn frame(frame: u64) -> Self {
        let t = (frame.max(1) - 1) as f64 * FRAME_SECONDS;
        let (radius0, core) = (0.38, 0.12);
        let omega0 = 0.8;
        let circulation = 2.0 * PI * core * core * omega0;
        let speed = circulation / (4.0 * PI * radius0) * ((8.0 * radius0 / core).ln() - 0.25);
        let tilt = 0.12 * (0.35 * t).sin();
        let ring = Ring {
            centre: [0.05 * (0.2 * t).sin(), 0.0, -0.55 + speed * t],
            normal: [0.0, -tilt.sin(), tilt.cos()],
            radius: radius0 * (1.0 + 0.01 * t),
            circulation,
            core,
        };
        RingPlume {
            ring,
            source_z: -1.0,
            // No free stream, a sphere of radius 0 far outside the domain: only the ring.
            flow: Wake::new(0.0, [0.0, 0.0, -1.0e3], 0.0, 0.0, vec![ring]),
        }
    }

    /// Smoke density at `p`: a Gaussian tube around the ring's core circle (width 1.5 σ)
    /// plus a trail of half that density along the axis from the source up to the ring
    /// (width 0.4 R, fading in over the lowest 0.2). Values in [0, ≈ 1.5].
    pub(crate) fn density(&self, p: [f64; 3]) -> f64 {
        let r = &self.ring;
        let d = [p[0] - r.centre[0], p[1] - r.centre[1], p[2] - r.centre[2]];
        let n = r.normal;
        let axial = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
        let radial = ((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) - axial * axial)
            .max(0.0)
            .sqrt();
        let s = 1.5 * r.core;
        let core2 = (radial - r.radius).powi(2) + axial * axial;
        let tube = (-core2 / (2.0 * s * s)).exp();
        let w = 0.4 * r.radius;
        let below = (-axial).clamp(0.0, f64::INFINITY);
        let above_source = ((p[2] - self.source_z) / 0.2).clamp(0.0, 1.0);
        let trail = if axial < 0.0 {
            0.5 * (-radial * radial / (2.0 * w * w)).exp()
                * above_source
                * (1.0 - (-below / r.core).exp())
        } else {
            0.0
        };
        tube + trail
    }
}

impl Flow for RingPlume {
    fn velocity(&self, p: [f64; 3]) -> [f64; 3] {
        self.flow.velocity(p)
    }
    fn gradient(&self, p: [f64; 3]) -> Gradient {
        self.flow.gradient(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ring_rises_and_carries_the_smoke() {
        let a = RingPlume::frame(1);
        let b = RingPlume::frame(4);
        assert!(b.ring.centre[2] > a.ring.centre[2] + 0.3);
        assert!(b.ring.centre[2] < 0.6, "stays inside the domain");
        // Core: Q near ω₀², densest smoke; axis below the ring: trail.
        let core = [a.ring.centre[0] + a.ring.radius, 0.0, a.ring.centre[2]];
        assert!(a.q(core) > 0.3, "{}", a.q(core));
        assert!(a.density(core) > 0.9);
        let trail = [a.ring.centre[0], 0.0, a.ring.centre[2] - 0.3];
        assert!(a.density(trail) > 0.2 && a.density(trail) < 0.6);
        // The fluid moves up through the ring's centre.
        assert!(a.velocity(a.ring.centre)[2] > 0.0);
    }
}
