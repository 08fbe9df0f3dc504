//! What a view state may hold beyond what its JSON types allow, checked once
//! ([`ViewState::validate`]) wherever a state comes in: a file, the window, the flags.

use super::{
    ViewState, MAX_IMAGE_SIDE, MAX_ISO_SURFACES, MAX_LIGHTS, MAX_MESHES, MAX_SPP, MIN_STEP,
};
use crate::camera::Projection;
use crate::colormap::ColorMapError;
use crate::mesh::MeshError;
use crate::planes::{PlaneError, MAX_CLIP_PLANES, MAX_SLICES};
use crate::shading::ShadingError;

/// What [`ViewState::validate`] refuses: a value the JSON types allow but the renderer
/// cannot use. The message names the field by its JSON path.
#[derive(Debug, thiserror::Error)]
pub enum InvalidViewState {
    /// `eye`, `look_at` or `up` of the camera.
    #[error("camera.{name}: not finite ({value:?})")]
    CameraNotFinite { name: &'static str, value: [f64; 3] },
    #[error("camera: eye and look_at are the same point")]
    EyeAtLookAt,
    #[error(
        "camera.up: {up:?} is zero or parallel to the view direction (eye → look_at), \
         which leaves the image's roll undefined"
    )]
    UpAlongView { up: [f64; 3] },
    #[error("camera.projection.fov_deg: expected 0 < fov < 179, found {fov_deg}")]
    FieldOfView { fov_deg: f64 },
    #[error("camera.projection.width: expected a finite number > 0, found {width}")]
    OrthographicWidth { width: f64 },
    #[error("iso: not finite ({iso})")]
    Iso { iso: f64 },
    #[error("step: expected a finite number ≥ {MIN_STEP} (cell widths), found {step:?}")]
    Step { step: f64 },
    #[error("spp: expected 1..={MAX_SPP}, found {spp}")]
    Spp { spp: u32 },
    /// `transfer.sigma`, `transfer.peak_opacity` or `transfer.k`.
    #[error("{name}: expected a finite number > 0, found {value}")]
    Transfer { name: &'static str, value: f64 },
    #[error("colormap.{0}")]
    ColorMap(ColorMapError),
    #[error("lights: expected at most {MAX_LIGHTS} entries, found {count}")]
    TooManyLights { count: usize },
    #[error("lights[{index}].{error}")]
    Light { index: usize, error: ShadingError },
    #[error("material.{0}")]
    Material(ShadingError),
    #[error("meshes: expected at most {MAX_MESHES} entries, found {count}")]
    TooManyMeshes { count: usize },
    #[error("meshes[{index}]: {error}")]
    Mesh { index: usize, error: MeshError },
    #[error("background: expected components in 0..=1, found {background:?}")]
    Background { background: [f32; 3] },
    #[error("more_isos: expected at most {} entries (with `iso`, {MAX_ISO_SURFACES} surfaces), found {count}", MAX_ISO_SURFACES - 1)]
    TooManySurfaces { count: usize },
    /// `iso_opacity`, `more_isos[i].value` or `more_isos[i].opacity`: `name` is the path.
    #[error("{name}: expected {expected}, found {value}")]
    Surface {
        name: String,
        expected: &'static str,
        value: f64,
    },
    /// `iso_colour` or `more_isos[i].colour`.
    #[error("{name}: expected components in 0..=1, found {colour:?}")]
    SurfaceColour { name: String, colour: [f32; 3] },
    #[error("clip: expected at most {MAX_CLIP_PLANES} planes, found {count}")]
    TooManyClipPlanes { count: usize },
    #[error("slices: expected at most {MAX_SLICES} planes, found {count}")]
    TooManySlices { count: usize },
    /// `clip[i]` or `slices[i]`.
    #[error("{name}: {error}")]
    Plane { name: String, error: PlaneError },
    #[error("slices[{index}].opacity: expected 0 < opacity ≤ 1, found {value}")]
    SliceOpacity { index: usize, value: f64 },
    /// `width` or `height`.
    #[error("{name}: expected 1..={MAX_IMAGE_SIDE}, found {value}")]
    ImageSide { name: &'static str, value: u32 },
}

impl ViewState {
    /// Checks what the JSON types cannot.
    pub fn validate(&self) -> Result<(), InvalidViewState> {
        let c = &self.camera;
        for (name, value) in [("eye", c.eye), ("look_at", c.look_at), ("up", c.up)] {
            if value.iter().any(|x| !x.is_finite()) {
                return Err(InvalidViewState::CameraNotFinite { name, value });
            }
        }
        if c.eye == c.look_at {
            return Err(InvalidViewState::EyeAtLookAt);
        }
        // An up vector along the view direction leaves the image's roll undefined; the
        // camera would silently pick a world axis instead.
        // Both vectors scaled to a largest component of 1 first (the direction is halved
        // before the subtraction), so that cameras far out (coordinates beyond 1e154,
        // whose squares overflow) are judged by their direction, not by infinities.
        let unit = |v: [f64; 3]| {
            let m = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            if m > 0.0 {
                v.map(|x| x / m)
            } else {
                v
            }
        };
        let forward = unit(std::array::from_fn(|a| 0.5 * c.look_at[a] - 0.5 * c.eye[a]));
        let up = unit(c.up);
        let cross = [
            forward[1] * up[2] - forward[2] * up[1],
            forward[2] * up[0] - forward[0] * up[2],
            forward[0] * up[1] - forward[1] * up[0],
        ];
        let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let sine_ok = norm(cross) > 1e-9 * norm(forward) * norm(up);
        if !sine_ok {
            return Err(InvalidViewState::UpAlongView { up: c.up });
        }
        match c.projection {
            Projection::Perspective { fov_deg } if !(fov_deg > 0.0 && fov_deg < 179.0) => {
                return Err(InvalidViewState::FieldOfView { fov_deg })
            }
            Projection::Orthographic { width } if !(width > 0.0 && width.is_finite()) => {
                return Err(InvalidViewState::OrthographicWidth { width })
            }
            _ => {}
        }
        if !self.iso.is_finite() {
            return Err(InvalidViewState::Iso { iso: self.iso });
        }
        if !(self.step.is_finite() && self.step >= MIN_STEP) {
            return Err(InvalidViewState::Step { step: self.step });
        }
        if !(1..=MAX_SPP).contains(&self.spp) {
            return Err(InvalidViewState::Spp { spp: self.spp });
        }
        for (name, value) in [
            ("transfer.sigma", self.transfer.sigma),
            ("transfer.peak_opacity", self.transfer.peak_opacity),
            ("transfer.k", self.transfer.k),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(InvalidViewState::Transfer { name, value });
            }
        }
        self.colormap
            .validate()
            .map_err(InvalidViewState::ColorMap)?;
        if self.lights.len() > MAX_LIGHTS {
            return Err(InvalidViewState::TooManyLights {
                count: self.lights.len(),
            });
        }
        for (index, l) in self.lights.iter().enumerate() {
            l.validate()
                .map_err(|error| InvalidViewState::Light { index, error })?;
        }
        self.material
            .validate()
            .map_err(InvalidViewState::Material)?;
        if self.meshes.len() > MAX_MESHES {
            return Err(InvalidViewState::TooManyMeshes {
                count: self.meshes.len(),
            });
        }
        for (index, m) in self.meshes.iter().enumerate() {
            m.validate()
                .map_err(|error| InvalidViewState::Mesh { index, error })?;
        }
        if self.background.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return Err(InvalidViewState::Background {
                background: self.background,
            });
        }
        self.validate_cuts()?;
        for (name, value) in [("width", self.width), ("height", self.height)] {
            if !(1..=MAX_IMAGE_SIDE).contains(&value) {
                return Err(InvalidViewState::ImageSide { name, value });
            }
        }
        Ok(())
    }
}

