//! Front-to-back region traversal along a ray by KD-tree descent, without allocation
//! (the caller owns a reusable stack).

use crate::volume::Volume;

/// The part of a ray inside one region (local frame, `t` in world units along a unit ray).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// The region, or [`SKIPPED`] for a whole KD subtree skipped by its value range.
    pub region: u32,
    pub t0: f64,
    pub t1: f64,
    /// Value range of the traversal's field over the region / subtree.
    pub min: f32,
    pub max: f32,
}

/// [`Segment::region`] of a skipped subtree.
pub const SKIPPED: u32 = u32::MAX;

/// Which subtrees [`Volume::segments_skipping`] may skip whole.
#[derive(Debug, Clone, Copy)]
pub struct Skip<K: Fn(f32, f32) -> bool> {
    /// Field whose ranges are tested.
    pub field: usize,
    /// Keep (descend into) a subtree whose range is `[min, max]`.
    pub keep: K,
    /// Skip subtrees that contain empty space too (callers that need to notice gaps in
    /// the data pass `false`).
    pub across_gaps: bool,
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
        f: F,
    ) {
        let skip = Skip {
            field: 0,
            keep: |_, _| true,
            across_gaps: false,
        };
        self.segments_skipping(o, d, t_min, t_max, stack, &skip, f)
    }

    /// As [`Volume::segments`], but a KD subtree whose value range `skip.keep` rejects is
    /// reported as one [`SKIPPED`] segment over the ray's part of the subtree's cell.
    #[allow(clippy::too_many_arguments)]
    pub fn segments_skipping<K: Fn(f32, f32) -> bool, F: FnMut(Segment) -> bool>(
        &self,
        o: [f64; 3],
        d: [f64; 3],
        t_min: f64,
        t_max: f64,
        stack: &mut Vec<(u32, f64, f64)>,
        skip: &Skip<K>,
        mut f: F,
    ) {
        let Some(nodes) = self.packed.get(skip.field).or_else(|| self.packed.first()) else {
            return;
        };
        if nodes.is_empty() {
            return;
        }
        let inv = inverse(&d);
        let Some((t0, t1)) = ray_box(&self.bounds_min, &self.bounds_max, &o, &inv, t_min, t_max)
        else {
            return;
        };
        let has_fields = !self.fields.is_empty();
        stack.clear();
        stack.push((0, t0, t1));
        while let Some((mut node, ta, mut tb)) = stack.pop() {
            // The tree was checked acyclic at open; depth bounds this walk.
            loop {
                let n = &nodes[node as usize];
                let axis = n.axis as usize;
                if axis < 3 {
                    if has_fields && (skip.across_gaps || n.full) && !(skip.keep)(n.min, n.max) {
                        if ta < tb
                            && !f(Segment {
                                region: SKIPPED,
                                t0: ta,
                                t1: tb,
                                min: n.min,
                                max: n.max,
                            })
                        {
                            return;
                        }
                        break;
                    }
                    let split = n.split;
                    let below_first = o[axis] < split || (o[axis] == split && d[axis] < 0.0);
                    let (near, far) = if below_first { (n.a, n.b) } else { (n.b, n.a) };
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
                } else {
                    if n.a != SKIPPED {
                        let reg = &self.regions[n.a as usize];
                        if let Some((s0, s1)) = ray_box(&reg.min, &reg.max, &o, &inv, ta, tb) {
                            if !f(Segment {
                                region: n.a,
                                t0: s0,
                                t1: s1,
                                min: n.min,
                                max: n.max,
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
