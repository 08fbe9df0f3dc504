//! Lights, Phong shading, and where shading normals come from.
//!
//! Energy: with `ambient + diffuse + specular ≤ 1`, base colours and light colours in
//! 0..=1 and light intensities summing to at most 1, [`phong`] stays in 0..=1 per channel.
//! The defaults of new views ([`default_lights`], [`Material::new_view`]) go past 1 on
//! purpose, as an exposure: a surface facing the camera in a saturated base colour then
//! reaches about 1.1 times that colour, and the film clamps highlights to white.

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

use crate::camera::Camera;

/// Which gradient gives the shading normal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Shading {
    /// Central differences of the reconstruction over one local cell width: continuous
    /// across cell faces and level boundaries ([`crate::volume::Volume::shading_gradient`]).
    #[default]
    Smooth,
    /// The analytic gradient of the reconstruction (piecewise, facets at cell faces).
    Analytic,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Light {
    /// Light travelling along `direction` (world units, need not be normalised).
    Directional {
        direction: [f64; 3],
        colour: [f32; 3],
        intensity: f32,
    },
    /// Light from a point (no fall-off with distance).
    Point {
        position: [f64; 3],
        colour: [f32; 3],
        intensity: f32,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    pub shininess: f32,
}

impl Material {
    /// The material of new views ([`crate::view_state::ViewState::default_for`]): more
    /// diffuse and ambient light than [`Material::default`], so that with
    /// [`default_lights`] the median lit surface reaches a luma of about 100 on the
    /// default colour map (issue 26). `Default` stays what state files without a
    /// `material` read, so they render as before.
    pub fn new_view() -> Material {
        Material {
            ambient: 0.2,
            diffuse: 0.8,
            specular: 0.25,
            shininess: 32.0,
        }
    }
}

impl Default for Material {
    /// The coefficients of states saved before issue 26 (and without a `material`).
    fn default() -> Self {
        Material {
            ambient: 0.15,
            diffuse: 0.65,
            specular: 0.2,
            shininess: 32.0,
        }
    }
}

/// Why a light or a material is refused. The message names the field, so a view state's
/// error can prefix where the light or material sits (`lights[1].`, `material.`).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ShadingError {
    /// A material coefficient (`ambient`, `diffuse`, `specular`, `shininess`).
    #[error("{name}: expected a finite number ≥ 0, found {value}")]
    Coefficient { name: &'static str, value: f32 },
    /// A light's `direction` or `position`.
    #[error("{name}: not finite ({value:?})")]
    NotFinite { name: &'static str, value: [f64; 3] },
    /// A directional light needs a direction to shine along.
    #[error("direction: expected a non-zero vector, found [0, 0, 0]")]
    ZeroDirection,
    #[error("colour: expected components ≥ 0, found {colour:?}")]
    Colour { colour: [f32; 3] },
    #[error("intensity: expected a finite number ≥ 0, found {intensity}")]
    Intensity { intensity: f32 },
}

impl Material {
    /// Checks finite, non-negative coefficients.
    pub(crate) fn validate(&self) -> Result<(), ShadingError> {
        for (name, v) in [
            ("ambient", self.ambient),
            ("diffuse", self.diffuse),
            ("specular", self.specular),
            ("shininess", self.shininess),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ShadingError::Coefficient { name, value: v });
            }
        }
        Ok(())
    }
}

impl Light {
    /// Unit direction from `p` towards the light, and the distance to it (∞ for directional).
    ///
    /// A zero direction (or a point light at `p`) gives +z at distance 0 for a point
    /// light and ∞ for a directional one, so callers never see NaN.
    pub(crate) fn towards(&self, p: DVec3) -> (DVec3, f64) {
        match *self {
            Light::Directional { direction, .. } => (
                (-DVec3::from_array(direction))
                    .try_normalize()
                    .unwrap_or(DVec3::Z),
                f64::INFINITY,
            ),
            Light::Point { position, .. } => {
                let d = DVec3::from_array(position) - p;
                let len = d.length();
                if len > 0.0 && len.is_finite() {
                    (d / len, len)
                } else {
                    (DVec3::Z, 0.0)
                }
            }
        }
    }

