//! Opaque triangle meshes in the scene: how a mesh file is placed (part of the view
//! state), the mesh in world coordinates, and all meshes of a scene in one BVH.
//!
//! One file per concept: `placement` is where a mesh file goes and how the command line
//! and the panel give it (`PATH[@x,y,z,scale]`), `triangles` a mesh in world
//! coordinates, `obj` loads and writes OBJ files (tobj), `meshes` intersects rays with all
//! of a scene's, `icosphere` builds spheres for tests, `error` says why a mesh is refused.

pub use glam::{DVec3, Vec3};

mod error;
#[cfg(any(test, feature = "testkit"))]
mod icosphere;
mod meshes;
mod obj;
mod placement;
mod triangles;

pub use error::{MeshError, MeshErrorKind};
#[cfg(any(test, feature = "testkit"))]
pub use icosphere::icosphere;
pub use meshes::{MeshHit, Meshes};
pub use placement::{MeshInstance, MeshSpecError};
pub use triangles::TriangleMesh;