impl ViewState {
    /// The surfaces, clip and slice planes: counts, finite values, opacities in (0, 1].
    fn validate_cuts(&self) -> Result<(), InvalidViewState> {
        if self.more_isos.len() + 1 > MAX_ISO_SURFACES {
            return Err(InvalidViewState::TooManySurfaces {
                count: self.more_isos.len(),
            });
        }
        let styles = std::iter::once((
            "iso_".to_string(),
            self.iso,
            self.iso_opacity,
            self.iso_colour,
        ))
        .chain(
            self.more_isos
                .iter()
                .enumerate()
                .map(|(i, s)| (format!("more_isos[{i}]."), s.value, s.opacity, s.colour)),
        );
        for (path, value, opacity, colour) in styles {
            if !value.is_finite() {
                return Err(InvalidViewState::Surface {
                    name: format!("{path}value").replace("iso_value", "iso"),
                    expected: "a finite number",
                    value,
                });
            }
            if !(opacity > 0.0 && opacity <= 1.0) {
                return Err(InvalidViewState::Surface {
                    name: format!("{path}opacity"),
                    expected: "0 < opacity ≤ 1",
                    value: opacity,
                });
            }
            if let Some(c) = colour {
                if c.iter().any(|x| !(0.0..=1.0).contains(x)) {
                    return Err(InvalidViewState::SurfaceColour {
                        name: format!("{path}colour"),
                        colour: c,
                    });
                }
            }
        }
        if self.clip.len() > MAX_CLIP_PLANES {
            return Err(InvalidViewState::TooManyClipPlanes {
                count: self.clip.len(),
            });
        }
        if self.slices.len() > MAX_SLICES {
            return Err(InvalidViewState::TooManySlices {
                count: self.slices.len(),
            });
        }
        for (i, p) in self.clip.iter().enumerate() {
            p.check().map_err(|error| InvalidViewState::Plane {
                name: format!("clip[{i}]"),
                error,
            })?;
        }
        for (index, s) in self.slices.iter().enumerate() {
            s.plane.check().map_err(|error| InvalidViewState::Plane {
                name: format!("slices[{index}]"),
                error,
            })?;
            if !(s.opacity > 0.0 && s.opacity <= 1.0) {
                return Err(InvalidViewState::SliceOpacity {
                    index,
                    value: s.opacity,
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshInstance;
    use crate::shading::Light;
    use crate::view_state::tests::fields;
    use crate::view_state::ViewStateError;
    use std::path::Path;

    #[test]
    fn invalid_values_are_rejected_with_their_name() {
        use InvalidViewState as I;
        let s = ViewState::default_for([0.0; 3], [1.0; 3], &fields());
        type Change = Box<dyn Fn(&mut ViewState)>;
        type Check = fn(&InvalidViewState) -> bool;
        let cases: Vec<(&str, Change, Check)> = vec![
            ("width", Box::new(|s| s.width = 0), |e| {
                matches!(
                    e,
                    I::ImageSide {
                        name: "width",
                        value: 0
                    }
                )
            }),
            ("height", Box::new(|s| s.height = 100_000), |e| {
                matches!(e, I::ImageSide { name: "height", .. })
            }),
            ("step", Box::new(|s| s.step = -1.0), |e| {
                matches!(e, I::Step { .. })
            }),
            ("step", Box::new(|s| s.step = 1e-30), |e| {
                matches!(e, I::Step { .. })
            }),
            (
                "camera.up",
                Box::new(|s| {
                    s.camera.up = std::array::from_fn(|a| s.camera.look_at[a] - s.camera.eye[a])
                }),
                |e| matches!(e, I::UpAlongView { .. }),
            ),
            ("camera.up", Box::new(|s| s.camera.up = [0.0; 3]), |e| {
                matches!(
                    e,
                    I::UpAlongView {
                        up: [0.0, 0.0, 0.0]
                    }
                )
            }),
            (
                "colormap.points",
                Box::new(|s| s.colormap.points.clear()),
                |e| matches!(e, I::ColorMap(ColorMapError::NoPoints)),
            ),
            (
                "lights: expected at most 64",
                Box::new(|s| s.lights = vec![s.lights[0]; MAX_LIGHTS + 1]),
                |e| matches!(e, I::TooManyLights { count } if *count == MAX_LIGHTS + 1),
            ),
            (
                "meshes: expected at most 64",
                Box::new(|s| s.meshes = vec![MeshInstance::at_origin("a.obj"); MAX_MESHES + 1]),
                |e| matches!(e, I::TooManyMeshes { count } if *count == MAX_MESHES + 1),
            ),
            ("spp", Box::new(|s| s.spp = 0), |e| {
                matches!(e, I::Spp { spp: 0 })
            }),
            (
                "transfer.sigma",
                Box::new(|s| s.transfer.sigma = 0.0),
                |e| {
                    matches!(
                        e,
                        I::Transfer {
                            name: "transfer.sigma",
                            ..
                        }
                    )
                },
            ),
            ("colormap.band", Box::new(|s| s.colormap.band = -1.0), |e| {
                matches!(e, I::ColorMap(ColorMapError::Band { .. }))
            }),
            (
                "camera.projection.fov_deg",
                Box::new(|s| s.camera.projection = Projection::Perspective { fov_deg: 200.0 }),
                |e| matches!(e, I::FieldOfView { .. }),
            ),
            (
                "meshes[0]",
                Box::new(|s| {
                    let mut m = MeshInstance::at_origin("a.obj");
                    m.scale = -1.0;
                    s.meshes.push(m);
                }),
                |e| matches!(e, I::Mesh { index: 0, .. }),
            ),
            (
                "lights[0].intensity",
                Box::new(|s| {
                    if let Some(Light::Directional { intensity, .. }) = s.lights.first_mut() {
                        *intensity = -1.0;
                    }
                }),
                |e| {
                    matches!(
                        e,
                        I::Light {
                            index: 0,
                            error: ShadingError::Intensity { .. }
                        }
                    )
                },
            ),
        ];
        for (name, change, check) in cases {
            let mut bad = s.clone();
            change(&mut bad);
            let e = ViewState::from_json(Path::new("v.json"), &bad.to_json()).expect_err(name);
            let ViewStateError::Invalid { error, .. } = &e else {
                panic!("{name}: not an invalid value: {e}");
            };
            assert!(check(error), "{name}: {error:?}");
            // The message names the field by its JSON path.
            assert!(e.to_string().contains(name), "{name}: {e}");
        }
        assert_eq!(
            I::ColorMap(ColorMapError::Unsorted {
                index: 2,
                value: 0.5,
                previous: 1.0
            })
            .to_string(),
            "colormap.points[2].value 0.5 is below points[1].value 1: points must be sorted"
        );
        let e = ViewState::load(Path::new("/nonexistent/v.json")).expect_err("missing");
        assert!(e.to_string().contains("/nonexistent/v.json"), "{e}");
    }

    /// Issue 27: surfaces and planes a state file may hold but the renderer cannot use
    /// are refused, named by their JSON path.
    #[test]
    fn bad_surfaces_and_planes_are_named() {
        use crate::planes::{Plane, Slice};
        use crate::view_state::IsoSurface;
        let base = ViewState::default_for([0.0; 3], [1.0; 3], &super::super::tests::fields());
        let plane = Plane {
            origin: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
        };
        let surface = IsoSurface {
            value: 0.1,
            opacity: 0.5,
            colour: None,
        };
        type Change = Box<dyn Fn(&mut ViewState)>;
        let cases: Vec<(Change, &str)> = vec![
            (Box::new(|s| s.iso_opacity = 0.0), "iso_opacity"),
            (
                Box::new(|s| s.iso_colour = Some([2.0, 0.0, 0.0])),
                "iso_colour",
            ),
            (
                Box::new(move |s| s.more_isos = vec![surface; 8]),
                "more_isos: expected at most 7",
            ),
            (
                Box::new(move |s| {
                    s.more_isos = vec![IsoSurface {
                        value: f64::NAN,
                        ..surface
                    }]
                }),
                "more_isos[0].value",
            ),
            (
                Box::new(move |s| s.clip = vec![plane; 7]),
                "clip: expected at most 6",
            ),
            (
                Box::new(move |s| {
                    s.clip = vec![
                        plane,
                        Plane {
                            normal: [0.0; 3],
                            ..plane
                        },
                    ]
                }),
                "clip[1]: the normal",
            ),
            (
                Box::new(move |s| s.slices = vec![Slice::new(plane); 4]),
                "slices: expected at most 3",
            ),
            (
                Box::new(move |s| {
                    s.slices = vec![Slice {
                        opacity: 0.0,
                        ..Slice::new(plane)
                    }]
                }),
                "slices[0].opacity",
            ),
        ];
        for (change, want) in cases {
            let mut s = base.clone();
            change(&mut s);
            let e = s.validate().expect_err(want).to_string();
            assert!(e.starts_with(want), "{want}: {e}");
        }
    }
}