    /// Light colour times intensity.
    pub(crate) fn radiance(&self) -> Vec3 {
        match *self {
            Light::Directional {
                colour, intensity, ..
            }
            | Light::Point {
                colour, intensity, ..
            } => Vec3::from_array(colour) * intensity,
        }
    }

    /// Checks finite numbers, a non-zero direction and non-negative colour/intensity.
    pub(crate) fn validate(&self) -> Result<(), ShadingError> {
        let (v, name, colour, intensity) = match *self {
            Light::Directional {
                direction,
                colour,
                intensity,
            } => (direction, "direction", colour, intensity),
            Light::Point {
                position,
                colour,
                intensity,
            } => (position, "position", colour, intensity),
        };
        if v.iter().any(|x| !x.is_finite()) {
            return Err(ShadingError::NotFinite { name, value: v });
        }
        if name == "direction" && v.iter().all(|x| *x == 0.0) {
            return Err(ShadingError::ZeroDirection);
        }
        if colour.iter().any(|c| !(c.is_finite() && *c >= 0.0)) {
            return Err(ShadingError::Colour { colour });
        }
        if !(intensity.is_finite() && intensity >= 0.0) {
            return Err(ShadingError::Intensity { intensity });
        }
        Ok(())
    }
}

/// Key light of [`default_lights`]: the camera's own direction (a headlight).
pub const KEY_INTENSITY: f32 = 0.85;
/// Fill light of [`default_lights`], and its azimuth and elevation in degrees relative
/// to the camera (azimuth from behind the viewer towards the right, elevation up).
pub const FILL_INTENSITY: f32 = 0.35;
pub const FILL_DIR_DEG: [f64; 2] = [40.0, 35.0];

/// Two white directional lights fixed to the camera's pose: a key light at the camera
/// (a headlight, [`KEY_INTENSITY`]) and a fill from above-right behind the viewer
/// ([`FILL_INTENSITY`], at [`FILL_DIR_DEG`]) that models the shape. Issue 26: the earlier
/// rig put its key light over the shoulder, so undersides and surfaces turned away from
/// it got ambient light only and the median lit surface came out at a luma of 53–65;
/// with the key at the camera every surface the camera sees faces it. Together with
/// [`Material::new_view`] they make surfaces bright on dark and light backgrounds.
/// Stored in world coordinates, so they stay put when the camera later moves.
pub fn default_lights(camera: &Camera) -> Vec<Light> {
    let b = camera.basis();
    let fill = towards(&b, FILL_DIR_DEG);
    let white = [1.0, 1.0, 1.0];
    vec![
        Light::Directional {
            direction: b.forward.to_array(),
            colour: white,
            intensity: KEY_INTENSITY,
        },
        Light::Directional {
            direction: (-fill).to_array(),
            colour: white,
            intensity: FILL_INTENSITY,
        },
    ]
}

/// Unit direction towards a light at `[azimuth, elevation]` degrees in the camera frame
/// of `b`: azimuth 0 is the camera's own direction (behind the viewer), positive to the
/// right; elevation positive up.
pub(crate) fn towards(b: &crate::camera::Basis, dir_deg: [f64; 2]) -> DVec3 {
    let [az, el] = dir_deg.map(f64::to_radians);
    el.cos() * (az.cos() * -b.forward + az.sin() * b.right) + el.sin() * b.up
}

