//! Bounding volume hierarchy built with the binned surface area heuristic, and the
//! watertight ray/triangle test it is used with.
//!
//! The BVH is generic over primitives: it is built from one box per primitive and
//! traversal calls back into the caller for the primitive test, so it never needs to
//! know what a triangle is. Everything is `f64`, so scenes placed at 1e6 from the origin
//! keep their precision.

use format::Aabb;
use glam::DVec3;

use crate::camera::Ray;

/// The box around `points`.
pub(crate) fn box_of(points: &[DVec3]) -> Aabb {
    points.iter().fold(Aabb::EMPTY, |b, p| b.grow(p.to_array()))
}

/// Parametric interval where the ray is inside the box `b`, clipped to `[t_min, t_max]`.
///
/// `inv_dir` is `1 / ray.dir` per component (±∞ for zero components; such a ray is
/// inside that slab if its origin is, boundary included). The far distance is
/// widened by `1 + 2γ₃` (Ize 2013) so rounding cannot make a ray slip between boxes.
fn clip(b: &Aabb, origin: DVec3, inv_dir: DVec3, t_min: f64, t_max: f64) -> Option<(f64, f64)> {
    const GAMMA3: f64 = 3.0 * f64::EPSILON / (1.0 - 3.0 * f64::EPSILON);
    let mut near = t_min;
    let mut far = t_max;
    for a in 0..3 {
        if inv_dir[a].is_infinite() {
            // Ray parallel to this slab: inside it everywhere or nowhere.
            if origin[a] < b.min[a] || origin[a] > b.max[a] {
                return None;
            }
            continue;
        }
        let t0 = (b.min[a] - origin[a]) * inv_dir[a];
        let t1 = (b.max[a] - origin[a]) * inv_dir[a];
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1) * (1.0 + 2.0 * GAMMA3));
    }
    (near <= far).then_some((near, far))
}

/// Cost of one traversal step relative to one primitive test.
const TRAVERSAL_COST: f64 = 1.0;
const BINS: usize = 16;
/// Leaves never hold more primitives than this unless they cannot be split (equal
/// centroids) or the tree is at its depth limit.
const MAX_LEAF: usize = 8;
/// Depth limit; traversal's fixed stack is sized from it.
const MAX_DEPTH: usize = 60;

#[derive(Debug, Clone, Copy)]
struct Node {
    bounds: Aabb,
    /// Leaf: index of the first primitive in `prims`. Inner: index of the second child
    /// (the first child directly follows its parent).
    offset: u32,
    /// Number of primitives; 0 for inner nodes.
    count: u32,
}

/// A BVH over primitives given by their bounding boxes.
#[derive(Debug, Clone)]
pub(crate) struct Bvh {
    nodes: Vec<Node>,
    prims: Vec<u32>,
}

struct BuildPrim {
    bounds: Aabb,
    centroid: DVec3,
    index: u32,
}

