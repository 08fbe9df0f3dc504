//! Opaque triangle meshes from OBJ files (tobj), placed by translation and uniform scale.

use std::path::PathBuf;

use files::input::{read_whole, InputErrorKind, Limits};
pub use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

use format::Aabb;

use crate::bvh::{box_of, intersect_triangle, Bvh, RayShear};
use crate::camera::Ray;

/// How a mesh file is placed in the scene (part of the view state): a vertex `v` of the
/// file ends up at `translation + scale · v`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshInstance {
    pub path: PathBuf,
    pub translation: [f64; 3],
    pub scale: f64,
    pub colour: [f32; 3],
}

/// Default colour of meshes given on the command line: light grey.
pub(crate) const DEFAULT_MESH_COLOUR: [f32; 3] = [0.8, 0.8, 0.8];

impl MeshInstance {
    /// A mesh at its file coordinates.
    pub fn at_origin(path: impl Into<PathBuf>) -> MeshInstance {
        MeshInstance {
            path: path.into(),
            translation: [0.0; 3],
            scale: 1.0,
            colour: DEFAULT_MESH_COLOUR,
        }
    }

    /// Parses the CLI form `PATH[@x,y,z,scale]`, e.g. `data/sphere.obj@0,0,0,1`.
    pub(crate) fn parse(spec: &str) -> Result<MeshInstance, MeshSpecError> {
        let Some((path, place)) = spec.rsplit_once('@') else {
            return Ok(MeshInstance::at_origin(spec));
        };
        let nums: Vec<f64> = place
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|error| MeshSpecError::Number {
                place: place.to_string(),
                error,
            })?;
        let [x, y, z, scale] = nums[..] else {
            return Err(MeshSpecError::Count {
                place: place.to_string(),
                found: nums.len(),
            });
        };
        let m = MeshInstance {
            translation: [x, y, z],
            scale,
            ..MeshInstance::at_origin(path)
        };
        m.validate().map_err(MeshSpecError::Placement)?;
        Ok(m)
    }

    /// Finite translation, finite positive scale, colour components in 0..=1.
    pub(crate) fn validate(&self) -> Result<(), MeshError> {
        let err = |kind| Err(MeshError::new(&self.path, kind));
        if self.translation.iter().any(|x| !x.is_finite()) {
            return err(MeshErrorKind::Translation {
                translation: self.translation,
            });
        }
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return err(MeshErrorKind::Scale { scale: self.scale });
        }
        if self.colour.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return err(MeshErrorKind::Colour {
                colour: self.colour,
            });
        }
        Ok(())
    }
}

/// First intersection with a mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshHit {
    pub t: f64,
    /// Unit geometric (or interpolated) normal, not yet flipped towards the ray.
    pub normal: DVec3,
    pub colour: Vec3,
}

/// An indexed triangle mesh in world coordinates (after placement).
#[derive(Debug, Clone, PartialEq)]
pub struct TriangleMesh {
    pub positions: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
    /// Per-vertex normals (same length as `positions`), if the file has them.
    pub normals: Option<Vec<DVec3>>,
    pub colour: Vec3,
}

