//! Mouse navigation as changes to a [`Camera`]: orbit around a pivot, pan in the view
//! plane, zoom towards the cursor, frame a box. Pure functions of the camera, so the
//! window, the scripted orbit and the tests move the camera the same way.

use glam::{DQuat, DVec3};

use crate::camera::{Camera, Projection, DEFAULT_FOV_DEG};

/// Radians of orbit per pixel of drag.
pub(crate) const ORBIT_PER_PIXEL: f64 = 0.008;

/// Keeps the view direction this far (radians) from the up axis, so orbiting over the
/// pole never flips the picture.
const POLE_MARGIN: f64 = 0.02;

fn v(a: [f64; 3]) -> DVec3 {
    DVec3::from_array(a)
}

/// The up axis orbiting turns around: the camera's `up`, or +z when it is unusable.
fn up_axis(cam: &Camera) -> DVec3 {
    v(cam.up).try_normalize().unwrap_or(DVec3::Z)
}

/// Turns eye and look-at around `pivot`: `yaw` radians about the up axis, `pitch` about
/// the camera's right axis (positive: look from higher up).
pub fn orbit(cam: &mut Camera, pivot: [f64; 3], yaw: f64, pitch: f64) {
    let pivot = v(pivot);
    let up = up_axis(cam);
    let basis = cam.basis();
    let offset = v(cam.eye) - pivot;
    let dist = offset.length();
    if !(dist > 0.0 && dist.is_finite()) {
        return;
    }
    // Limit the pitch so the eye stays off the poles of the up axis.
    let angle_from_up = (offset / dist).dot(up).clamp(-1.0, 1.0).acos();
    let new_angle = (angle_from_up - pitch).clamp(POLE_MARGIN, std::f64::consts::PI - POLE_MARGIN);
    let pitch = angle_from_up - new_angle;
    let q = DQuat::from_axis_angle(up, yaw) * DQuat::from_axis_angle(basis.right, -pitch);
    cam.eye = (pivot + q * offset).to_array();
    cam.look_at = (pivot + q * (v(cam.look_at) - pivot)).to_array();
    cam.up = up.to_array();
}

/// World units per pixel at the distance of `pivot`, for an image `height_px` high.
pub(crate) fn world_per_pixel(cam: &Camera, pivot: [f64; 3], width_px: f64, height_px: f64) -> f64 {
    match cam.projection {
        Projection::Orthographic { width } => width / width_px.max(1.0),
        Projection::Perspective { fov_deg } => {
            let depth = (v(pivot) - v(cam.eye)).dot(cam.basis().forward).abs();
            2.0 * depth * (0.5 * fov_deg.to_radians()).tan() / height_px.max(1.0)
        }
    }
}

/// Moves the camera (and returns the moved pivot) so the scene follows a drag of
/// (`dx`, `dy`) pixels on an image `width_px`×`height_px`.
pub fn pan(
    cam: &mut Camera,
    pivot: [f64; 3],
    dx: f64,
    dy: f64,
    width_px: f64,
    height_px: f64,
) -> [f64; 3] {
    let s = world_per_pixel(cam, pivot, width_px, height_px);
    let b = cam.basis();
    let shift = (-dx * s) * b.right + (dy * s) * b.up;
    if !shift.is_finite() {
        return pivot;
    }
    cam.eye = (v(cam.eye) + shift).to_array();
    cam.look_at = (v(cam.look_at) + shift).to_array();
    (v(pivot) + shift).to_array()
}

/// Zooms by `factor` (< 1: closer) towards image position (`x`, `y`) in pixels of a
/// `width_px`×`height_px` image: the point under the cursor stays under the cursor.
pub(crate) fn zoom(
    cam: &mut Camera,
    pivot: [f64; 3],
    factor: f64,
    x: f64,
    y: f64,
    width_px: u32,
    height_px: u32,
) {
    if !(factor > 0.0 && factor.is_finite()) {
        return;
    }
    let rays = cam.ray_generator(width_px, height_px);
    match &mut cam.projection {
        Projection::Orthographic { width } => {
            // The cursor's offset from the image centre shrinks with the view.
            let centre = rays.ray(0.5 * f64::from(width_px), 0.5 * f64::from(height_px));
            let under = rays.ray(x, y);
            let offset = under.origin - centre.origin;
            *width *= factor;
            let shift = (1.0 - factor) * offset;
            cam.eye = (v(cam.eye) + shift).to_array();
            cam.look_at = (v(cam.look_at) + shift).to_array();
        }
        Projection::Perspective { .. } => {
            let ray = rays.ray(x, y);
            let dist = (v(pivot) - v(cam.eye)).length();
            let step = (1.0 - factor) * dist;
            if !step.is_finite() {
                return;
            }
            let shift = step * ray.dir;
            cam.eye = (v(cam.eye) + shift).to_array();
            cam.look_at = (v(cam.look_at) + shift).to_array();
        }
    }
}

