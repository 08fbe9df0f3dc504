//! Everything that determines a picture besides the data file: camera, mode, iso value,
//! sampling, transfer function, colour map, lights, meshes, resolution.
//!
//! Saved and loaded as JSON so a view set up in the GUI renders headless pixel for
//! pixel. Unknown fields are rejected (a typo must not silently fall back to a default);
//! values serde cannot check are checked by [`ViewState::validate`], which `load` calls.

use std::io::Write;
use std::path::{Path, PathBuf};

use files::input::{read_whole, InputErrorKind, Limits};
use serde::{Deserialize, Serialize};

use crate::camera::{Camera, Projection};
use crate::colormap::{ColorMap, ColorMapError};
use crate::mesh::{MeshError, MeshInstance};
pub use crate::sampling::Strategy;
use crate::shading::{default_lights, Light, Material, ShadingError};
pub use crate::transfer::{Band, Mode};

mod overrides;
pub use overrides::{OverrideError, Overrides, UnknownField};

/// Range of one field: of a file (from its field table), or of a whole sequence (from its
/// manifest), which is the same record.
pub use format::sequence::FieldRange;

/// Upper limit of `width`/`height`, so a state file cannot ask for an absurd allocation.
pub const MAX_IMAGE_SIDE: u32 = 16384;
/// Upper limit of `spp`.
pub const MAX_SPP: u32 = 4096;
/// Smallest `step` (in cell widths): a thousand samples per cell is twenty times finer than
/// the reference renders (0.01) and far below any visible difference, while a step like
/// `1e-30` made every ray march for ever (`t + dt == t`).
pub(crate) const MIN_STEP: f64 = 1e-3;

/// Why a `WxH` size argument is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{flag}: expected WxH with sides {min}..={MAX_IMAGE_SIDE}, found `{text}`")]
pub struct SizeError {
    pub flag: String,
    pub min: u32,
    pub text: String,
}

/// `WxH` (or `WXH`) with both sides in `min..=`[`MAX_IMAGE_SIDE`]: the one reading of an
/// image or window size every command uses.
pub fn parse_size(flag: &str, text: &str, min: u32) -> Result<(u32, u32), SizeError> {
    let bad = || SizeError {
        flag: flag.to_string(),
        min,
        text: text.to_string(),
    };
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(bad)?;
    let w: u32 = w.trim().parse().map_err(|_| bad())?;
    let h: u32 = h.trim().parse().map_err(|_| bad())?;
    let side = min..=MAX_IMAGE_SIDE;
    if !side.contains(&w) || !side.contains(&h) {
        return Err(bad());
    }
    Ok((w, h))
}
/// Most `meshes` entries: each is loaded and placed separately (2,000 took 15 s and 3.3 GB).
pub(crate) const MAX_MESHES: usize = 64;
/// Most `lights` entries: every shaded sample loops over them, with a shadow ray each
/// when `shadows` is on (100,000 lights in a 14 MB state took 24 s for 64×48 pixels on one
/// thread, about an hour at the default 800×600). The defaults have three.
pub(crate) const MAX_LIGHTS: usize = 64;

/// Camera and all render settings. JSON field names are the Rust field names.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewState {
    pub camera: Camera,
    pub mode: Mode,
    /// Field the iso value / transfer function applies to (e.g. `q`).
    pub iso_field: String,
    pub iso: f64,
    pub strategy: Strategy,
    /// Sample step in units of the local (finest contributing) cell width.
    pub step: f64,
    /// Samples (jittered rays) per pixel.
    #[serde(default = "one")]
    pub spp: u32,
    /// Seed of the per-pixel jitter (interleaved sampling).
    #[serde(default)]
    pub seed: u64,
    pub transfer: Band,
    pub colormap: ColorMap,
    pub lights: Vec<Light>,
    #[serde(default)]
    pub material: Material,
    #[serde(default)]
    pub meshes: Vec<MeshInstance>,
    /// Shadow rays towards every light, through meshes and the volume's opacity.
    #[serde(default)]
    pub shadows: bool,
    /// Dvr: pre-integrated opacity between consecutive samples (see
    /// [`crate::transfer::PreIntegrated`]). On in new states ([`ViewState::default_for`]):
    /// with it `uniform` sampling reaches a lower error than point-sampled `bisect` with
    /// fewer samples (BENCHMARKS.md). Absent from a state file it reads as off, so states
    /// saved before it existed render as they did.
    #[serde(default)]
    pub preintegrated: bool,
    /// Colour where rays leave the scene.
    #[serde(default = "default_background")]
    pub background: [f32; 3],
    pub width: u32,
    pub height: u32,
}

