//! Read-only queries shared by both programs.
//! (Provisional brute-force versions; the real ones descend the KD-tree.)

use crate::schema::{ArchivedAabb, ArchivedBrickFile};

/// The part of a ray inside one region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionSegment {
    pub region: u32,
    pub t_enter: f64,
    pub t_exit: f64,
}

fn contains(b: &ArchivedAabb, p: [f64; 3]) -> bool {
    (0..3).all(|a| p[a] >= b.min[a].to_native() && p[a] < b.max[a].to_native())
}

/// Region containing `p` (boxes are half-open `[min, max)`), if any.
pub fn region_at(file: &ArchivedBrickFile, p: [f64; 3]) -> Option<u32> {
    file.regions
        .iter()
        .position(|r| contains(&r.bounds, p))
        .map(|i| i as u32)
}

/// Entry and exit distances of the ray `origin + t * dir` through a box, clipped to
/// `[t_min, t_max]`.
pub fn ray_box(
    b: &ArchivedAabb,
    origin: [f64; 3],
    dir: [f64; 3],
    t_min: f64,
    t_max: f64,
) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (t_min, t_max);
    for a in 0..3 {
        let inv = 1.0 / dir[a];
        let mut ta = (b.min[a].to_native() - origin[a]) * inv;
        let mut tb = (b.max[a].to_native() - origin[a]) * inv;
        if ta > tb {
            std::mem::swap(&mut ta, &mut tb);
        }
        if ta.is_nan() || tb.is_nan() {
            // Ray parallel to and on a slab plane: treat as inside when within the slab.
            if origin[a] < b.min[a].to_native() || origin[a] > b.max[a].to_native() {
                return None;
            }
            continue;
        }
        t0 = t0.max(ta);
        t1 = t1.min(tb);
    }
    (t0 < t1).then_some((t0, t1))
}

/// Regions crossed by the ray, front to back.
pub fn ray_regions(
    file: &ArchivedBrickFile,
    origin: [f64; 3],
    dir: [f64; 3],
    t_min: f64,
    t_max: f64,
) -> Vec<RegionSegment> {
    let mut out: Vec<RegionSegment> = file
        .regions
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            ray_box(&r.bounds, origin, dir, t_min, t_max).map(|(t_enter, t_exit)| RegionSegment {
                region: i as u32,
                t_enter,
                t_exit,
            })
        })
        .collect();
    out.sort_by(|a, b| a.t_enter.total_cmp(&b.t_enter));
    out
}