/// A camera that shows the box `min..max` whole, keeping `cam`'s projection kind.
pub(crate) fn frame_box(cam: &Camera, min: [f64; 3], max: [f64; 3]) -> Camera {
    let mut framed = Camera::frame(min, max);
    if let Projection::Orthographic { .. } = cam.projection {
        let diag = (v(max) - v(min)).length();
        framed.projection = Projection::Orthographic {
            width: if diag > 0.0 && diag.is_finite() {
                1.1 * diag
            } else {
                1.0
            },
        };
    }
    framed
}

/// Switches between perspective and orthographic keeping the size of the picture at
/// the look-at point.
pub(crate) fn set_orthographic(cam: &mut Camera, ortho: bool, aspect: f64) {
    let dist = (v(cam.look_at) - v(cam.eye)).length();
    match (cam.projection, ortho) {
        (Projection::Perspective { fov_deg }, true) => {
            let h = 2.0 * dist * (0.5 * fov_deg.to_radians()).tan();
            cam.projection = Projection::Orthographic {
                width: (h * aspect).max(1e-9),
            };
        }
        (Projection::Orthographic { .. }, false) => {
            cam.projection = Projection::Perspective {
                fov_deg: DEFAULT_FOV_DEG,
            };
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera {
            eye: [5.0, -3.0, 2.0],
            look_at: [0.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            projection: Projection::Perspective { fov_deg: 40.0 },
        }
    }

    #[test]
    fn a_full_turn_of_orbit_returns_to_the_start() {
        let mut c = cam();
        for _ in 0..120 {
            orbit(&mut c, [0.0; 3], std::f64::consts::TAU / 120.0, 0.0);
        }
        for a in 0..3 {
            assert!((c.eye[a] - cam().eye[a]).abs() < 1e-9, "{:?}", c.eye);
        }
        // Distance to the pivot is kept at every step.
        let mut c = cam();
        orbit(&mut c, [0.0; 3], 0.7, 0.3);
        assert!((v(c.eye).length() - v(cam().eye).length()).abs() < 1e-12);
    }

    #[test]
    fn orbit_stops_short_of_the_pole() {
        let mut c = cam();
        orbit(&mut c, [0.0; 3], 0.0, 10.0);
        let dir = v(c.eye).normalize();
        assert!(dir.dot(DVec3::Z) < 1.0 - 1e-5, "{dir}");
        assert!(c.basis().right.is_finite());
    }

    #[test]
    fn pan_moves_the_scene_with_the_cursor() {
        let mut c = cam();
        let pivot = [0.0; 3];
        let (w, h) = (800u32, 600u32);
        // The pivot projects to the image centre; after a pan of (+40, +30) pixels the
        // old pivot must be seen 40 px right and 30 px down of the centre.
        let new_pivot = pan(&mut c, pivot, 40.0, 30.0, f64::from(w), f64::from(h));
        let ray = c.ray(400.0 + 40.0, 300.0 + 30.0, w, h);
        let to_old = v(pivot) - ray.origin;
        let off_ray = (to_old - to_old.dot(ray.dir) * ray.dir).length();
        assert!(off_ray < 1e-3 * to_old.length(), "{off_ray}");
        assert!(v(new_pivot).length() > 0.0);
    }

    #[test]
    fn zoom_keeps_the_point_under_the_cursor() {
        for proj in [
            Projection::Perspective { fov_deg: 40.0 },
            Projection::Orthographic { width: 4.0 },
        ] {
            let mut c = cam();
            c.projection = proj;
            let (w, h) = (640u32, 480u32);
            let (x, y) = (500.0, 120.0);
            let before = c.ray(x, y, w, h);
            zoom(&mut c, [0.0; 3], 0.8, x, y, w, h);
            let after = c.ray(x, y, w, h);
            assert!((after.dir - before.dir).length() < 1e-9, "{proj:?}");
            // Same line through the scene: the new origin lies on the old ray.
            let d = after.origin - before.origin;
            let off = (d - d.dot(before.dir) * before.dir).length();
            assert!(off < 1e-9, "{proj:?}: {off}");
            if let Projection::Orthographic { width } = c.projection {
                assert!((width - 3.2).abs() < 1e-12);
            } else {
                assert!(v(c.eye).length() < v(cam().eye).length());
            }
        }
    }

    #[test]
    fn framing_keeps_the_projection_kind() {
        let mut c = cam();
        set_orthographic(&mut c, true, 1.5);
        let f = frame_box(&c, [0.0; 3], [1.0, 2.0, 3.0]);
        assert!(matches!(f.projection, Projection::Orthographic { .. }));
        set_orthographic(&mut c, false, 1.5);
        assert!(matches!(c.projection, Projection::Perspective { .. }));
    }
}