fn one() -> u32 {
    1
}

/// Dark blue-grey, so both white-ish meshes and blue shells stand out.
pub(crate) const DEFAULT_BACKGROUND: [f32; 3] = [0.08, 0.09, 0.11];

fn default_background() -> [f32; 3] {
    DEFAULT_BACKGROUND
}

/// Why a view state could not be loaded or saved.
#[derive(Debug, thiserror::Error)]
pub enum ViewStateError {
    // The cause is part of the one-line message, not a `source` (which would print it
    // twice in an anyhow chain).
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{}: not a valid view state: {error}", path.display())]
    Parse {
        path: PathBuf,
        error: serde_json::Error,
    },
    #[error("{}: {error}", path.display())]
    Invalid {
        path: PathBuf,
        error: InvalidViewState,
    },
    /// Larger than a view state may be; `size` is `None` for a stream that went on past
    /// the limit.
    #[error(
        "{}: expected a JSON view state of at most {limit} bytes, found {}",
        path.display(),
        found_bytes(*size)
    )]
    TooLarge {
        path: PathBuf,
        limit: u64,
        size: Option<u64>,
    },
    /// Not a file that can be read whole (a directory, …).
    #[error("{}: {kind}", path.display())]
    Input { path: PathBuf, kind: InputErrorKind },
    #[error("{}: not UTF-8 text: {error}", path.display())]
    NotUtf8 {
        path: PathBuf,
        error: std::str::Utf8Error,
    },
}

/// `N bytes`, or `more` for a stream read no further than the limit.
fn found_bytes(size: Option<u64>) -> String {
    match size {
        Some(n) => format!("{n} bytes"),
        None => "more".to_string(),
    }
}

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
    /// `transfer.sigma`, `transfer.peak` or `transfer.k`.
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
    /// `width` or `height`.
    #[error("{name}: expected 1..={MAX_IMAGE_SIDE}, found {value}")]
    ImageSide { name: &'static str, value: u32 },
}

/// The iso value and dvr band width a field starts with: 10 % of its positive maximum
/// (where the vortex cores of Q stand out), else the middle of its range; σ at 8 % of the
/// iso value as in the seed report, never zero.
pub(crate) fn default_iso(f: &FieldRange) -> (f64, f64) {
    let (iso, span) = {
        let (lo, hi) = crate::colormap::finite_range(f.min, f.max);
        let (lo, hi) = (f64::from(lo), f64::from(hi));
        let iso = if hi > 0.0 && lo < 0.1 * hi {
            0.1 * hi
        } else {
            0.5 * (lo + hi)
        };
        (iso, hi - lo)
    };
    let mut sigma = 0.08 * iso.abs();
    if sigma <= 0.0 || sigma.is_nan() {
        sigma = 0.02 * span;
    }
    if !(sigma > 0.0 && sigma.is_finite()) {
        sigma = 1e-3;
    }
    (iso, sigma)
}