impl TriangleMesh {
    /// Loads an OBJ file (all its models, triangulated) and places it.
    pub(crate) fn load_obj(instance: &MeshInstance) -> Result<TriangleMesh, MeshError> {
        let path = &instance.path;
        let err = |kind| MeshError::new(path, kind);
        instance.validate()?;
        // Read the file ourselves (tobj's "open failed"/"read error" do not say why, and it
        // would read `/dev/zero` until memory runs out); materials are not used.
        let text = read_whole(path, Limits::memory()).map_err(|e| match e.kind {
            InputErrorKind::IsDirectory => err(MeshErrorKind::IsDirectory),
            InputErrorKind::Io(e) => err(MeshErrorKind::Read(e)),
            kind => err(MeshErrorKind::Input(kind)),
        })?;
        let (models, _materials) = tobj::load_obj_buf(
            &mut text.as_slice(),
            &tobj::LoadOptions {
                triangulate: true,
                single_index: true,
                ignore_points: true,
                ignore_lines: true,
            },
            |_| Err(tobj::LoadError::OpenFileFailed),
        )
        .map_err(|e| err(MeshErrorKind::NotObj(e)))?;

        let mut mesh = TriangleMesh {
            positions: Vec::new(),
            triangles: Vec::new(),
            normals: Some(Vec::new()),
            colour: Vec3::from_array(instance.colour),
        };
        let t = DVec3::from_array(instance.translation);
        for model in &models {
            let m = &model.mesh;
            let base = mesh.positions.len();
            let count = m.positions.len() / 3;
            for (i, p) in m.positions.chunks_exact(3).enumerate() {
                let v = DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
                if !v.is_finite() {
                    return Err(err(MeshErrorKind::VertexNotFinite {
                        object: model.name.clone(),
                        vertex: i + 1,
                        position: v.to_array(),
                    }));
                }
                mesh.positions.push(t + instance.scale * v);
            }
            // Keep normals only if every model has one per vertex.
            if m.normals.len() == m.positions.len() {
                if let Some(ns) = mesh.normals.as_mut() {
                    ns.extend(m.normals.chunks_exact(3).map(|n| {
                        DVec3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2]))
                            .try_normalize()
                            .unwrap_or(DVec3::ZERO)
                    }));
                }
            } else {
                mesh.normals = None;
            }
            for (f, tri) in m.indices.chunks_exact(3).enumerate() {
                let mut idx = [0u32; 3];
                for (k, &vi) in tri.iter().enumerate() {
                    if vi as usize >= count {
                        return Err(err(MeshErrorKind::VertexOutOfRange {
                            object: model.name.clone(),
                            face: f + 1,
                            vertex: u64::from(vi) + 1,
                            vertices: count,
                        }));
                    }
                    idx[k] = (base + vi as usize) as u32;
                }
                mesh.triangles.push(idx);
            }
        }
        if mesh.triangles.is_empty() {
            return Err(err(MeshErrorKind::NoTriangles));
        }
        Ok(mesh)
    }

    /// Writes the mesh as OBJ text (positions, normals if any, 1-based faces).
    pub fn to_obj(&self, comment: &str) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        for line in comment.lines() {
            let _ = writeln!(s, "# {line}");
        }
        for p in &self.positions {
            let _ = writeln!(s, "v {} {} {}", fmt6(p.x), fmt6(p.y), fmt6(p.z));
        }
        if let Some(ns) = &self.normals {
            for n in ns {
                let _ = writeln!(s, "vn {} {} {}", fmt6(n.x), fmt6(n.y), fmt6(n.z));
            }
        }
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| i + 1);
            if self.normals.is_some() {
                let _ = writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}");
            } else {
                let _ = writeln!(s, "f {a} {b} {c}");
            }
        }
        s
    }
}

