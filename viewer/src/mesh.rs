//! Opaque triangle meshes from OBJ files (tobj), placed by translation and uniform scale.

use std::path::PathBuf;

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

use crate::camera::Ray;

/// How a mesh file is placed in the scene (part of the view state).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshInstance {
    pub path: PathBuf,
    pub translation: [f64; 3],
    pub scale: f64,
    pub colour: [f32; 3],
}

/// First intersection with a mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshHit {
    pub t: f64,
    /// Unit geometric (or interpolated) normal, not yet flipped towards the ray.
    pub normal: DVec3,
    pub colour: Vec3,
}

/// All meshes of a scene in one SAH BVH.
pub struct Meshes {}

impl Meshes {
    pub fn load(instances: &[MeshInstance]) -> Result<Meshes, MeshError> {
        let _ = instances;
        unimplemented!("provisional stub: the scene helper writes this")
    }

    pub fn empty() -> Meshes {
        Meshes {}
    }

    /// Nearest hit with `t` in `(t_min, t_max)`.
    pub fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<MeshHit> {
        let _ = (ray, t_min, t_max);
        None
    }

    /// Whether anything blocks the ray within `(t_min, t_max)` (shadow rays).
    pub fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        self.intersect(ray, t_min, t_max).is_some()
    }
}

#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", path.display())]
pub struct MeshError {
    pub path: PathBuf,
    pub message: String,
}
