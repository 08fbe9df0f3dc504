//! A pure camera: pose and projection; turns (pixel, sub-pixel offset) into a world ray.
//!
//! The camera knows nothing about the volume or the renderer: it is a pose (`eye`,
//! `look_at`, `up`) and a projection. Degenerate poses (eye on the look-at point, `up`
//! parallel to the view direction, non-finite numbers) never panic and never produce a
//! NaN ray; they fall back to a fixed, documented basis instead.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// A ray `origin + t * dir` in world units; `dir` is unit length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: DVec3,
    pub dir: DVec3,
}

impl Ray {
    /// Point at parameter `t`.
    pub(crate) fn at(&self, t: f64) -> DVec3 {
        self.origin + t * self.dir
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Projection {
    /// Vertical field of view in degrees.
    Perspective { fov_deg: f64 },
    /// Width of the view in world units.
    Orthographic { width: f64 },
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    pub eye: [f64; 3],
    pub look_at: [f64; 3],
    pub up: [f64; 3],
    pub projection: Projection,
}

/// Default vertical field of view of [`Camera::frame`], degrees.
pub(crate) const DEFAULT_FOV_DEG: f64 = 35.0;

/// Orthonormal camera basis: `forward` points from the eye into the scene, `right` and
/// `up` span the image plane (x to the right, y up on screen).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Basis {
    pub(crate) forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
}

/// Camera rays of one image size with the basis computed once ([`Camera::ray_generator`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayGen {
    basis: Basis,
    eye: DVec3,
    w: f64,
    h: f64,
    half_w: f64,
    half_h: f64,
    ortho: bool,
}

impl RayGen {
    /// Ray through image position (`x`, `y`) in pixels, as [`Camera::ray`].
    #[inline]
    pub(crate) fn ray(&self, x: f64, y: f64) -> Ray {
        let b = &self.basis;
        // Normalised device coordinates in [-1, 1], y up.
        let sx = 2.0 * x / self.w - 1.0;
        let sy = 1.0 - 2.0 * y / self.h;
        if self.ortho {
            Ray {
                origin: self.eye + (sx * self.half_w) * b.right + (sy * self.half_h) * b.up,
                dir: b.forward,
            }
        } else {
            let dir = b.forward + (sx * self.half_w) * b.right + (sy * self.half_h) * b.up;
            Ray {
                origin: self.eye,
                dir: dir.normalize(),
            }
        }
    }
}

impl RayGen {
    /// Where the world point `p` appears: the image position (`x`, `y` in pixels, as
    /// [`RayGen::ray`] takes them) and the parameter `t` of `p` along the ray through
    /// there (its distance from the eye, or from the image plane for an orthographic
    /// camera). `None` for a point behind the camera, which no camera ray reaches.
    pub fn project(&self, p: [f64; 3]) -> Option<(f64, f64, f64)> {
        let b = &self.basis;
        let v = DVec3::from_array(p) - self.eye;
        let z = v.dot(b.forward);
        if z.is_nan() || z <= 0.0 {
            return None;
        }
        let (sx, sy, t) = if self.ortho {
            (v.dot(b.right) / self.half_w, v.dot(b.up) / self.half_h, z)
        } else {
            (
                v.dot(b.right) / (z * self.half_w),
                v.dot(b.up) / (z * self.half_h),
                v.length(),
            )
        };
        Some((0.5 * (sx + 1.0) * self.w, 0.5 * (1.0 - sy) * self.h, t))
    }

    /// World length of one pixel at distance `depth` from the eye along the view (any
    /// depth for an orthographic camera): how long a scale bar is.
    pub fn pixel_size_at(&self, depth: f64) -> f64 {
        if self.ortho {
            2.0 * self.half_h / self.h
        } else {
            2.0 * self.half_h * depth / self.h
        }
    }

    /// Where perspective rays start (for an orthographic camera, the centre of the
    /// plane they start from).
    pub fn eye(&self) -> [f64; 3] {
        self.eye.to_array()
    }

    /// Whether the projection is orthographic.
    pub fn is_orthographic(&self) -> bool {
        self.ortho
    }