impl Bvh {
    /// Builds the tree with binned SAH (16 bins per axis). Deterministic. Primitives
    /// with empty or non-finite boxes are left out (they can never be hit).
    pub fn build(bounds: &[Aabb]) -> Bvh {
        let mut prims: Vec<BuildPrim> = bounds
            .iter()
            .enumerate()
            .filter(|(_, b)| !b.is_empty() && b.min.iter().chain(&b.max).all(|v| v.is_finite()))
            .filter_map(|(i, b)| {
                u32::try_from(i).ok().map(|index| BuildPrim {
                    bounds: *b,
                    centroid: DVec3::from_array(b.centre()),
                    index,
                })
            })
            .collect();
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(2 * prims.len()),
            prims: Vec::with_capacity(prims.len()),
        };
        if !prims.is_empty() {
            bvh.build_node(&mut prims, 0);
        }
        bvh
    }

    /// Number of primitives in the tree.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.prims.len()
    }

    /// Bounds of everything in the tree (empty box for an empty tree).
    #[cfg(test)]
    pub(crate) fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| n.bounds)
    }

    fn push_leaf(&mut self, bounds: Aabb, prims: &[BuildPrim]) -> usize {
        let node = Node {
            bounds,
            offset: self.prims.len() as u32,
            count: prims.len() as u32,
        };
        self.prims.extend(prims.iter().map(|p| p.index));
        self.nodes.push(node);
        self.nodes.len() - 1
    }

    fn build_node(&mut self, prims: &mut [BuildPrim], depth: usize) -> usize {
        let bounds = prims.iter().fold(Aabb::EMPTY, |b, p| b.union(p.bounds));
        let cbounds = prims
            .iter()
            .fold(Aabb::EMPTY, |b, p| b.grow(p.centroid.to_array()));
        let extent = DVec3::from_array(cbounds.max) - DVec3::from_array(cbounds.min);
        if prims.len() <= 2 || depth >= MAX_DEPTH || extent.max_element() <= 0.0 {
            return self.push_leaf(bounds, prims);
        }

        // Binned SAH: for each axis, count primitives per bin and sweep the split planes.
        let mut best: Option<(f64, usize, usize)> = None; // (cost, axis, split bin)
        for axis in 0..3 {
            if extent[axis] <= 0.0 {
                continue;
            }
            let scale = BINS as f64 / extent[axis];
            let mut counts = [0usize; BINS];
            let mut boxes = [Aabb::EMPTY; BINS];
            for p in prims.iter() {
                let b = bin_of(p.centroid[axis], cbounds.min[axis], scale);
                counts[b] += 1;
                boxes[b] = boxes[b].union(p.bounds);
            }
            // Right-to-left sweep: area and count of everything right of plane i.
            let mut right_area = [0.0; BINS];
            let mut right_count = [0usize; BINS];
            let (mut acc_b, mut acc_n) = (Aabb::EMPTY, 0);
            for i in (1..BINS).rev() {
                acc_b = acc_b.union(boxes[i]);
                acc_n += counts[i];
                right_area[i] = acc_b.half_area();
                right_count[i] = acc_n;
            }
            let (mut acc_b, mut acc_n) = (Aabb::EMPTY, 0);
            for i in 1..BINS {
                acc_b = acc_b.union(boxes[i - 1]);
                acc_n += counts[i - 1];
                if acc_n == 0 || right_count[i] == 0 {
                    continue;
                }
                let cost = acc_b.half_area() * acc_n as f64 + right_area[i] * right_count[i] as f64;
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, i));
                }
            }
        }

        let area = bounds.half_area();
        let leaf_cost = prims.len() as f64;
        let Some((cost, axis, split)) = best else {
            return self.push_leaf(bounds, prims);
        };
        let split_cost = if area > 0.0 {
            TRAVERSAL_COST + cost / area
        } else {
            TRAVERSAL_COST + leaf_cost / 2.0
        };
        if split_cost >= leaf_cost && prims.len() <= MAX_LEAF {
            return self.push_leaf(bounds, prims);
        }

        // Partition by bin; both sides are non-empty by construction of `best`.
        let scale = BINS as f64 / extent[axis];
        let lo = cbounds.min[axis];
        let mut mid = 0;
        for i in 0..prims.len() {
            if bin_of(prims[i].centroid[axis], lo, scale) < split {
                prims.swap(i, mid);
                mid += 1;
            }
        }
        if mid == 0 || mid == prims.len() {
            return self.push_leaf(bounds, prims);
        }

        let me = self.nodes.len();
        self.nodes.push(Node {
            bounds,
            offset: 0,
            count: 0,
        });
        let (left, right) = prims.split_at_mut(mid);
        self.build_node(left, depth + 1);
        let second = self.build_node(right, depth + 1);
        self.nodes[me].offset = second as u32;
        me
    }

    /// Where the searches of a group of rays can start: the deepest node above every
    /// primitive whose box `may_meet` lets through, found by descending while only one
    /// child's box may meet the group (the root when both may); `None` when no box may.
    /// `may_meet` must never refuse a box one of the rays meets (a frustum around them):
    /// then every node the search from the root would open lies under the start, and
    /// [`Bvh::nearest_from`] the start finds what [`Bvh::nearest`] finds.
    pub(crate) fn start_in(&self, may_meet: impl Fn(&Aabb) -> bool) -> Option<u32> {
        let mut idx = 0u32;
        if !may_meet(&self.nodes.first()?.bounds) {
            return None;
        }
        // A descent is no longer than the tree is deep; the count only guards a
        // malformed tree.
        for _ in 0..=MAX_DEPTH {
            let node = self.nodes.get(idx as usize)?;
            if node.count > 0 {
                return Some(idx);
            }
            let meets = |n: u32| {
                self.nodes
                    .get(n as usize)
                    .is_some_and(|c| may_meet(&c.bounds))
            };
            idx = match (meets(idx + 1), meets(node.offset)) {
                (true, true) => return Some(idx),
                (true, false) => idx + 1,
                (false, true) => node.offset,
                (false, false) => return None,
            };
        }
        Some(0)
    }

    /// Nearest primitive hit: `hit(prim, t_min, t_max)` returns the primitive's hit
    /// distance in `(t_min, t_max)`, if any. Returns the primitive and distance.
    #[cfg(test)]
    pub(crate) fn nearest(
        &self,
        ray: &Ray,
        t_min: f64,
        t_max: f64,
        hit: impl FnMut(u32, f64, f64) -> Option<f64>,
    ) -> Option<(u32, f64)> {
        self.nearest_from(0, ray, t_min, t_max, hit)
    }

    /// The nearest primitive hit among the primitives under node `start` (the root: 0;
    /// see [`Bvh::start_in`]): `hit(prim, t_min, t_max)` returns the primitive's hit
    /// distance in `(t_min, t_max)`, if any. Returns the primitive and distance.
    pub(crate) fn nearest_from(
        &self,
        start: u32,
        ray: &Ray,
        t_min: f64,
        t_max: f64,
        mut hit: impl FnMut(u32, f64, f64) -> Option<f64>,
    ) -> Option<(u32, f64)> {
        let inv = ray.dir.recip();
        let mut best: Option<(u32, f64)> = None;
        let mut far = t_max;
        // (node, entry distance): a node is only opened if it starts before the best hit.
        let mut stack = [(0u32, 0.0f64); MAX_DEPTH + 2];
        let root = self.nodes.get(start as usize)?;
        let (entry, _) = clip(&root.bounds, ray.origin, inv, t_min, far)?;
        stack[0] = (start, entry);
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let (idx, entry) = stack[sp];
            if entry > far {
                continue;
            }
            let Some(node) = self.nodes.get(idx as usize) else {
                continue;
            };
            if node.count > 0 {
                let first = node.offset as usize;
                for &p in self
                    .prims
                    .get(first..first + node.count as usize)
                    .unwrap_or(&[])
                {
                    if let Some(t) = hit(p, t_min, far) {
                        if t > t_min && t < far {
                            far = t;
                            best = Some((p, t));
                        }
                    }
                }
                continue;
            }
            // Push the farther child first so the nearer one is opened next.
            let (a, b) = (idx + 1, node.offset);
            let ta = self
                .nodes
                .get(a as usize)
                .and_then(|n| clip(&n.bounds, ray.origin, inv, t_min, far));
            let tb = self
                .nodes
                .get(b as usize)
                .and_then(|n| clip(&n.bounds, ray.origin, inv, t_min, far));
            let mut push = |n: u32, t: f64| {
                if sp < stack.len() {
                    stack[sp] = (n, t);
                    sp += 1;
                }
            };
            match (ta, tb) {
                (Some((na, _)), Some((nb, _))) => {
                    if nb < na {
                        push(a, na);
                        push(b, nb);
                    } else {
                        push(b, nb);
                        push(a, na);
                    }
                }
                (Some((na, _)), None) => push(a, na),
                (None, Some((nb, _))) => push(b, nb),
                (None, None) => {}
            }
        }
        best
    }

    /// Whether any primitive is hit in `(t_min, t_max)`; `hit` as for [`Bvh::nearest`].
    pub(crate) fn any(
        &self,
        ray: &Ray,
        t_min: f64,
        t_max: f64,
        mut hit: impl FnMut(u32, f64, f64) -> Option<f64>,
    ) -> bool {
        let inv = ray.dir.recip();
        let mut stack = [0u32; MAX_DEPTH + 2];
        let mut sp = 0usize;
        if self.nodes.is_empty() {
            return false;
        }
        stack[0] = 0;
        sp += 1;
        while sp > 0 {
            sp -= 1;
            let idx = stack[sp] as usize;
            let Some(node) = self.nodes.get(idx) else {
                continue;
            };
            if clip(&node.bounds, ray.origin, inv, t_min, t_max).is_none() {
                continue;
            }
            if node.count > 0 {
                let first = node.offset as usize;
                for &p in self
                    .prims
                    .get(first..first + node.count as usize)
                    .unwrap_or(&[])
                {
                    if hit(p, t_min, t_max).is_some_and(|t| t > t_min && t < t_max) {
                        return true;
                    }
                }
                continue;
            }
            for n in [idx + 1, node.offset as usize] {
                if sp < stack.len() {
                    stack[sp] = n as u32;
                    sp += 1;
                }
            }
        }
        false
    }
}

