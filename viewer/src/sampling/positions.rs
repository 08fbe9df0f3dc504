//! Where the samples of one region segment go: `uniform` steps by a fixed `dt` and carries
//! its sequence from region to region; `paper` and `bisect` cut the segment into intervals
//! (first delimiter jittered) and sample their midpoints, each with its own length `Δ`.

use super::{Strategy, MAX_POSITIONS_PER_SEGMENT};

/// Sample positions of one region segment: `(t, Δ)`. Ends early (and says so in
/// `truncated`) when a step no longer moves `t` or after [`MAX_POSITIONS_PER_SEGMENT`]
/// positions, so no step size can make a ray march for ever.
pub(super) struct Positions {
    strategy: Strategy,
    a: f64,
    b: f64,
    end: f64,
    dt: f64,
    count: u32,
    pub(super) truncated: bool,
}

impl Positions {
    /// `t_next` carries the uniform sequence from region to region.
    pub(super) fn new(
        strategy: Strategy,
        t0: f64,
        t1: f64,
        dt: f64,
        jitter: f64,
        t_next: f64,
    ) -> Self {
        match strategy {
            Strategy::Uniform => {
                let a = if t_next < t0 {
                    t0 + jitter * dt
                } else {
                    t_next
                };
                Positions {
                    strategy,
                    a,
                    b: a,
                    end: t1,
                    dt,
                    count: 0,
                    truncated: false,
                }
            }
            _ => Positions {
                strategy,
                a: t0,
                b: t0 + jitter * dt,
                end: t1,
                dt,
                count: 0,
                truncated: false,
            },
        }
    }

    /// Where the uniform sequence continues after this segment.
    pub(super) fn next_t(&self) -> f64 {
        self.a
    }
}

impl Iterator for Positions {
    type Item = (f64, f64);

    fn next(&mut self) -> Option<(f64, f64)> {
        if self.count >= MAX_POSITIONS_PER_SEGMENT {
            self.truncated |= self.a < self.end;
            return None;
        }
        self.count += 1;
        if self.strategy == Strategy::Uniform {
            if self.a >= self.end {
                return None;
            }
            let t = self.a;
            self.a += self.dt;
            if self.a <= t {
                // The step is below the resolution of t here: stop rather than loop.
                self.truncated = true;
                self.a = self.end;
            }
            return Some((t, self.dt));
        }
        // Interval delimiters t0, t0 + jitter·dt, t0 + (1 + jitter)·dt, …, t1; midpoints.
        loop {
            if self.a >= self.end {
                return None;
            }
            let b = self.b.min(self.end);
            let a = self.a;
            self.a = b;
            let next_b = self.b + self.dt;
            if next_b.partial_cmp(&self.b) != Some(std::cmp::Ordering::Greater) && b < self.end {
                // `b + dt == b`: no further delimiter can be placed; end the segment here.
                self.truncated = true;
                self.b = self.end;
            } else {
                self.b = next_b;
            }
            if b > a {
                return Some((0.5 * (a + b), b - a));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_intervals_tile_the_segment() {
        for jitter in [0.0, 0.3, 0.999] {
            let (t0, t1, dt) = (1.25, 4.0, 0.4);
            let pos: Vec<(f64, f64)> =
                Positions::new(Strategy::Paper, t0, t1, dt, jitter, 0.0).collect();
            let total: f64 = pos.iter().map(|p| p.1).sum();
            assert!((total - (t1 - t0)).abs() < 1e-12);
            let mut a = t0;
            for &(t, delta) in &pos {
                assert!(
                    (t - (a + 0.5 * delta)).abs() < 1e-12 && delta > 0.0 && delta <= dt + 1e-12
                );
                a += delta;
            }
            // Uniform: fixed step, continuing a sequence that reached this segment.
            let u: Vec<f64> = Positions::new(Strategy::Uniform, t0, t1, dt, jitter, 2.0)
                .map(|p| p.0)
                .collect();
            assert_eq!(u.first().copied(), Some(2.0));
            assert!(u.windows(2).all(|w| (w[1] - w[0] - dt).abs() < 1e-12));
        }
    }

    /// A step below the resolution of `t` (`t + dt == t` far from the origin) or a segment
    /// of more than `MAX_POSITIONS_PER_SEGMENT` steps ends the sequence, marked truncated,
    /// instead of marching for ever.
    #[test]
    fn positions_end_when_the_step_cannot_advance() {
        for strategy in [Strategy::Uniform, Strategy::Paper, Strategy::Bisect] {
            let mut p = Positions::new(strategy, 1e12, 1e12 + 1.0, 1e-6, 0.5, 0.0);
            let n = p.by_ref().count();
            assert!(n <= 3, "{strategy:?}: {n} positions");
            assert!(p.truncated, "{strategy:?}");

            let mut p = Positions::new(strategy, 0.0, 1.0, 1e-9, 0.5, 0.0);
            let n = p.by_ref().count();
            assert_eq!(n as u32, MAX_POSITIONS_PER_SEGMENT, "{strategy:?}");
            assert!(p.truncated, "{strategy:?}");

            let mut p = Positions::new(strategy, 0.0, 1.0, 0.25, 0.5, 0.0);
            assert!(p.by_ref().count() <= 5);
            assert!(
                !p.truncated,
                "{strategy:?}: an ordinary segment is not truncated"
            );
        }
    }
}