    /// The camera's unit axes (world): to the right on screen, up on screen, into the
    /// scene.
    pub fn axes(&self) -> [[f64; 3]; 3] {
        [
            self.basis.right.to_array(),
            self.basis.up.to_array(),
            self.basis.forward.to_array(),
        ]
    }
}

impl RayGen {
    /// The rays of every point of the pixel rectangle `[x0, x1] × [y0, y1]` (any
    /// sub-pixel offset), with `frame` subtracted from positions as the volume's local
    /// frame does: see [`Frustum`].
    pub(crate) fn frustum(&self, x0: f64, y0: f64, x1: f64, y1: f64, frame: DVec3) -> Frustum {
        let b = &self.basis;
        // Normalised device coordinates: x grows to the right, y upwards (so from y1).
        let (sx0, sx1) = (2.0 * x0 / self.w - 1.0, 2.0 * x1 / self.w - 1.0);
        let (sy0, sy1) = (1.0 - 2.0 * y1 / self.h, 1.0 - 2.0 * y0 / self.h);
        let (ax0, ax1) = (sx0 * self.half_w, sx1 * self.half_w);
        let (ay0, ay1) = (sy0 * self.half_h, sy1 * self.half_h);
        // A point `eye + s (forward + a right + c up)` (perspective, s ≥ 0) or
        // `eye + a right + c up + s forward` (orthographic) of the group has
        // a ∈ [ax0, ax1] and c ∈ [ay0, ay1]: four half-spaces `n·(X − eye) ≥ k`.
        let planes = if self.ortho {
            [(b.right, ax0), (-b.right, -ax1), (b.up, ay0), (-b.up, -ay1)]
        } else {
            [
                (b.right - ax0 * b.forward, 0.0),
                (ax1 * b.forward - b.right, 0.0),
                (b.up - ay0 * b.forward, 0.0),
                (ay1 * b.forward - b.up, 0.0),
            ]
        };
        Frustum {
            eye: self.eye - frame,
            planes,
        }
    }
}

/// The rays of a rectangle of pixels as four half-spaces that contain every one of them
/// (for a perspective camera, the pyramid from the eye through the rectangle; for an
/// orthographic one, the prism along the view). A box wholly outside one half-space is
/// met by none of those rays, so a group of pixels can skip what its frustum misses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Frustum {
    eye: DVec3,
    /// `(n, k)`: the rays lie where `n·(X − eye) ≥ k`.
    planes: [(DVec3, f64); 4],
}

impl Frustum {
    /// Whether some ray of the frustum may meet the box `min..max` (same frame as the
    /// frustum). Never false for a box a ray meets: the test allows a billionth of the
    /// distances involved for round-off in the rays (computed point by point) and here,
    /// and anything non-finite counts as "may meet".
    pub(crate) fn may_meet(&self, min: &[f64; 3], max: &[f64; 3]) -> bool {
        let (lo, hi) = (DVec3::from_array(*min), DVec3::from_array(*max));
        let centre = 0.5 * (lo + hi) - self.eye;
        let half = 0.5 * (hi - lo);
        let size =
            centre.abs().element_sum() + half.abs().element_sum() + self.eye.abs().element_sum();
        self.planes.iter().all(|&(n, k)| {
            // Largest `n·(X − eye) − k` over the box.
            let most = n.dot(centre) + n.abs().dot(half) - k;
            let slack = 1e-9 * (n.abs().element_sum() * size + k.abs());
            // NaN compares false: "may meet".
            most.partial_cmp(&-slack) != Some(std::cmp::Ordering::Less)
        })
    }
}

fn finite_vec(a: [f64; 3]) -> Option<DVec3> {
    let v = DVec3::from_array(a);
    v.is_finite().then_some(v)
}

