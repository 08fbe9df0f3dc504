//! Lights and Phong shading.

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Light {
    /// Light travelling along `direction` (world units, need not be normalised).
    Directional {
        direction: [f64; 3],
        colour: [f32; 3],
        intensity: f32,
    },
    Point {
        position: [f64; 3],
        colour: [f32; 3],
        intensity: f32,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Material {
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    pub shininess: f32,
}

impl Light {
    /// Unit direction from `p` towards the light, and the distance to it (∞ for directional).
    pub fn towards(&self, p: DVec3) -> (DVec3, f64) {
        let _ = p;
        unimplemented!("provisional stub: the scene helper writes this")
    }
}

/// Phong shading of a surface point with unit `normal` (flipped to face the viewer),
/// `view` the unit direction from the point to the eye, `visibility[i]` the shadow
/// transmittance towards light `i` (1 = unshadowed).
pub fn phong(
    base: Vec3,
    normal: DVec3,
    view: DVec3,
    p: DVec3,
    lights: &[Light],
    visibility: &[f32],
    material: &Material,
) -> Vec3 {
    let _ = (base, normal, view, p, lights, visibility, material);
    unimplemented!("provisional stub: the scene helper writes this")
}