fn bin_of(c: f64, lo: f64, scale: f64) -> usize {
    let b = ((c - lo) * scale) as isize;
    b.clamp(0, BINS as isize - 1) as usize
}

/// Per-ray constants of the watertight ray/triangle test (Woop, Benthin, Wald,
/// "Watertight Ray/Triangle Intersection", JCGT 2013): the ray is sheared so it runs
/// along +z, and the triangle is tested in 2D with edge functions. Points exactly on a
/// shared edge or vertex give edge functions of exactly opposite sign in the two
/// triangles, so a ray can never slip through a closed mesh.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RayShear {
    origin: DVec3,
    k: [usize; 3],
    s: DVec3,
}

impl RayShear {
    pub(crate) fn new(ray: &Ray) -> RayShear {
        let a = ray.dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding: swap kx, ky when the dominant component is negative.
        if ray.dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let dz = ray.dir[kz];
        RayShear {
            origin: ray.origin,
            k: [kx, ky, kz],
            s: DVec3::new(ray.dir[kx] / dz, ray.dir[ky] / dz, 1.0 / dz),
        }
    }
}

/// Hit of [`intersect_triangle`]: distance and barycentric weights of `v0`, `v1`, `v2`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TriHit {
    pub t: f64,
    pub(crate) bary: [f64; 3],
}

