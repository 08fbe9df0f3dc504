//! All meshes of a scene in one SAH BVH: the nearest hit of a ray, and whether anything
//! blocks a shadow ray.

use format::Aabb;
use glam::{DVec3, Vec3};

use super::error::MeshError;
use super::placement::MeshInstance;
use super::triangles::TriangleMesh;
use crate::bvh::{box_of, intersect_triangle, Bvh, RayShear};
use crate::camera::Ray;

/// First intersection with a mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshHit {
    pub t: f64,
    /// Unit geometric (or interpolated) normal, not yet flipped towards the ray.
    pub normal: DVec3,
    pub colour: Vec3,
}

#[derive(Debug, Clone, Copy)]
struct Tri {
    v: [DVec3; 3],
    /// Per-vertex unit normals, or the geometric normal three times.
    n: [DVec3; 3],
    mesh: u32,
}

/// All meshes of a scene in one SAH BVH.
pub struct Meshes {
    tris: Vec<Tri>,
    colours: Vec<Vec3>,
    bvh: Bvh,
}

impl std::fmt::Debug for Meshes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Meshes")
            .field("meshes", &self.colours.len())
            .field("triangles", &self.tris.len())
            .finish()
    }
}

impl Meshes {
    /// Loads and places every instance (errors name the file).
    pub fn load(instances: &[MeshInstance]) -> Result<Meshes, MeshError> {
        let meshes = instances
            .iter()
            .map(TriangleMesh::load_obj)
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Meshes::from_meshes(&meshes))
    }

    /// Builds the BVH over meshes already in world coordinates.
    pub fn from_meshes(meshes: &[TriangleMesh]) -> Meshes {
        let mut tris = Vec::new();
        let mut colours = Vec::new();
        for (mi, m) in meshes.iter().enumerate() {
            colours.push(m.colour);
            for t in &m.triangles {
                let Some(v) = t
                    .iter()
                    .map(|&i| m.positions.get(i as usize).copied())
                    .collect::<Option<Vec<_>>>()
                else {
                    continue;
                };
                let v = [v[0], v[1], v[2]];
                let geo = (v[1] - v[0]).cross(v[2] - v[0]).try_normalize();
                let Some(geo) = geo else {
                    continue; // zero area: can never be hit
                };
                let n = m
                    .normals
                    .as_ref()
                    .and_then(|ns| {
                        let n = [
                            *ns.get(t[0] as usize)?,
                            *ns.get(t[1] as usize)?,
                            *ns.get(t[2] as usize)?,
                        ];
                        n.iter().all(|x| x.length() > 0.5).then_some(n)
                    })
                    .unwrap_or([geo; 3]);
                tris.push(Tri {
                    v,
                    n,
                    mesh: mi as u32,
                });
            }
        }
        let boxes: Vec<Aabb> = tris.iter().map(|t| box_of(&t.v)).collect();
        let bvh = Bvh::build(&boxes);
        Meshes { tris, colours, bvh }
    }

    pub fn empty() -> Meshes {
        Meshes {
            tris: Vec::new(),
            colours: Vec::new(),
            bvh: Bvh::build(&[]),
        }
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Bounds of all triangles (world frame, the vertices' own extremes), `None` without
    /// triangles.
    #[cfg(test)]
    pub(crate) fn bounds(&self) -> Option<Aabb> {
        let b = self.bvh.bounds();
        (!b.is_empty()).then_some(b)
    }

    /// Where the searches of the rays inside `frustum` (world frame) can start in the
    /// meshes' tree ([`Bvh::start_in`]); `None` when no triangle's box lies in it.
    pub(crate) fn start_in(&self, frustum: &crate::camera::Frustum) -> Option<u32> {
        self.bvh.start_in(|b| frustum.may_meet(&b.min, &b.max))
    }

    /// Nearest hit with `t` in `(t_min, t_max)`.
    pub fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<MeshHit> {
        self.intersect_from(0, ray, t_min, t_max)
    }

    /// [`Meshes::intersect`] searching from node `start` of the meshes' tree, which must
    /// be a [`Meshes::start_in`] of a frustum around the ray.
    pub(crate) fn intersect_from(
        &self,
        start: u32,
        ray: &Ray,
        t_min: f64,
        t_max: f64,
    ) -> Option<MeshHit> {
        if self.tris.is_empty() {
            return None;
        }
        let sh = RayShear::new(ray);
        let mut bary = [0.0; 3];
        let (prim, t) = self
            .bvh
            .nearest_from(start, ray, t_min, t_max, |p, lo, hi| {
                let tri = self.tris.get(p as usize)?;
                let h = intersect_triangle(&sh, tri.v[0], tri.v[1], tri.v[2], lo, hi)?;
                bary = h.bary;
                Some(h.t)
            })?;
        // `bary` belongs to the last accepted hit, which is the nearest one.
        let tri = self.tris.get(prim as usize)?;
        let n = bary[0] * tri.n[0] + bary[1] * tri.n[1] + bary[2] * tri.n[2];
        let normal = n
            .try_normalize()
            .or_else(|| {
                (tri.v[1] - tri.v[0])
                    .cross(tri.v[2] - tri.v[0])
                    .try_normalize()
            })
            .unwrap_or(DVec3::Z);
        Some(MeshHit {
            t,
            normal,
            colour: self
                .colours
                .get(tri.mesh as usize)
                .copied()
                .unwrap_or(Vec3::ONE),
        })
    }

    /// Whether anything blocks the ray within `(t_min, t_max)` (shadow rays).
    pub fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        if self.tris.is_empty() {
            return false;
        }
        let sh = RayShear::new(ray);
        self.bvh.any(ray, t_min, t_max, |p, lo, hi| {
            let tri = self.tris.get(p as usize)?;
            intersect_triangle(&sh, tri.v[0], tri.v[1], tri.v[2], lo, hi).map(|h| h.t)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::icosphere;
    use proptest::prelude::*;

    #[test]
    fn nearest_of_several_meshes_gives_its_colour() {
        let mut a = icosphere(DVec3::new(0.0, 0.0, 0.0), 1.0, 2);
        a.colour = Vec3::new(1.0, 0.0, 0.0);
        let mut b = icosphere(DVec3::new(0.0, 0.0, 5.0), 1.0, 2);
        b.colour = Vec3::new(0.0, 0.0, 1.0);
        let meshes = Meshes::from_meshes(&[a, b]);
        assert_eq!(meshes.triangle_count(), 2 * 320);
        let down = Ray {
            origin: DVec3::new(0.01, 0.02, 10.0),
            dir: DVec3::NEG_Z,
        };
        let h = meshes.intersect(&down, 0.0, f64::INFINITY).expect("hit");
        assert_eq!(h.colour, Vec3::new(0.0, 0.0, 1.0));
        assert!((h.t - 4.0).abs() < 0.02);
        // Starting between them, the first sphere is the nearest.
        let h = meshes.intersect(&down, 6.5, f64::INFINITY).expect("hit");
        assert_eq!(h.colour, Vec3::new(1.0, 0.0, 0.0));
        assert!((h.t - 9.0).abs() < 0.02);
        let b = meshes.bounds().expect("bounds");
        assert!((DVec3::from_array(b.min) - DVec3::new(-1.0, -1.0, -1.0)).length() < 1e-9);
        assert!((DVec3::from_array(b.max) - DVec3::new(1.0, 1.0, 6.0)).length() < 1e-9);
        assert!(Meshes::empty().bounds().is_none());
        assert!(Meshes::empty()
            .intersect(&down, 0.0, f64::INFINITY)
            .is_none());
    }

    /// Every camera ray of a group of pixels (at the group's corners and edges and at
    /// random sub-pixel offsets) finds from the group's start in the meshes' tree
    /// ([`Meshes::start_in`] of the group's frustum) the hit it finds from the root, bit
    /// for bit, or none where the group has no start: three spheres, cameras outside
    /// them, between them, looking along an axis through vertices, far away, and
    /// orthographic, the scene at the origin and at 1e6. Starts below the root and
    /// groups without one both occur.
    #[test]
    fn a_group_of_camera_rays_finds_the_same_hits_from_its_start() {
        use crate::camera::{Camera, Projection};
        let bits =
            |h: Option<MeshHit>| h.map(|h| (h.t.to_bits(), h.normal.to_array().map(f64::to_bits)));
        let mut seed = 5u64;
        let mut lcg = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut below_root, mut none, mut hits) = (0, 0, 0);
        for shift in [0.0, 1e6] {
            let at = |x: f64, y: f64, z: f64| DVec3::new(x, y, z) + DVec3::splat(shift);
            let meshes = Meshes::from_meshes(&[
                icosphere(at(0.0, 0.0, 0.0), 1.0, 3),
                icosphere(at(3.0, 0.5, 0.0), 0.7, 2),
                icosphere(at(-2.0, 2.0, 1.0), 0.5, 1),
            ]);
            let p = |v: DVec3| v.to_array();
            let persp = |fov_deg| Projection::Perspective { fov_deg };
            let cameras = [
                (at(6.0, -8.0, 4.0), at(0.5, 0.5, 0.0), persp(40.0)),
                (at(1.5, 0.2, 0.1), at(3.0, 0.5, 0.0), persp(80.0)),
                (at(0.0, 0.0, 9.0), at(0.0, 0.0, 0.0), persp(25.0)),
                (at(4e3, -3e3, 2e3), at(0.0, 0.0, 0.0), persp(0.1)),
                (
                    at(0.0, -9.0, 0.0),
                    at(0.0, 0.0, 0.0),
                    Projection::Orthographic { width: 7.0 },
                ),
            ];
            for (eye, look_at, projection) in cameras {
                let cam = Camera {
                    eye: p(eye),
                    look_at: p(look_at),
                    up: [0.0, 0.0, 1.0],
                    projection,
                };
                let (w, h) = (30u32, 22u32);
                let rays = cam.ray_generator(w, h);
                for (x0, y0, x1, y1) in crate::tiles::Tile::image(w, h).groups(4) {
                    let start = meshes.start_in(&rays.frustum(x0, y0, x1, y1, DVec3::ZERO));
                    match start {
                        None => none += 1,
                        Some(n) if n > 0 => below_root += 1,
                        Some(_) => {}
                    }
                    let mut points = vec![(x0, y0), (x1, y0), (x0, y1), (x1, y1)];
                    for _ in 0..12 {
                        points.push((x0 + (x1 - x0) * lcg(), y0 + (y1 - y0) * lcg()));
                    }
                    for (x, y) in points {
                        let ray = rays.ray(x, y);
                        let want = meshes.intersect(&ray, 0.0, f64::INFINITY);
                        let got =
                            start.and_then(|n| meshes.intersect_from(n, &ray, 0.0, f64::INFINITY));
                        assert_eq!(
                            bits(got),
                            bits(want),
                            "camera {cam:?}, pixel ({x}, {y}), start {start:?}"
                        );
                        hits += usize::from(want.is_some());
                    }
                }
            }
        }
        assert!(
            below_root > 40 && none > 40 && hits > 500,
            "{below_root} starts below the root, {none} groups without one, {hits} hits"
        );
    }

    #[test]
    fn rays_through_shared_vertices_and_edges_always_hit() {
        // An octahedron: its vertices and edge midpoints lie exactly on axes/planes, so
        // rays aimed at them hit shared edges and vertices exactly.
        let oct = TriangleMesh {
            positions: vec![
                DVec3::X,
                DVec3::NEG_X,
                DVec3::Y,
                DVec3::NEG_Y,
                DVec3::Z,
                DVec3::NEG_Z,
            ],
            triangles: vec![
                [0, 2, 4],
                [2, 1, 4],
                [1, 3, 4],
                [3, 0, 4],
                [2, 0, 5],
                [1, 2, 5],
                [3, 1, 5],
                [0, 3, 5],
            ],
            normals: None,
            colour: Vec3::ONE,
        };
        let meshes = Meshes::from_meshes(std::slice::from_ref(&oct));
        let mut targets = oct.positions.clone();
        for t in &oct.triangles {
            for k in 0..3 {
                let a = oct.positions[t[k] as usize];
                let b = oct.positions[t[(k + 1) % 3] as usize];
                for f in [0.5, 0.25, 1.0 / 3.0] {
                    targets.push(a + f * (b - a));
                }
            }
        }
        // From inside, every direction towards a vertex or edge point leaves through
        // the surface.
        for target in &targets {
            for origin in [
                DVec3::ZERO,
                DVec3::new(0.1, -0.2, 0.05),
                DVec3::new(-0.3, 0.1, 0.2),
            ] {
                let out = Ray {
                    origin,
                    dir: (*target - origin).normalize(),
                };
                assert!(
                    meshes.occluded(&out, 0.0, f64::INFINITY),
                    "{origin:?} -> {target:?}"
                );
                assert!(meshes.intersect(&out, 0.0, f64::INFINITY).is_some());
            }
        }
        // Axis-aligned rays from outside on a 1/8 grid (exact arithmetic): many enter
        // exactly through shared edges (a coordinate is 0) or vertices. Hit iff
        // |a| + |b| <= 1, at distance 3 - (1 - |a| - |b|).
        for axis in 0..3 {
            for sign in [1.0, -1.0] {
                for i in -8..=8 {
                    for j in -8..=8 {
                        let (a, b) = (f64::from(i) / 8.0, f64::from(j) / 8.0);
                        let mut o = [0.0; 3];
                        o[axis] = 3.0 * sign;
                        o[(axis + 1) % 3] = a;
                        o[(axis + 2) % 3] = b;
                        let mut d = [0.0; 3];
                        d[axis] = -sign;
                        let ray = Ray {
                            origin: DVec3::from_array(o),
                            dir: DVec3::from_array(d),
                        };
                        let h = meshes.intersect(&ray, 0.0, f64::INFINITY);
                        let inside = a.abs() + b.abs() <= 1.0;
                        assert_eq!(h.is_some(), inside, "axis {axis} sign {sign} at {a},{b}");
                        if let Some(h) = h {
                            let want = 3.0 - (1.0 - a.abs() - b.abs());
                            assert!((h.t - want).abs() < 1e-12, "{} vs {want}", h.t);
                        }
                        assert_eq!(meshes.occluded(&ray, 0.0, f64::INFINITY), inside);
                    }
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn closed_sphere_is_watertight_from_inside(
            c in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            d in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            shift in prop_oneof![Just(0.0), Just(1e6)],
            axis in 0usize..4,
        ) {
            let centre = DVec3::splat(shift);
            let sphere = icosphere(centre, 0.5, 2);
            let meshes = Meshes::from_meshes(&[sphere]);
            let origin = centre + 0.2 * DVec3::new(c.0, c.1, c.2);
            // Mix arbitrary directions with axis-aligned ones (which hit the
            // icosphere's symmetric vertices and edges).
            let dir = match axis {
                0 => DVec3::new(d.0, d.1, d.2),
                1 => DVec3::new(d.0.signum(), 0.0, 0.0),
                2 => DVec3::new(0.0, d.1.signum(), 0.0),
                _ => DVec3::new(0.0, 0.0, d.2.signum()),
            };
            prop_assume!(dir.length() > 1e-3);
            let ray = Ray { origin, dir: dir.normalize() };
            prop_assert!(meshes.occluded(&ray, 0.0, f64::INFINITY));
            let h = meshes.intersect(&ray, 0.0, f64::INFINITY);
            prop_assert!(h.is_some());
            // Hit lies on the sphere (within the chord error of level 2: ~2% of r).
            let p = ray.at(h.map_or(0.0, |h| h.t));
            prop_assert!(((p - centre).length() - 0.5).abs() < 0.02);
        }
    }
}
