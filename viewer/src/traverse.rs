//! Front-to-back region traversal along a ray by KD-tree descent, without allocation
//! (the caller owns a reusable stack).

use crate::volume::{KdN, Volume};

/// The part of a ray inside one region (local frame, `t` in world units along a unit ray).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub region: u32,
    pub t0: f64,
    pub t1: f64,
}

/// Entry/exit of the ray through the box `min..max`, clipped to `[t_min, t_max]`.
#[inline]
pub fn ray_box(
    min: &[f64; 3],
    max: &[f64; 3],
    o: &[f64; 3],
    inv: &[f64; 3],
    t_min: f64,
    t_max: f64,
) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (t_min, t_max);
    for a in 0..3 {
        if inv[a].is_infinite() {
            // Parallel to the slabs: inside or out for the whole ray.
            if o[a] < min[a] || o[a] >= max[a] {
                return None;
            }
            continue;
        }
        let ta = (min[a] - o[a]) * inv[a];
        let tb = (max[a] - o[a]) * inv[a];
        let (lo, hi) = if ta <= tb { (ta, tb) } else { (tb, ta) };
        t0 = t0.max(lo);
        t1 = t1.min(hi);
    }
    (t0 < t1).then_some((t0, t1))
}

/// `1/d` per axis, infinite for a zero component.
pub fn inverse(d: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|a| {
        if d[a] == 0.0 {
            f64::INFINITY
        } else {
            1.0 / d[a]
        }
    })
}

impl Volume<'_> {
    /// Calls `f` for every region the ray `o + t d` (local frame) crosses within
    /// `[t_min, t_max]`, front to back; `f` returns `false` to stop.
    pub fn segments<F: FnMut(Segment) -> bool>(
        &self,
        o: [f64; 3],
        d: [f64; 3],
        t_min: f64,
        t_max: f64,
        stack: &mut Vec<(u32, f64, f64)>,
        mut f: F,
    ) {
        if self.kd.is_empty() {
            return;
        }
        let inv = inverse(&d);
        let Some((t0, t1)) = ray_box(&self.bounds_min, &self.bounds_max, &o, &inv, t_min, t_max)
        else {
            return;
        };
        stack.clear();
        stack.push((0, t0, t1));
        while let Some((mut node, ta, mut tb)) = stack.pop() {
            // The tree was checked acyclic at open; depth bounds this walk.
            loop {
                match self.kd[node as usize] {
                    KdN::Inner {
                        axis,
                        split,
                        left,
                        right,
                    } => {
                        let below_first = o[axis] < split || (o[axis] == split && d[axis] < 0.0);
                        let (near, far) = if below_first {
                            (left, right)
                        } else {
                            (right, left)
                        };
                        if inv[axis].is_infinite() {
                            node = near;
                            continue;
                        }
                        let ts = (split - o[axis]) * inv[axis];
                        if ts > tb || ts <= 0.0 {
                            node = near;
                        } else if ts < ta {
                            node = far;
                        } else {
                            stack.push((far, ts, tb));
                            node = near;
                            tb = ts;
                        }
                    }
                    KdN::Leaf(region) => {
                        if let Some(r) = region {
                            let reg = &self.regions[r as usize];
                            if let Some((s0, s1)) = ray_box(&reg.min, &reg.max, &o, &inv, ta, tb) {
                                if !f(Segment {
                                    region: r,
                                    t0: s0,
                                    t1: s1,
                                }) {
                                    return;
                                }
                            }
                        }
                        break;
                    }
                }
            }
        }
    }
}
