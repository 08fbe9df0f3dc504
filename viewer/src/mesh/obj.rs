//! OBJ files: loading one (all its models, triangulated, read whole within the memory
//! limit) and placing it, and writing a mesh as OBJ text.

use files::input::{read_whole, InputErrorKind, Limits};
use glam::{DVec3, Vec3};

use super::error::{MeshError, MeshErrorKind};
use super::placement::MeshInstance;
use super::triangles::TriangleMesh;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Ray;
    use crate::mesh::{icosphere, Meshes};
    use std::path::{Path, PathBuf};

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).expect("write obj");
        p
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
}