/// Watertight ray/triangle test (both faces), hits with `t` in `(t_min, t_max)`.
pub(crate) fn intersect_triangle(
    sh: &RayShear,
    v0: DVec3,
    v1: DVec3,
    v2: DVec3,
    t_min: f64,
    t_max: f64,
) -> Option<TriHit> {
    let [kx, ky, kz] = sh.k;
    let a = v0 - sh.origin;
    let b = v1 - sh.origin;
    let c = v2 - sh.origin;
    // Shear and scale the vertices.
    let ax = a[kx] - sh.s.x * a[kz];
    let ay = a[ky] - sh.s.y * a[kz];
    let bx = b[kx] - sh.s.x * b[kz];
    let by = b[ky] - sh.s.y * b[kz];
    let cx = c[kx] - sh.s.x * c[kz];
    let cy = c[ky] - sh.s.y * c[kz];
    // Edge functions (scaled barycentrics).
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let az = sh.s.z * a[kz];
    let bz = sh.s.z * b[kz];
    let cz = sh.s.z * c[kz];
    let t = (u * az + v * bz + w * cz) / det;
    if !(t > t_min && t < t_max) {
        return None;
    }
    Some(TriHit {
        t,
        bary: [u / det, v / det, w / det],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn tri_box(t: &[DVec3; 3]) -> Aabb {
        box_of(t)
    }

    fn brute(tris: &[[DVec3; 3]], ray: &Ray, t_min: f64, t_max: f64) -> Option<(u32, f64)> {
        let sh = RayShear::new(ray);
        let mut best: Option<(u32, f64)> = None;
        for (i, t) in tris.iter().enumerate() {
            let far = best.map_or(t_max, |b| b.1);
            if let Some(h) = intersect_triangle(&sh, t[0], t[1], t[2], t_min, far) {
                best = Some((i as u32, h.t));
            }
        }
        best
    }

    #[test]
    fn triangle_hit_distance_and_barycentrics() {
        let ray = Ray {
            origin: DVec3::new(0.25, 0.25, 5.0),
            dir: DVec3::NEG_Z,
        };
        let sh = RayShear::new(&ray);
        let (v0, v1, v2) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        let h = intersect_triangle(&sh, v0, v1, v2, 0.0, f64::INFINITY).expect("hit");
        assert!((h.t - 5.0).abs() < 1e-12);
        let p = h.bary[0] * v0 + h.bary[1] * v1 + h.bary[2] * v2;
        assert!((p - DVec3::new(0.25, 0.25, 0.0)).length() < 1e-12);
        // Back face is hit too; t range is respected.
        assert!(intersect_triangle(&sh, v0, v2, v1, 0.0, f64::INFINITY).is_some());
        assert!(intersect_triangle(&sh, v0, v1, v2, 0.0, 5.0).is_none());
        assert!(intersect_triangle(&sh, v0, v1, v2, 5.0, 9.0).is_none());
        // Outside the triangle.
        let miss = RayShear::new(&Ray {
            origin: DVec3::new(0.75, 0.75, 5.0),
            dir: DVec3::NEG_Z,
        });
        assert!(intersect_triangle(&miss, v0, v1, v2, 0.0, f64::INFINITY).is_none());
    }

    #[test]
    fn empty_and_degenerate_trees() {
        let bvh = Bvh::build(&[]);
        let ray = Ray {
            origin: DVec3::ZERO,
            dir: DVec3::X,
        };
        assert!(bvh.nearest(&ray, 0.0, 1.0, |_, _, _| Some(0.5)).is_none());
        assert!(!bvh.any(&ray, 0.0, 1.0, |_, _, _| Some(0.5)));
        // Many primitives with the same centroid: must still build (one leaf).
        let b = Aabb {
            min: [-1.0; 3],
            max: [1.0; 3],
        };
        let bvh = Bvh::build(&vec![b; 100]);
        assert_eq!(bvh.len(), 100);
        let mut seen = 0;
        bvh.any(&ray, 0.0, 10.0, |_, _, _| {
            seen += 1;
            None
        });
        assert_eq!(seen, 100);
        // NaN boxes are dropped.
        let nan = Aabb {
            min: [f64::NAN; 3],
            max: [f64::NAN; 3],
        };
        assert_eq!(Bvh::build(&[nan, b]).len(), 1);
    }

    fn v3(range: f64) -> impl Strategy<Value = DVec3> {
        (-range..range, -range..range, -range..range).prop_map(|(x, y, z)| DVec3::new(x, y, z))
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        #[test]
        fn bvh_matches_brute_force(
            centres in prop::collection::vec(v3(10.0), 1..300),
            offsets in prop::collection::vec((v3(1.5), v3(1.5)), 300),
            rays in prop::collection::vec((v3(14.0), v3(1.0)), 40),
            shift in prop_oneof![Just(0.0), Just(1e6)],
        ) {
            let tris: Vec<[DVec3; 3]> = centres.iter().zip(&offsets).map(|(c, (a, b))| {
                let c = *c + DVec3::splat(shift);
                [c, c + *a, c + *b]
            }).collect();
            let boxes: Vec<Aabb> = tris.iter().map(tri_box).collect();
            let bvh = Bvh::build(&boxes);
            prop_assert_eq!(bvh.len(), tris.len());
            for (o, d) in &rays {
                let Some(dir) = d.try_normalize() else { continue };
                let ray = Ray { origin: *o + DVec3::splat(shift), dir };
                let want = brute(&tris, &ray, 1e-9, f64::INFINITY);
                let got = bvh.nearest(&ray, 1e-9, f64::INFINITY, |p, lo, hi| {
                    let t = &tris[p as usize];
                    intersect_triangle(&RayShear::new(&ray), t[0], t[1], t[2], lo, hi).map(|h| h.t)
                });
                prop_assert_eq!(want.map(|w| w.1), got.map(|g| g.1));
                let any = bvh.any(&ray, 1e-9, f64::INFINITY, |p, lo, hi| {
                    let t = &tris[p as usize];
                    intersect_triangle(&RayShear::new(&ray), t[0], t[1], t[2], lo, hi).map(|h| h.t)
                });
                prop_assert_eq!(any, want.is_some());
            }
        }
    }
}
