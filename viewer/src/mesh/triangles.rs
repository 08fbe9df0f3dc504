//! A triangle mesh in world coordinates, as loaded and placed (or built for a test).

use glam::{DVec3, Vec3};

/// An indexed triangle mesh in world coordinates (after placement).
#[derive(Debug, Clone, PartialEq)]
pub struct TriangleMesh {
    pub positions: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
    /// Per-vertex normals (same length as `positions`), if the file has them.
    pub normals: Option<Vec<DVec3>>,
    pub colour: Vec3,
}