/// Phong shading of a surface point with unit `normal` (flipped to face the viewer),
/// `view` the unit direction from the point to the eye, `visibility[i]` the shadow
/// transmittance towards light `i` (1 = unshadowed; missing entries count as 1).
///
/// `ambient·base + Σ visᵢ·Lᵢ·(diffuse·base·max(0, n·l) + specular·max(0, r·v)^shininess)`
/// with `r` the reflection of `l` about `n`; lights behind the surface contribute nothing.
pub(crate) fn phong(
    base: Vec3,
    normal: DVec3,
    view: DVec3,
    p: DVec3,
    lights: &[Light],
    visibility: &[f32],
    material: &Material,
) -> Vec3 {
    let mut c = base * material.ambient;
    for (i, light) in lights.iter().enumerate() {
        let vis = visibility.get(i).copied().unwrap_or(1.0).clamp(0.0, 1.0);
        if vis <= 0.0 {
            continue;
        }
        let (l, _) = light.towards(p);
        let n_dot_l = normal.dot(l);
        if n_dot_l <= 0.0 || !n_dot_l.is_finite() {
            continue;
        }
        let r = 2.0 * n_dot_l * normal - l;
        let r_dot_v = r.dot(view).max(0.0);
        let spec = if r_dot_v > 0.0 {
            (r_dot_v as f32).powf(material.shininess)
        } else {
            0.0
        };
        let term =
            base * (material.diffuse * n_dot_l as f32) + Vec3::splat(material.specular * spec);
        c += light.radiance() * vis * term;
    }
    c.max(Vec3::ZERO)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn dir_light(d: [f64; 3], intensity: f32) -> Light {
        Light::Directional {
            direction: d,
            colour: [1.0, 1.0, 1.0],
            intensity,
        }
    }

    #[test]
    fn towards_points_at_the_light() {
        let l = dir_light([0.0, 0.0, -2.0], 1.0);
        assert_eq!(l.towards(DVec3::ONE), (DVec3::Z, f64::INFINITY));
        let p = Light::Point {
            position: [1.0, 2.0, 5.0],
            colour: [1.0; 3],
            intensity: 1.0,
        };
        let (d, dist) = p.towards(DVec3::new(1.0, 2.0, 1.0));
        assert!((d - DVec3::Z).length() < 1e-15);
        assert!((dist - 4.0).abs() < 1e-15);
        let (d, dist) = p.towards(DVec3::new(1.0, 2.0, 5.0));
        assert!(d.is_finite() && dist == 0.0);
        let zero = dir_light([0.0; 3], 1.0);
        assert!(zero.towards(DVec3::ZERO).0.is_finite());
        assert_eq!(zero.validate(), Err(ShadingError::ZeroDirection));
    }

    #[test]
    fn head_on_light_gives_ambient_plus_diffuse_plus_specular() {
        let m = Material::default();
        let base = Vec3::new(0.2, 0.5, 0.8);
        // Light and viewer both along the normal: n·l = 1, r·v = 1.
        let c = phong(
            base,
            DVec3::Z,
            DVec3::Z,
            DVec3::ZERO,
            &[dir_light([0.0, 0.0, -1.0], 1.0)],
            &[1.0],
            &m,
        );
        let want = base * (m.ambient + m.diffuse) + Vec3::splat(m.specular);
        assert!((c - want).abs().max_element() < 1e-6, "{c:?} vs {want:?}");
        // Lambert: at 60° the diffuse term halves; specular vanishes (r·v = cos 120° < 0)
        // for a viewer on the other side.
        let l = DVec3::new(60f64.to_radians().sin(), 0.0, 60f64.to_radians().cos());
        let v = DVec3::new(-l.x, 0.0, l.z); // mirror direction: r == v
        let c2 = phong(
            base,
            DVec3::Z,
            v,
            DVec3::ZERO,
            &[dir_light((-l).to_array(), 1.0)],
            &[1.0],
            &m,
        );
        let want2 = base * (m.ambient + 0.5 * m.diffuse) + Vec3::splat(m.specular);
        assert!(
            (c2 - want2).abs().max_element() < 1e-5,
            "{c2:?} vs {want2:?}"
        );
    }

    #[test]
    fn shadowed_and_backlit_points_get_ambient_only() {
        let m = Material::default();
        let base = Vec3::new(0.3, 0.6, 0.9);
        let lights = [dir_light([0.0, 0.0, -1.0], 1.0)];
        let shadowed = phong(base, DVec3::Z, DVec3::Z, DVec3::ZERO, &lights, &[0.0], &m);
        assert!((shadowed - base * m.ambient).abs().max_element() < 1e-7);
        let backlit = phong(
            base,
            DVec3::NEG_Z,
            DVec3::NEG_Z,
            DVec3::ZERO,
            &lights,
            &[1.0],
            &m,
        );
        assert!((backlit - base * m.ambient).abs().max_element() < 1e-7);
    }

    #[test]
    fn default_lights_light_what_the_camera_sees() {
        let cam = Camera::frame([0.0; 3], [1.0; 3]);
        let lights = default_lights(&cam);
        // Issue 26: the key light is a headlight, so a surface facing the camera gets
        // its full intensity.
        let b = cam.basis();
        let key = lights[0];
        assert!(key.towards(DVec3::ZERO).0.dot(-b.forward) > 0.999);
        assert!(key.radiance().x >= 0.8);
        // Every surface the camera sees, however it is turned, gets direct light (the
        // headlight), so nothing visible is lit by the ambient term alone.
        for i in 0..200 {
            let a = f64::from(i) * 0.731;
            let tilt = 1.4 * (f64::from(i) / 200.0); // up to 80° away from the viewer
            let n = (-b.forward * tilt.cos() + (b.right * a.cos() + b.up * a.sin()) * tilt.sin())
                .normalize();
            let direct: f64 = lights
                .iter()
                .map(|l| {
                    let (to_light, _) = l.towards(DVec3::ZERO);
                    f64::from(l.radiance().x) * n.dot(to_light).max(0.0)
                })
                .sum();
            assert!(direct > 0.14, "normal {n} gets only {direct} direct light");
        }
        // A surface facing the camera is lit by both lights.
        let n = -cam.basis().forward;
        for l in &lights {
            assert!(l.towards(DVec3::ZERO).0.dot(n) > 0.3);
            assert!(l.validate().is_ok());
        }
        assert!(Material::default().validate().is_ok());
        assert!(Material::new_view().validate().is_ok());
    }

    fn unit() -> impl Strategy<Value = DVec3> {
        (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0)
            .prop_filter("non-zero", |(x, y, z)| x * x + y * y + z * z > 1e-3)
            .prop_map(|(x, y, z)| DVec3::new(x, y, z).normalize())
    }

    proptest! {
        #[test]
        fn energy_stays_in_bounds_and_grows_with_visibility(
            n in unit(), v in unit(), l1 in unit(), l2 in unit(),
            base in (0.0f32..=1.0, 0.0f32..=1.0, 0.0f32..=1.0),
            split in 0.0f32..=1.0, vis1 in 0.0f32..=1.0, vis2 in 0.0f32..=1.0,
            shin in 1.0f32..200.0,
        ) {
            let base = Vec3::new(base.0, base.1, base.2);
            let m = Material { shininess: shin, ..Material::default() };
            let lights = [dir_light(l1.to_array(), split), dir_light(l2.to_array(), 1.0 - split)];
            let c = phong(base, n, v, DVec3::ZERO, &lights, &[vis1, vis2], &m);
            let lit = phong(base, n, v, DVec3::ZERO, &lights, &[1.0, 1.0], &m);
            let dark = phong(base, n, v, DVec3::ZERO, &lights, &[0.0, 0.0], &m);
            prop_assert!(c.is_finite());
            prop_assert!(c.max_element() <= 1.0 + 1e-5, "{:?}", c);
            prop_assert!(c.min_element() >= 0.0);
            prop_assert!((dark - base * m.ambient).abs().max_element() < 1e-6);
            prop_assert!((c - dark).min_element() >= -1e-6);
            prop_assert!((lit - c).min_element() >= -1e-6);
        }
    }
}