impl Camera {
    /// The camera's orthonormal basis.
    ///
    /// Fallbacks: if `eye == look_at` (or either is not finite) the camera looks along
    /// −z; if `up` is zero, not finite or parallel to the view direction, the world axis
    /// least aligned with the view direction is used as `up` instead.
    pub(crate) fn basis(&self) -> Basis {
        let forward = match (finite_vec(self.eye), finite_vec(self.look_at)) {
            (Some(e), Some(l)) => (l - e).try_normalize().unwrap_or(DVec3::NEG_Z),
            _ => DVec3::NEG_Z,
        };
        let up_hint = finite_vec(self.up).and_then(DVec3::try_normalize);
        // `up` must not be (nearly) parallel to `forward`: 1e-9 in sin(angle) still gives
        // a well-conditioned cross product in f64.
        let right = up_hint
            .map(|u| forward.cross(u))
            .filter(|c| c.length() > 1e-9)
            .map(DVec3::normalize)
            .unwrap_or_else(|| {
                let a = forward.abs();
                let axis = if a.x <= a.y && a.x <= a.z {
                    DVec3::X
                } else if a.y <= a.z {
                    DVec3::Y
                } else {
                    DVec3::Z
                };
                forward.cross(axis).normalize()
            });
        let up = right.cross(forward);
        Basis { forward, right, up }
    }

    /// Ray through image position (`x`, `y`) in pixels (0,0 = top-left corner of the
    /// image; pixel centres at +0.5) of a `width`×`height` image.
    ///
    /// Perspective rays start at the eye; orthographic rays start on the plane through
    /// the eye perpendicular to the view direction (so a camera inside the volume sees
    /// what is in front of that plane) and all share the view direction. For many rays
    /// use [`Camera::ray_generator`], which computes the basis once (same rays).
    #[cfg(test)]
    pub(crate) fn ray(&self, x: f64, y: f64, width: u32, height: u32) -> Ray {
        self.ray_generator(width, height).ray(x, y)
    }

    /// Per-frame constants of [`Camera::ray`] for a `width`×`height` image.
    pub fn ray_generator(&self, width: u32, height: u32) -> RayGen {
        let b = self.basis();
        let w = f64::from(width.max(1));
        let h = f64::from(height.max(1));
        let aspect = w / h;
        let eye = finite_vec(self.eye).unwrap_or(DVec3::ZERO);
        let (ortho, half_w, half_h) = match self.projection {
            Projection::Perspective { fov_deg } => {
                let fov = if fov_deg.is_finite() && fov_deg > 0.0 && fov_deg < 179.0 {
                    fov_deg
                } else {
                    DEFAULT_FOV_DEG
                };
                let half_h = (0.5 * fov.to_radians()).tan();
                (false, half_h * aspect, half_h)
            }
            Projection::Orthographic { width: ow } => {
                let ow = if ow.is_finite() && ow > 0.0 { ow } else { 1.0 };
                let half_w = 0.5 * ow;
                (true, half_w, half_w / aspect)
            }
        };
        RayGen {
            basis: b,
            eye,
            w,
            h,
            half_w,
            half_h,
            ortho,
        }
    }