impl ViewState {
    /// [`ViewState::default_for`] the field ranges of an opened volume, with the camera
    /// framing the regions where the iso field can cross the iso value (the interesting
    /// part, often much smaller than the domain), or the whole data when none can.
    pub fn default_for_volume(vol: &crate::volume::Volume) -> ViewState {
        let mut s = ViewState::default_for(
            vol.to_world(vol.bounds_min),
            vol.to_world(vol.bounds_max),
            &vol.fields,
        );
        if let Ok(f) = vol.field_index(&s.iso_field) {
            let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            for (r, reg) in vol.regions().enumerate() {
                let [mn, mx] = vol.range(r, f);
                if f64::from(mn) <= s.iso && s.iso <= f64::from(mx) {
                    for a in 0..3 {
                        lo[a] = lo[a].min(reg.min[a]);
                        hi[a] = hi[a].max(reg.max[a]);
                    }
                }
            }
            if (0..3).all(|a| lo[a] <= hi[a]) {
                s.camera = Camera::frame(vol.to_world(lo), vol.to_world(hi));
                s.lights_follow_camera();
            }
        }
        s
    }

    /// A state that shows any data set reasonably on first open: the camera frames the
    /// box `min..max`, the iso field is `q` (else the first field), the iso value is
    /// 10 % of its positive maximum (else the middle of its range), colour by `speed`
    /// (else the second field, else the iso field) over that field's range.
    pub(crate) fn default_for(min: [f64; 3], max: [f64; 3], fields: &[FieldRange]) -> ViewState {
        let camera = Camera::frame(min, max);
        let iso_range = fields
            .iter()
            .find(|f| f.name == "q")
            .or_else(|| fields.first());
        let iso_field = iso_range.map_or_else(|| "q".to_string(), |f| f.name.clone());
        let (iso, sigma) = iso_range.map_or((0.0, 1e-3), default_iso);
        let colour_field = fields
            .iter()
            .find(|f| f.name == "speed")
            .or_else(|| fields.iter().find(|f| f.name != iso_field))
            .or(iso_range);
        let colormap = match colour_field {
            Some(f) => ColorMap::default_for_range(&f.name, f.min, f.max),
            None => ColorMap::default_for_range("speed", 0.0, 1.0),
        };
        ViewState {
            lights: default_lights(&camera),
            camera,
            mode: Mode::Iso,
            iso_field,
            iso,
            strategy: Strategy::Exact,
            step: 0.5,
            spp: 1,
            seed: 0,
            transfer: Band {
                sigma,
                peak: 1.6,
                k: 2.0,
            },
            colormap,
            material: Material::default(),
            meshes: Vec::new(),
            shadows: false,
            preintegrated: true,
            background: DEFAULT_BACKGROUND,
            width: 800,
            height: 600,
        }
    }

    /// The strategy the rays use: `exact` finds iso-surface roots; a dvr band has no
    /// single root, so in dvr mode it samples as [`crate::render::effective_strategy`]
    /// says: `uniform` with pre-integration, `bisect` without.
    pub(crate) fn effective_strategy(&self) -> Strategy {
        crate::render::effective_strategy(self.mode, self.strategy, self.preintegrated)
    }

    /// Puts the default lights back over the viewer's shoulder for the current camera
    /// (used whenever the camera moves and the lights were not chosen by hand).
    pub(crate) fn lights_follow_camera(&mut self) {
        self.lights = default_lights(&self.camera);
    }

