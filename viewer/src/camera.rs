//! A pure camera: pose and projection; turns (pixel, sub-pixel offset) into a world ray.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// A ray `origin + t * dir` in world units; `dir` is unit length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: DVec3,
    pub dir: DVec3,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Projection {
    /// Vertical field of view in degrees.
    Perspective { fov_deg: f64 },
    /// Width of the view in world units.
    Orthographic { width: f64 },
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub eye: [f64; 3],
    pub look_at: [f64; 3],
    pub up: [f64; 3],
    pub projection: Projection,
}

impl Camera {
    /// Ray through image position (`x`, `y`) in pixels (0,0 = top-left corner of the
    /// image; pixel centres at +0.5) of a `width`×`height` image.
    pub fn ray(&self, x: f64, y: f64, width: u32, height: u32) -> Ray {
        let _ = (x, y, width, height);
        unimplemented!("provisional stub: the scene helper writes this")
    }

    /// A camera that frames the box `min..max` from a pleasant oblique direction.
    pub fn frame(min: [f64; 3], max: [f64; 3]) -> Camera {
        let _ = (min, max);
        unimplemented!("provisional stub: the scene helper writes this")
    }
}