/// Shortest text for `x` rounded to 6 decimals (`-0` printed as `0`).
fn fmt6(x: f64) -> String {
    let s = format!("{x:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" || s.is_empty() {
        "0".to_string()
    } else {
        s.to_string()
    }
}

/// A sphere of `radius` around `centre` from a subdivided icosahedron
/// (`20·4^subdivisions` triangles, counter-clockwise seen from outside), with exact
/// radial normals.
#[cfg(any(test, feature = "testkit"))]
pub fn icosphere(centre: DVec3, radius: f64, subdivisions: u32) -> TriangleMesh {
    let g = (1.0 + 5f64.sqrt()) / 2.0;
    let mut unit: Vec<DVec3> = [
        [-1.0, g, 0.0],
        [1.0, g, 0.0],
        [-1.0, -g, 0.0],
        [1.0, -g, 0.0],
        [0.0, -1.0, g],
        [0.0, 1.0, g],
        [0.0, -1.0, -g],
        [0.0, 1.0, -g],
        [g, 0.0, -1.0],
        [g, 0.0, 1.0],
        [-g, 0.0, -1.0],
        [-g, 0.0, 1.0],
    ]
    .iter()
    .map(|p| DVec3::from_array(*p).normalize())
    .collect();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut cache: std::collections::HashMap<(u32, u32), u32> = Default::default();
        let mut mid = |a: u32, b: u32, unit: &mut Vec<DVec3>| -> u32 {
            let key = (a.min(b), a.max(b));
            *cache.entry(key).or_insert_with(|| {
                let p = (unit[a as usize] + unit[b as usize]).normalize();
                unit.push(p);
                (unit.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(tris.len() * 4);
        for [a, b, c] in tris {
            let ab = mid(a, b, &mut unit);
            let bc = mid(b, c, &mut unit);
            let ca = mid(c, a, &mut unit);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    TriangleMesh {
        positions: unit.iter().map(|u| centre + radius * *u).collect(),
        triangles: tris,
        normals: Some(unit),
        colour: Vec3::from_array(DEFAULT_MESH_COLOUR),
    }
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

    /// Bounds of all triangles, `None` without triangles.
    #[cfg(test)]
    pub(crate) fn bounds(&self) -> Option<Aabb> {
        let b = self.bvh.bounds();
        (!b.is_empty()).then_some(b)
    }

    /// Nearest hit with `t` in `(t_min, t_max)`.
    pub fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<MeshHit> {
        if self.tris.is_empty() {
            return None;
        }
        let sh = RayShear::new(ray);
        let mut bary = [0.0; 3];
        let (prim, t) = self.bvh.nearest(ray, t_min, t_max, |p, lo, hi| {
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

/// Why a `PATH[@x,y,z,scale]` mesh spec is refused.
#[derive(Debug, thiserror::Error)]
pub enum MeshSpecError {
    #[error("mesh placement `{place}`: expected x,y,z,scale numbers: {error}")]
    Number {
        place: String,
        error: std::num::ParseFloatError,
    },
    #[error("mesh placement `{place}`: expected 4 numbers x,y,z,scale, found {found}")]
    Count { place: String, found: usize },
    /// The numbers parse but do not place a mesh (a scale ≤ 0, …).
    #[error("{0}")]
    Placement(MeshError),
}

/// A mesh that cannot be placed or loaded: the file and what is wrong with it.
#[derive(Debug, thiserror::Error)]
#[error("{}: {kind}", path.display())]
pub struct MeshError {
    pub path: PathBuf,
    pub kind: MeshErrorKind,
}

impl MeshError {
    pub(crate) fn new(path: impl Into<PathBuf>, kind: MeshErrorKind) -> Self {
        Self {
            path: path.into(),
            kind,
        }
    }
}

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MeshErrorKind {
    #[error("translation: not finite ({translation:?})")]
    Translation { translation: [f64; 3] },
    #[error("scale: expected a finite number > 0, found {scale}")]
    Scale { scale: f64 },
    #[error("colour: expected components in 0..=1, found {colour:?}")]
    Colour { colour: [f32; 3] },
    #[error("is a directory, expected an OBJ file")]
    IsDirectory,
    #[error("cannot read OBJ file: {0}")]
    Read(std::io::Error),
    /// Reading the file whole failed otherwise (a device, over the size limit...).
    #[error("{0}")]
    Input(InputErrorKind),
    #[error("not a valid OBJ file: {0}")]
    NotObj(tobj::LoadError),
    /// Vertex numbers are 1-based, as in the file.
    #[error("object `{object}`: vertex {vertex} is not finite ({:?})", DVec3::from_array(*.position))]
    VertexNotFinite {
        object: String,
        vertex: usize,
        position: [f64; 3],
    },
    /// Face and vertex numbers are 1-based, as in the file.
    #[error("object `{object}`: face {face} refers to vertex {vertex}, but there are {vertices} vertices")]
    VertexOutOfRange {
        object: String,
        face: usize,
        vertex: u64,
        vertices: usize,
    },
    #[error("expected at least one triangle, found none")]
    NoTriangles,
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::path::Path;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).expect("write obj");
        p
    }

    #[test]
    fn icosphere_is_closed_and_round() {
        let s = icosphere(DVec3::new(1.0, 2.0, 3.0), 0.5, 3);
        assert_eq!(s.triangles.len(), 20 * 64);
        assert_eq!(s.positions.len(), 10 * 64 + 2);
        for p in &s.positions {
            assert!(((*p - DVec3::new(1.0, 2.0, 3.0)).length() - 0.5).abs() < 1e-12);
        }
        // Closed, consistently oriented: each directed edge appears once, its reverse once.
        let mut edges = std::collections::HashMap::new();
        for t in &s.triangles {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1);
            assert_eq!(edges.get(&(b, a)), Some(&1));
        }
        // Outward winding.
        let c = DVec3::new(1.0, 2.0, 3.0);
        for t in &s.triangles {
            let [a, b, d] = t.map(|i| s.positions[i as usize]);
            assert!((b - a).cross(d - a).dot(a - c) > 0.0);
        }
    }

    #[test]
    fn obj_round_trip_and_placement() {
        let dir = tempfile::tempdir().expect("tempdir");
        let s = icosphere(DVec3::ZERO, 0.5, 1);
        let path = write(dir.path(), "s.obj", &s.to_obj("test sphere"));
        let inst = MeshInstance {
            path: path.clone(),
            translation: [10.0, 0.0, 0.0],
            scale: 2.0,
            colour: [0.5, 0.5, 0.5],
        };
        let m = TriangleMesh::load_obj(&inst).expect("load");
        assert_eq!(m.triangles.len(), s.triangles.len());
        for p in &m.positions {
            assert!(((*p - DVec3::new(10.0, 0.0, 0.0)).length() - 1.0).abs() < 1e-5);
        }
        assert!(m.normals.is_some());
        let meshes = Meshes::load(&[inst]).expect("load");
        // Ray along -x from far away hits the placed sphere (radius 1 at x=10) at x=11.
        let ray = Ray {
            origin: DVec3::new(20.0, 0.01, 0.02),
            dir: DVec3::NEG_X,
        };
        let h = meshes.intersect(&ray, 0.0, f64::INFINITY).expect("hit");
        assert!((h.t - 9.0).abs() < 0.05, "{}", h.t);
        assert!(h.normal.dot(DVec3::X) > 0.95);
        assert_eq!(h.colour, Vec3::splat(0.5));
        assert!(meshes.occluded(&ray, 0.0, 100.0));
        assert!(!meshes.occluded(&ray, 0.0, 8.0));
        assert!(meshes.intersect(&ray, 0.0, 8.0).is_none());
        // From inside, the far wall is hit.
        let inside = Ray {
            origin: DVec3::new(10.0, 0.0, 0.0),
            dir: DVec3::X,
        };
        let h = meshes.intersect(&inside, 0.0, f64::INFINITY).expect("hit");
        assert!((h.t - 1.0).abs() < 0.05);
    }

    #[test]
    fn bad_files_give_clear_errors() {
        let dir = tempfile::tempdir().expect("tempdir");
        let missing = dir.path().join("nope.obj");
        let e = Meshes::load(&[MeshInstance::at_origin(&missing)]).expect_err("missing");
        assert_eq!(e.path, missing);
        assert!(e.to_string().contains("nope.obj"), "{e}");
        let empty = write(dir.path(), "empty.obj", "# nothing\nv 0 0 0\n");
        let e = Meshes::load(&[MeshInstance::at_origin(&empty)]).expect_err("empty");
        assert!(matches!(e.kind, MeshErrorKind::NoTriangles), "{e}");
        assert!(e.to_string().contains("triangle"), "{e}");
        let bad = write(dir.path(), "bad.obj", "v 0 0 0\nv 1 0 0\nf 1 2 7\n");
        let e = Meshes::load(&[MeshInstance::at_origin(&bad)]).expect_err("bad index");
        assert!(matches!(e.kind, MeshErrorKind::NotObj(_)), "{e}");
        assert!(e.to_string().contains("bad.obj"), "{e}");
        let garbage = write(dir.path(), "garbage.obj", "v 0 zero 0\nf 1 1 1\n");
        let e = Meshes::load(&[MeshInstance::at_origin(&garbage)]).expect_err("garbage");
        assert!(e.to_string().contains("garbage.obj"), "{e}");
        let e = Meshes::load(&[MeshInstance::at_origin(dir.path())]).expect_err("directory");
        assert!(matches!(e.kind, MeshErrorKind::IsDirectory), "{e}");
        let ok = write(
            dir.path(),
            "tri.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        );
        let mut inst = MeshInstance::at_origin(&ok);
        inst.scale = 0.0;
        let e = Meshes::load(&[inst]).expect_err("scale");
        assert!(matches!(e.kind, MeshErrorKind::Scale { .. }), "{e}");
        assert!(e.kind.to_string().starts_with("scale"), "{e}");
        assert!(Meshes::load(&[MeshInstance::at_origin(&ok)]).is_ok());
    }

    #[test]
    fn bundled_sphere_matches_the_sample_obstacle() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/sphere.obj");
        assert!(std::fs::metadata(&path).expect("data/sphere.obj").len() < 400_000);
        let m = TriangleMesh::load_obj(&MeshInstance::at_origin(&path)).expect("load");
        assert!(m.triangles.len() >= 1280);
        for p in &m.positions {
            assert!((p.length() - 0.5).abs() < 1e-5, "{p:?}");
        }
        let ns = m.normals.as_ref().expect("normals");
        for (p, n) in m.positions.iter().zip(ns) {
            assert!((*n - *p / 0.5).length() < 1e-5);
        }
    }

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

    #[test]
    fn parse_cli_spec() {
        let m = MeshInstance::parse("data/sphere.obj@1,2,3,0.5").expect("parse");
        assert_eq!(m.path, PathBuf::from("data/sphere.obj"));
        assert_eq!(m.translation, [1.0, 2.0, 3.0]);
        assert_eq!(m.scale, 0.5);
        assert_eq!(MeshInstance::parse("a.obj").expect("plain").scale, 1.0);
        assert!(matches!(
            MeshInstance::parse("a.obj@1,2,3"),
            Err(MeshSpecError::Count { found: 3, .. })
        ));
        assert!(matches!(
            MeshInstance::parse("a.obj@1,2,3,x"),
            Err(MeshSpecError::Number { .. })
        ));
        assert!(matches!(
            MeshInstance::parse("a.obj@1,2,3,-1"),
            Err(MeshSpecError::Placement(MeshError {
                kind: MeshErrorKind::Scale { .. },
                ..
            }))
        ));
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