    /// Sets the iso value and keeps the dvr band's width at 8 % of it, as in the seed
    /// report (σ 0.004 at iso 0.05); an iso value of 0 keeps the current width.
    pub fn set_iso(&mut self, iso: f64) {
        self.iso = iso;
        if iso != 0.0 && iso.is_finite() {
            self.transfer.sigma = 0.08 * iso.abs();
        }
    }

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
            ("transfer.peak", self.transfer.peak),
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
        for (name, value) in [("width", self.width), ("height", self.height)] {
            if !(1..=MAX_IMAGE_SIDE).contains(&value) {
                return Err(InvalidViewState::ImageSide { name, value });
            }
        }
        Ok(())
    }

    /// Parses and validates JSON text; `path` only names the source in errors.
    pub(crate) fn from_json(path: &Path, text: &str) -> Result<ViewState, ViewStateError> {
        let state: ViewState =
            serde_json::from_str(text).map_err(|error| ViewStateError::Parse {
                path: path.to_path_buf(),
                error,
            })?;
        state.validate().map_err(|error| ViewStateError::Invalid {
            path: path.to_path_buf(),
            error,
        })?;
        Ok(state)
    }

    /// Reads a state file (at most 16 MiB, a regular file checked by its size before
    /// reading, a device or pipe read no further than that).
    pub fn load(path: &Path) -> Result<ViewState, ViewStateError> {
        const MAX_BYTES: u64 = 16 << 20;
        let path_buf = || path.to_path_buf();
        let too_large = |size| ViewStateError::TooLarge {
            path: path_buf(),
            limit: MAX_BYTES,
            size,
        };
        let bytes = read_whole(path, Limits::both(MAX_BYTES)).map_err(|e| match e.kind {
            InputErrorKind::Io(error) => ViewStateError::Io {
                path: path_buf(),
                error,
            },
            InputErrorKind::TooLarge { size, .. } => too_large(Some(size)),
            InputErrorKind::StreamTooLarge { .. } => too_large(None),
            kind => ViewStateError::Input {
                path: path_buf(),
                kind,
            },
        })?;
        let text = String::from_utf8(bytes).map_err(|e| ViewStateError::NotUtf8 {
            path: path_buf(),
            error: e.utf8_error(),
        })?;
        ViewState::from_json(path, &text)
    }

    /// Pretty JSON text.
    pub fn to_json(&self) -> String {
        // Serialising plain data with string keys cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Writes the state with [`files::output::write_atomic`] (temporary file next to
    /// `path`, renamed over it; a device or FIFO is written into).
    pub fn save(&self, path: &Path) -> Result<(), ViewStateError> {
        files::output::write_atomic(path, |f| {
            f.write_all(self.to_json().as_bytes())?;
            f.write_all(b"\n")
        })
        .map_err(|error| ViewStateError::Io {
            path: path.to_path_buf(),
            error,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields() -> Vec<FieldRange> {
        vec![
            FieldRange {
                name: "q".into(),
                min: -2.0,
                max: 0.5,
            },
            FieldRange {
                name: "speed".into(),
                min: 0.0,
                max: 0.08,
            },
        ]
    }

    #[test]
    fn defaults_are_valid_and_sensible() {
        let s = ViewState::default_for([-1.0, -1.0, -1.0], [3.0, 1.0, 1.0], &fields());
        s.validate().expect("valid");
        assert_eq!(s.iso_field, "q");
        assert!((s.iso - 0.05).abs() < 1e-7);
        assert!((s.transfer.sigma - 0.004).abs() < 1e-7);
        assert_eq!(s.colormap.field, "speed");
        assert_eq!(s.mode, Mode::Iso);
        // Without fields, and with odd ranges, still valid.
        ViewState::default_for([0.0; 3], [0.0; 3], &[])
            .validate()
            .expect("no fields");
        let odd = [FieldRange {
            name: "density".into(),
            min: 3.0,
            max: 3.0,
        }];
        let s = ViewState::default_for([0.0; 3], [1.0; 3], &odd);
        s.validate().expect("constant field");
        assert_eq!(s.iso_field, "density");
        assert_eq!(s.colormap.field, "density");
        let nan = [FieldRange {
            name: "q".into(),
            min: f32::NAN,
            max: 1.0,
        }];
        ViewState::default_for([0.0; 3], [1.0; 3], &nan)
            .validate()
            .expect("nan range");
        // Ranges wider than f32::MAX (a manifest may hold -3e38 … 3e38; caught by the
        // `sequence_state` fuzz target's check of the default state) for the colour field
        // and the iso field.
        let wide = [
            FieldRange {
                name: "q".into(),
                min: -3e38,
                max: 3e38,
            },
            FieldRange {
                name: "speed".into(),
                min: f32::MIN,
                max: f32::MAX,
            },
        ];
        ViewState::default_for([0.0; 3], [1.0; 3], &wide)
            .validate()
            .expect("ranges wider than f32::MAX");
    }

    /// Issue 32: a file whose Q overflowed f32 (stored as ±f32::MAX by the baker, or ±inf
    /// in a file written otherwise) rendered with "colormap.band: expected a finite
    /// number" although no state was given. Every default is finite and valid, whatever
    /// the ranges.
    #[test]
    fn defaults_from_overflowing_ranges_are_valid() {
        for (min, max) in [
            (-f32::MAX, f32::MAX),
            (f32::NEG_INFINITY, f32::INFINITY),
            (0.0, f32::INFINITY),
            (f32::NEG_INFINITY, f32::NAN),
        ] {
            // Q alone: the colour map falls back to the iso field.
            let q = [FieldRange {
                name: "q".into(),
                min,
                max,
            }];
            let s = ViewState::default_for([0.0; 3], [1.0; 3], &q);
            s.validate()
                .unwrap_or_else(|e| panic!("[{min}, {max}]: {e}"));
            assert!(s.iso.is_finite() && s.colormap.band.is_finite());
        }
    }

    /// A camera placed far out (its squared coordinates overflow) is judged by its
    /// direction: it used to be refused with "camera.up is parallel to the view direction".
    #[test]
    fn a_camera_far_from_the_origin_is_valid() {
        let s = ViewState::default_for([1e200; 3], [1.0001e200; 3], &fields());
        s.validate().expect("valid far out");
        let mut s = s;
        s.camera.up = std::array::from_fn(|a| s.camera.look_at[a] - s.camera.eye[a]);
        assert!(matches!(
            s.validate(),
            Err(InvalidViewState::UpAlongView { .. })
        ));
    }

    #[test]
    fn field_overrides_start_the_new_field_from_its_range() {
        let mut fields = fields();
        fields.push(FieldRange {
            name: "density".into(),
            min: 0.0,
            max: 2.0,
        });
        let base = ViewState::default_for([0.0; 3], [1.0; 3], &fields);
        let over = |colour: Option<&str>, iso_field: Option<&str>, iso: Option<f64>| Overrides {
            colour_field: colour.map(str::to_string),
            iso_field: iso_field.map(str::to_string),
            iso,
            ..Overrides::default()
        };

        let mut s = base.clone();
        over(Some("density"), None, None)
            .apply_fields(&mut s, &fields)
            .expect("known");
        assert_eq!(s.colormap, ColorMap::default_for_range("density", 0.0, 2.0));
        assert_eq!((s.iso_field.as_str(), s.iso), ("q", base.iso));

        let mut s = base.clone();
        over(None, Some("density"), None)
            .apply_fields(&mut s, &fields)
            .expect("known");
        assert_eq!((s.iso_field.as_str(), s.iso), ("density", 0.2));
        assert!((s.transfer.sigma - 0.016).abs() < 1e-12);
        assert_eq!(s.colormap, base.colormap);

        // An explicit --iso is kept (apply sets it first).
        let mut s = base.clone();
        let o = over(None, Some("density"), Some(1.5));
        o.apply(&mut s, false).expect("apply");
        o.apply_fields(&mut s, &fields).expect("known");
        assert_eq!((s.iso_field.as_str(), s.iso), ("density", 1.5));

        // Naming the current fields changes nothing, even a hand-made colour map.
        let mut s = base.clone();
        s.colormap = ColorMap::seed_report();
        let kept = s.clone();
        over(Some("speed"), Some("q"), None)
            .apply_fields(&mut s, &fields)
            .expect("known");
        assert_eq!(s, kept);

        let e = over(Some("vorticity"), None, None)
            .apply_fields(&mut base.clone(), &fields)
            .expect_err("unknown");
        assert_eq!(e.flag, "--colour-field");
        assert_eq!(e.known, ["q", "speed", "density"]);
        assert_eq!(
            e.to_string(),
            "--colour-field: no field named \"vorticity\" (fields: q, speed, density)"
        );
        let e = over(None, Some("w"), None)
            .apply_fields(&mut base.clone(), &fields)
            .expect_err("unknown");
        assert_eq!(e.flag, "--iso-field");
    }

    #[test]
    fn json_round_trip_through_a_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("view.json");
        let mut s = ViewState::default_for([0.0; 3], [1.0; 3], &fields());
        s.mode = Mode::Dvr;
        s.strategy = Strategy::Bisect;
        s.meshes.push(MeshInstance::at_origin("data/sphere.obj"));
        s.shadows = true;
        s.seed = 42;
        s.camera.projection = Projection::Orthographic { width: 2.5 };
        s.colormap = ColorMap::seed_report();
        s.save(&path).expect("save");
        let back = ViewState::load(&path).expect("load");
        assert_eq!(s, back);
        // Only the final file is left behind.
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .expect("read_dir")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("view.json")]);
        let text = std::fs::read_to_string(&path).expect("read");
        assert!(text.contains("\"mode\": \"dvr\""), "{text}");
        assert!(text.contains("\"strategy\": \"bisect\""), "{text}");
    }

    #[test]
    fn unknown_fields_are_rejected_with_their_name() {
        let s = ViewState::default_for([0.0; 3], [1.0; 3], &fields());
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        v["isovalue"] = serde_json::json!(0.1);
        let e = ViewState::from_json(Path::new("v.json"), &v.to_string()).expect_err("unknown");
        let msg = e.to_string();
        assert!(
            msg.starts_with("v.json: ") && msg.contains("isovalue"),
            "{msg}"
        );
        // The cause is in the message only once (an anyhow chain would repeat a source).
        assert!(std::error::Error::source(&e).is_none());
        // Nested: inside the camera and inside a light.
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        v["camera"]["fov"] = serde_json::json!(30);
        let e = ViewState::from_json(Path::new("v.json"), &v.to_string()).expect_err("nested");
        assert!(e.to_string().contains("fov"), "{e}");
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        v["lights"][0]["power"] = serde_json::json!(3);
        let e = ViewState::from_json(Path::new("v.json"), &v.to_string()).expect_err("light");
        assert!(e.to_string().contains("power"), "{e}");
        // Bad enum strings.
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        v["strategy"] = serde_json::json!("fast");
        let e = ViewState::from_json(Path::new("v.json"), &v.to_string()).expect_err("enum");
        assert!(e.to_string().contains("fast"), "{e}");
    }

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

    #[test]
    fn defaulted_fields_may_be_omitted() {
        let s = ViewState::default_for([0.0; 3], [1.0; 3], &fields());
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        let obj = v.as_object_mut().expect("object");
        for k in ["spp", "seed", "material", "meshes", "shadows", "background"] {
            obj.remove(k);
        }
        let back = ViewState::from_json(Path::new("v.json"), &v.to_string()).expect("parse");
        assert_eq!(back, s);
    }

    #[test]
    fn enums_parse_and_print() {
        for m in Mode::ALL {
            assert_eq!(m.to_string().parse::<Mode>(), Ok(m));
        }
        for s in Strategy::ALL {
            assert_eq!(s.to_string().parse::<Strategy>(), Ok(s));
        }
        assert!("ISO".parse::<Mode>().is_err());
    }

    #[test]
    fn transfer_function_matches_the_seed_report() {
        let tf = crate::transfer::Transfer {
            mode: Mode::Dvr,
            iso: 0.05,
            band: Band::SEED_REPORT,
        };
        assert_eq!(tf.opacity(0.05), 1.0); // peak 1.6 clamps to 1
        assert_eq!(tf.opacity(0.0419), 0.0);
        assert_eq!(tf.opacity(0.0581), 0.0);
        let x: f64 = 1.5;
        let want = 1.6 * (-0.5 * x * x).exp();
        assert!((tf.opacity(0.05 + 1.5 * 0.004) - want).abs() < 1e-12);
    }
}