    /// A camera that frames the box `min..max` from a pleasant oblique direction.
    ///
    /// The camera looks at the box centre from the (+x, −y, +z) octant, slightly from
    /// above (`up` = +z), just far enough for every box corner to fit the vertical field
    /// of view of [`DEFAULT_FOV_DEG`] (plus 5 %) on both image axes. Inverted corners are swapped, a degenerate
    /// (flat or point) box gets a size relative to its position, and non-finite input
    /// frames the unit box.
    pub fn frame(min: [f64; 3], max: [f64; 3]) -> Camera {
        let (lo, hi) = match (finite_vec(min), finite_vec(max)) {
            (Some(a), Some(b)) => (a.min(b), a.max(b)),
            _ => (DVec3::ZERO, DVec3::ONE),
        };
        // Halves first and lengths of scaled vectors: boxes far out (coordinates beyond
        // 1e154, whose squares overflow) frame as boxes near the origin do.
        let centre = 0.5 * lo + 0.5 * hi;
        // Bounding-sphere radius; a flat or point box still gets a visible extent that
        // is representable next to its (possibly huge) coordinates.
        let floor = (centre.abs().max_element() * 1e-9).max(1e-6);
        let half_size = 0.5 * hi - 0.5 * lo;
        let mut radius = half_size.length();
        if !radius.is_finite() {
            let scale = half_size.abs().max_element();
            radius = scale * (half_size / scale).length();
        }
        let radius = radius.max(floor);
        let dir = DVec3::new(1.0, -1.6, 0.9).normalize();
        let mut cam = Camera {
            eye: (centre + radius * dir).to_array(),
            look_at: centre.to_array(),
            up: [0.0, 0.0, 1.0],
            projection: Projection::Perspective {
                fov_deg: DEFAULT_FOV_DEG,
            },
        };
        // Nearest distance at which every corner projects inside the vertical field of
        // view on both image axes (a square image; wider images only gain room), plus
        // 5 % margin. Tighter than the bounding sphere for elongated boxes.
        let b = cam.basis();
        let tan_half = (0.5 * DEFAULT_FOV_DEG.to_radians()).tan();
        let half = half_size.max(DVec3::splat(0.5 * floor));
        let mut distance = 0.0f64;
        for i in 0..8 {
            let q = DVec3::new(
                if i & 1 == 0 { -half.x } else { half.x },
                if i & 2 == 0 { -half.y } else { half.y },
                if i & 4 == 0 { -half.z } else { half.z },
            );
            let (x, y, z) = (q.dot(b.right), q.dot(b.up), q.dot(b.forward));
            distance = distance.max((x.abs().max(y.abs()) / tan_half) - z);
        }
        let distance = 1.05 * distance.max(radius);
        cam.eye = (centre + distance * dir).to_array();
        cam
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A point projected and cast back lies on the ray through its pixel, at `t`.
    #[test]
    fn projection_inverts_the_camera_rays() {
        for projection in [
            Projection::Perspective { fov_deg: 40.0 },
            Projection::Orthographic { width: 3.0 },
        ] {
            let cam = Camera {
                eye: [3.0, -4.0, 2.0],
                look_at: [0.5, 0.2, -0.1],
                up: [0.0, 0.0, 1.0],
                projection,
            };
            let rays = cam.ray_generator(320, 200);
            for p in [[0.5, 0.2, -0.1], [1.0, -1.0, 0.3], [-0.7, 0.9, 0.8]] {
                let (x, y, t) = rays.project(p).expect("in front");
                let r = rays.ray(x, y);
                let q = r.at(t);
                assert!(
                    (q - DVec3::from_array(p)).length() < 1e-9,
                    "{projection:?} {p:?}"
                );
            }
            // The look-at point is the image centre.
            let (x, y, _) = rays.project(cam.look_at).expect("in front");
            assert!((x - 160.0).abs() < 1e-9 && (y - 100.0).abs() < 1e-9);
            // Behind the eye: nothing.
            assert!(rays.project([6.0, -8.0, 4.0]).is_none());
        }
    }

    fn persp(eye: [f64; 3], look_at: [f64; 3], up: [f64; 3], fov: f64) -> Camera {
        Camera {
            eye,
            look_at,
            up,
            projection: Projection::Perspective { fov_deg: fov },
        }
    }

    fn close(a: DVec3, b: DVec3, tol: f64) -> bool {
        (a - b).length() <= tol
    }

    #[test]
    fn centre_pixel_ray_points_at_look_at() {
        let cam = persp([1.0, 2.0, 3.0], [4.0, -2.0, 3.5], [0.0, 0.0, 1.0], 50.0);
        // 101×51: the centre of pixel (50, 25) is the image centre.
        let r = cam.ray(50.5, 25.5, 101, 51);
        let want = (DVec3::new(4.0, -2.0, 3.5) - DVec3::new(1.0, 2.0, 3.0)).normalize();
        assert!(close(r.dir, want, 1e-12), "{:?} vs {want:?}", r.dir);
        assert_eq!(r.origin, DVec3::new(1.0, 2.0, 3.0));
        assert!((r.dir.length() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn perspective_corner_rays_span_the_field_of_view() {
        // Camera on +z looking down −z, up +y: image x = world x, image y = world y.
        let cam = persp([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 90.0);
        let (w, h) = (200, 100);
        // Top edge middle: angle of half the vertical fov (45°) above the axis.
        let top = cam.ray(100.0, 0.0, w, h);
        assert!(close(
            top.dir,
            DVec3::new(0.0, 1.0, -1.0).normalize(),
            1e-12
        ));
        // Left edge middle: tan(half horizontal fov) = aspect · tan(45°) = 2.
        let left = cam.ray(0.0, 50.0, w, h);
        assert!(close(
            left.dir,
            DVec3::new(-2.0, 0.0, -1.0).normalize(),
            1e-12
        ));
        // Pixel (0,0) centre hits the plane z=0 at the expected spot: x = -2·5·(1 - 1/200).
        let r = cam.ray(0.5, 0.5, w, h);
        let t = -r.origin.z / r.dir.z;
        let p = r.at(t);
        assert!((p.x - (-10.0 * (1.0 - 0.5 / 100.0))).abs() < 1e-9, "{p:?}");
        assert!((p.y - (5.0 * (1.0 - 0.5 / 50.0))).abs() < 1e-9, "{p:?}");
    }

    #[test]
    fn orthographic_rays_are_parallel_and_offset_through_pixel_centres() {
        let cam = Camera {
            eye: [0.0, 0.0, 10.0],
            look_at: [0.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            projection: Projection::Orthographic { width: 4.0 },
        };
        let (w, h) = (4, 2);
        for py in 0..h {
            for px in 0..w {
                let r = cam.ray(f64::from(px) + 0.5, f64::from(py) + 0.5, w, h);
                assert!(close(r.dir, DVec3::NEG_Z, 1e-15));
                // Each pixel is 1 world unit wide; centres at x = -1.5, -0.5, 0.5, 1.5
                // and y = 0.5, -0.5 (image height = 4 / aspect 2 = 2).
                let want = DVec3::new(f64::from(px) - 1.5, 0.5 - f64::from(py), 10.0);
                assert!(close(r.origin, want, 1e-12), "{:?} vs {want:?}", r.origin);
            }
        }
    }

    #[test]
    fn degenerate_poses_give_finite_orthonormal_bases() {
        let cams = [
            // up parallel to the view direction
            persp([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 40.0),
            persp([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 0.0, -3.0], 40.0),
            // eye on the look-at point
            persp([1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [0.0, 1.0, 0.0], 40.0),
            // zero up, NaN eye, silly fov
            persp([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.0),
            persp(
                [f64::NAN, 0.0, 5.0],
                [0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                400.0,
            ),
        ];
        for cam in cams {
            let b = cam.basis();
            for (a, c) in [(b.forward, b.right), (b.forward, b.up), (b.right, b.up)] {
                assert!(a.dot(c).abs() < 1e-12, "{cam:?}");
            }
            for v in [b.forward, b.right, b.up] {
                assert!((v.length() - 1.0).abs() < 1e-12, "{cam:?}");
            }
            let r = cam.ray(3.5, 7.5, 16, 16);
            assert!(r.origin.is_finite() && r.dir.is_finite(), "{cam:?}");
        }
    }

    #[test]
    fn frame_sees_the_whole_box() {
        let boxes: [([f64; 3], [f64; 3]); 5] = [
            ([-1.0, -2.0, -0.5], [3.0, 2.0, 0.5]),
            // huge offset
            ([1e6, 1e6, 1e6], [1e6 + 1.0, 1e6 + 2.0, 1e6 + 0.5]),
            // flat, point and inverted boxes
            ([0.0, 0.0, 0.0], [1.0, 1.0, 0.0]),
            ([2.0, 2.0, 2.0], [2.0, 2.0, 2.0]),
            ([1.0, 1.0, 1.0], [0.0, 0.0, 0.0]),
        ];
        for (lo, hi) in boxes {
            let cam = Camera::frame(lo, hi);
            let b = cam.basis();
            let eye = DVec3::from_array(cam.eye);
            let half = (0.5 * DEFAULT_FOV_DEG.to_radians()).tan();
            // Every box corner projects inside the (square) image and in front of the eye.
            for i in 0..8 {
                let c = DVec3::new(
                    if i & 1 == 0 { lo[0] } else { hi[0] },
                    if i & 2 == 0 { lo[1] } else { hi[1] },
                    if i & 4 == 0 { lo[2] } else { hi[2] },
                );
                let d = c - eye;
                let z = d.dot(b.forward);
                assert!(z > 0.0, "corner behind the eye for {lo:?}..{hi:?}");
                assert!((d.dot(b.right) / z).abs() <= half, "{lo:?}..{hi:?}");
                assert!((d.dot(b.up) / z).abs() <= half, "{lo:?}..{hi:?}");
            }
            // Oblique: not along a coordinate axis, and the centre pixel looks at the centre.
            assert!(b.forward.abs().max_element() < 0.9);
            let r = cam.ray(32.0, 32.0, 64, 64);
            assert!(close(r.dir, b.forward, 1e-12));
        }
    }

    #[test]
    fn frame_of_non_finite_box_is_usable() {
        let cam = Camera::frame([f64::NAN; 3], [f64::INFINITY; 3]);
        let r = cam.ray(1.0, 1.0, 2, 2);
        assert!(r.origin.is_finite() && r.dir.is_finite());
    }

    #[test]
    fn serde_round_trip() {
        let cam = Camera::frame([0.0; 3], [1.0; 3]);
        let s = serde_json::to_string(&cam).expect("serialize");
        let back: Camera = serde_json::from_str(&s).expect("deserialize");
        assert_eq!(cam, back);
        let ortho = Camera {
            projection: Projection::Orthographic { width: 3.0 },
            ..cam
        };
        let s = serde_json::to_string(&ortho).expect("serialize");
        assert!(s.contains("\"orthographic\""), "{s}");
        assert_eq!(
            ortho,
            serde_json::from_str::<Camera>(&s).expect("deserialize")
        );
    }

    /// A group's frustum holds a small box around every point of every ray through its
    /// rectangle (corners and random offsets, both projections), rejects boxes beside,
    /// behind the side planes and far off, and takes a non-finite box as "may meet".
    #[test]
    fn a_frustum_holds_its_rays_and_rejects_boxes_beside_them() {
        let mut seed = 3u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for projection in [
            Projection::Perspective { fov_deg: 40.0 },
            Projection::Orthographic { width: 6.0 },
        ] {
            let cam = Camera {
                eye: [1e3 + 5.0, -3.0, 4.0],
                look_at: [1e3, 0.5, 0.0],
                up: [0.0, 0.0, 1.0],
                projection,
            };
            let rays = cam.ray_generator(64, 48);
            let frame = DVec3::new(1e3, 0.0, 0.0);
            let (x0, y0, x1, y1) = (20.0, 12.0, 24.0, 16.0);
            let fr = rays.frustum(x0, y0, x1, y1, frame);
            let mut points = vec![(x0, y0), (x1, y0), (x0, y1), (x1, y1)];
            for _ in 0..200 {
                points.push((x0 + 4.0 * rnd(), y0 + 4.0 * rnd()));
            }
            for (x, y) in points {
                let ray = rays.ray(x, y);
                let t = 20.0 * rnd();
                let p = (ray.at(t) - frame).to_array();
                let tiny = p.map(|v| v + 1e-12);
                assert!(
                    fr.may_meet(&p, &tiny),
                    "{projection:?}: ray ({x}, {y}) at t {t}"
                );
            }
            // A box on the ray through the centre of the next group to the right, or
            // below, lies outside.
            for (x, y) in [(x1 + 2.0, 0.5 * (y0 + y1)), (0.5 * (x0 + x1), y1 + 2.0)] {
                let p = (rays.ray(x, y).at(8.0) - frame).to_array();
                let q = p.map(|v| v + 0.05);
                assert!(!fr.may_meet(&p, &q), "{projection:?}: box at ({x}, {y})");
            }
            assert!(fr.may_meet(&[f64::NAN; 3], &[f64::NAN; 3]));
        }
    }
}
