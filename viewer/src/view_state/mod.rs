//! Everything that determines a picture besides the data file: camera, mode, iso value,
//! sampling, transfer function, colour map, lights, meshes, resolution.
//!
//! Saved and loaded as JSON so a view set up in the GUI renders headless pixel for
//! pixel. Unknown fields are rejected (a typo must not silently fall back to a default);
//! values serde cannot check are checked by [`ViewState::validate`], which `load` calls.

use serde::{Deserialize, Serialize};

use crate::camera::Camera;
use crate::colormap::ColorMap;
use crate::mesh::MeshInstance;
use crate::overlay::Overlays;
pub use crate::planes::{Plane, Slice};
pub use crate::sampling::Strategy;
use crate::shading::{default_lights, Light, Material};
pub use crate::transfer::{Band, Mode};

mod command;
mod file;
mod overrides;
mod resolve;
mod size;
mod validate;
pub use crate::fields::UnknownField;
pub use command::ViewCommand;
pub use file::ViewStateError;
pub use overrides::{IsoValues, OverrideError, Overrides, SurfaceColour};
pub use resolve::{ResolveError, ResolvedView};
pub use size::{parse_size, SizeError};
pub use validate::InvalidViewState;

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

/// Most `meshes` entries: each is loaded and placed separately (2,000 took 15 s and 3.3 GB).
pub(crate) const MAX_MESHES: usize = 64;
/// Most `lights` entries: every shaded sample loops over them, with a shadow ray each
/// when `shadows` is on (100,000 lights in a 14 MB state took 24 s for 64×48 pixels on one
/// thread, about an hour at the default 800×600). The defaults have two.
pub(crate) const MAX_LIGHTS: usize = 64;

/// Camera and all render settings. JSON field names are the Rust field names.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewState {
    pub camera: Camera,
    pub mode: Mode,
    /// Field the iso value / transfer function applies to (e.g. `q`).
    pub iso_field: String,
    /// The iso value of the first iso-surface (iso mode; the middle of the dvr band).
    pub iso: f64,
    /// Opacity of the first iso-surface: 1 hides what lies behind it; less shows the
    /// surfaces inside it (see `more_isos`).
    #[serde(default = "one_f64", skip_serializing_if = "is_one")]
    pub iso_opacity: f64,
    /// A fixed colour for the first iso-surface instead of the colour map's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iso_colour: Option<[f32; 3]>,
    /// Further iso-surfaces of the iso field (iso mode), drawn with the first in ray
    /// order: e.g. a translucent shell around an opaque core. At most
    /// [`MAX_ISO_SURFACES`] surfaces in all.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub more_isos: Vec<IsoSurface>,
    /// Clip planes: each keeps the side its normal points to (see [`crate::planes`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clip: Vec<Plane>,
    /// Slice planes coloured by the colour field.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub slices: Vec<Slice>,
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
    /// What the picture carries besides the data: a list of `legend`, `axes`, `box`,
    /// `scale`, `title` (see [`crate::overlay`]). Absent from a state file it means every
    /// overlay but the title, as for a new view: a picture should say what its colours
    /// mean; `[]` gives the bare image.
    #[serde(default)]
    pub overlays: Overlays,
    pub width: u32,
    pub height: u32,
}

fn one() -> u32 {
    1
}

fn one_f64() -> f64 {
    1.0
}

fn is_one(x: &f64) -> bool {
    *x == 1.0
}

/// Most iso-surfaces in one view (`iso` and `more_isos` together).
pub const MAX_ISO_SURFACES: usize = 8;

/// Opacity of a surface added by [`ViewState::add_surface`]: enough to see it, little
/// enough to see through it.
pub const NEW_SURFACE_OPACITY: f64 = 0.4;

/// One iso-surface of the iso field: its value, opacity and (optionally) a fixed colour
/// instead of the colour map's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IsoSurface {
    pub value: f64,
    #[serde(default = "one_f64")]
    pub opacity: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour: Option<[f32; 3]>,
}

/// Dark blue-grey, so both white-ish meshes and blue shells stand out.
pub(crate) const DEFAULT_BACKGROUND: [f32; 3] = [0.08, 0.09, 0.11];

fn default_background() -> [f32; 3] {
    DEFAULT_BACKGROUND
}

/// Fields whose vortex cores are their *negative* values: λ2 (`qbricks-bake --fields
/// lambda2`), the middle eigenvalue of S² + Ω². Their default iso value mirrors Q's.
pub(crate) const NEGATIVE_CORE_FIELDS: [&str; 1] = ["lambda2"];

/// The iso value and dvr band width a field starts with: 10 % of its positive maximum
/// (where the vortex cores of Q stand out), for a field of [`NEGATIVE_CORE_FIELDS`] 10 % of
/// its negative minimum (the same rule on the negated field), else the middle of its range;
/// σ at 8 % of the iso value as in the seed report, never zero. Other fields keep Q's rule
/// even when their negative side is the larger (Q's strain regions often are).
pub(crate) fn default_iso(f: &FieldRange) -> (f64, f64) {
    let (iso, span) = {
        let (lo, hi) = crate::colormap::finite_range(f.min, f.max);
        let (lo, hi) = (f64::from(lo), f64::from(hi));
        let iso = if NEGATIVE_CORE_FIELDS.contains(&f.name.as_str()) {
            if lo < 0.0 && hi > 0.1 * lo {
                0.1 * lo
            } else {
                0.5 * (lo + hi)
            }
        } else if hi > 0.0 && lo < 0.1 * hi {
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
    /// framing the iso surface ([`ViewState::frame_surface`]).
    pub fn default_for_volume(vol: &crate::volume::Volume) -> ViewState {
        let mut s = ViewState::default_unframed(vol);
        s.frame_surface(vol);
        s
    }

    /// [`ViewState::default_for`] the field ranges of an opened volume, the camera on the
    /// whole data: for a caller that places or frames the camera itself.
    pub(crate) fn default_unframed(vol: &crate::volume::Volume) -> ViewState {
        ViewState::default_for(
            vol.to_world(vol.bounds_min),
            vol.to_world(vol.bounds_max),
            &vol.fields,
        )
    }

    /// World boxes whose union holds the surface of the view's iso field and value
    /// ([`crate::framing::surface_boxes`]); empty when the field is missing or no cell
    /// lies on both sides of the iso value (an empty picture).
    pub fn surface_bounds(&self, vol: &crate::volume::Volume) -> Vec<([f64; 3], [f64; 3])> {
        let mut out = Vec::new();
        self.surface_boxes(vol)
            .for_each(vol, |lo, hi| out.push((vol.to_world(lo), vol.to_world(hi))));
        out
    }

    /// [`ViewState::surface_bounds`] without listing them (local frame of `vol`): a
    /// billion-cell file has tens of millions.
    pub fn surface_boxes(&self, vol: &crate::volume::Volume) -> crate::framing::SurfaceBoxes {
        let f = vol.field_index(&self.iso_field).unwrap_or(usize::MAX);
        crate::framing::SurfaceBoxes::of(vol, f, self.iso)
    }

    /// Points the camera at the visible structure, the iso surface's bounds (not the
    /// regions that may hold the value, which reach far past it), centred and filling
    /// [`crate::framing::DEFAULT_FILL`] of the image; at the whole data when there is no
    /// surface. Keeps the projection kind; the default lights follow.
    pub fn frame_surface(&mut self, vol: &crate::volume::Volume) {
        let boxes = self.surface_boxes(vol);
        if boxes.is_empty(vol) {
            self.frame_boxes(&[(vol.to_world(vol.bounds_min), vol.to_world(vol.bounds_max))]);
            return;
        }
        let aspect = f64::from(self.width.max(1)) / f64::from(self.height.max(1));
        let fill = crate::framing::DEFAULT_FILL;
        self.camera = boxes.fit(vol, aspect, fill, self.camera.projection);
        self.lights_follow_camera();
    }

    /// Points the camera at the union of the world boxes as
    /// [`crate::framing::fit_boxes`] does for this state's image size, keeping the
    /// projection kind; the default lights follow.
    pub fn frame_boxes(&mut self, boxes: &[([f64; 3], [f64; 3])]) {
        let aspect = f64::from(self.width.max(1)) / f64::from(self.height.max(1));
        let fill = crate::framing::DEFAULT_FILL;
        self.camera = crate::framing::fit_boxes(boxes, aspect, fill, self.camera.projection);
        self.lights_follow_camera();
    }

    /// A state that shows any data set reasonably on first open: the camera frames the
    /// box `min..max`, the iso field is `q` (else the first field), the iso value is
    /// 10 % of its positive maximum (else the middle of its range), colour by `speed`
    /// (else the second field, else the iso field) over that field's range.
    pub(crate) fn default_for(min: [f64; 3], max: [f64; 3], fields: &[FieldRange]) -> ViewState {
        let projection = crate::camera::Projection::Perspective {
            fov_deg: crate::camera::DEFAULT_FOV_DEG,
        };
        let fill = crate::framing::DEFAULT_FILL;
        let camera = crate::framing::fit(min, max, 800.0 / 600.0, fill, projection);
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
            iso_opacity: 1.0,
            iso_colour: None,
            more_isos: Vec::new(),
            clip: Vec::new(),
            slices: Vec::new(),
            strategy: Strategy::Exact,
            step: 0.5,
            spp: 1,
            seed: 0,
            transfer: Band {
                sigma,
                peak_opacity: Band::SHELL_PEAK_OPACITY,
                k: 2.0,
            },
            colormap,
            material: Material::new_view(),
            meshes: Vec::new(),
            overlays: Overlays::default(),
            shadows: false,
            preintegrated: true,
            background: DEFAULT_BACKGROUND,
            width: 800,
            height: 600,
        }
    }

    /// The strategy the rays use: `exact` finds iso-surface roots; a dvr band has no
    /// single root, so in dvr mode it samples as [`Strategy::in_mode`] says: `uniform`
    /// with pre-integration, `bisect` without.
    pub fn effective_strategy(&self) -> Strategy {
        self.strategy.in_mode(self.mode, self.preintegrated)
    }

    /// Puts the default lights back over the viewer's shoulder for the current camera
    /// (used whenever the camera moves and the lights were not chosen by hand).
    pub(crate) fn lights_follow_camera(&mut self) {
        self.lights = default_lights(&self.camera);
    }

    /// A warning when nothing can be drawn because the iso value (in dvr mode: the band
    /// around it) lies outside the range of the iso field in `fields`, naming the value,
    /// the field and its range; `None` otherwise, also when the field is missing (that is
    /// an error elsewhere). Issue 26: such a view used to give an empty picture silently.
    pub fn iso_outside_range(&self, fields: &[FieldRange]) -> Option<String> {
        let f = fields.iter().find(|f| f.name == self.iso_field)?;
        let (lo, hi) = crate::transfer::Transfer {
            mode: self.mode,
            iso: self.iso,
            band: self.transfer,
        }
        .band();
        let (min, max) = (f64::from(f.min), f64::from(f.max));
        // NaN compares false both ways: a non-finite range warns of nothing.
        let outside = hi < min || lo > max;
        let what = match self.mode {
            Mode::Iso => format!("iso value {}", self.iso),
            Mode::Dvr => format!("dvr band {lo}…{hi}"),
        };
        outside.then(|| {
            format!(
                "the {what} is outside the range of {} ({min} … {max}): nothing to draw",
                f.name
            )
        })
    }

    /// Every iso-surface of the view, the first (`iso`) first.
    pub fn surfaces(&self) -> Vec<IsoSurface> {
        let first = IsoSurface {
            value: self.iso,
            opacity: self.iso_opacity,
            colour: self.iso_colour,
        };
        std::iter::once(first)
            .chain(self.more_isos.iter().copied())
            .collect()
    }

    /// Replaces the iso-surfaces by `surfaces` (the first sets `iso` as
    /// [`ViewState::set_iso`] does); an empty list changes nothing.
    pub fn set_surfaces(&mut self, surfaces: &[IsoSurface]) {
        let Some((first, more)) = surfaces.split_first() else {
            return;
        };
        self.set_iso(first.value);
        self.iso_opacity = first.opacity;
        self.iso_colour = first.colour;
        self.more_isos = more.to_vec();
    }

    /// Adds an iso-surface at half the last one's value, translucent
    /// ([`NEW_SURFACE_OPACITY`]) so the surfaces inside it show: with the default Q
    /// value, a shell around the vortex cores. `false` (and nothing added) when the view
    /// has [`MAX_ISO_SURFACES`] already.
    pub fn add_surface(&mut self) -> bool {
        if self.more_isos.len() + 1 >= MAX_ISO_SURFACES {
            return false;
        }
        let last = self.more_isos.last().map_or(self.iso, |s| s.value);
        self.more_isos.push(IsoSurface {
            value: 0.5 * last,
            opacity: NEW_SURFACE_OPACITY,
            colour: None,
        });
        true
    }

    /// Removes iso-surface `index` (0: the first, `iso`, whose place the next one takes);
    /// `false` (and nothing removed) for the last one left or an index past the end.
    pub fn remove_surface(&mut self, index: usize) -> bool {
        let mut all = self.surfaces();
        if all.len() < 2 || index >= all.len() {
            return false;
        }
        all.remove(index);
        if index == 0 {
            self.set_surfaces(&all);
        } else {
            self.more_isos.remove(index - 1);
        }
        true
    }

    /// Sets the iso value and keeps the dvr band's width at 8 % of it, as in the seed
    /// report (σ 0.004 at iso 0.05); an iso value of 0 keeps the current width.
    pub fn set_iso(&mut self, iso: f64) {
        self.iso = iso;
        if iso != 0.0 && iso.is_finite() {
            self.transfer.sigma = 0.08 * iso.abs();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(super) fn fields() -> Vec<FieldRange> {
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

    /// λ2 marks vortex cores with negative values: its default iso is 10 % of its minimum,
    /// as Q's is of its maximum; Q keeps its rule however negative its minimum, and a
    /// λ2 range without negative values takes the middle.
    #[test]
    fn lambda2_defaults_to_a_tenth_of_its_negative_minimum() {
        let range = |name: &str, min: f32, max: f32| FieldRange {
            name: name.into(),
            min,
            max,
        };
        let (iso, sigma) = default_iso(&range("lambda2", -0.5, 0.04));
        assert!((iso + 0.05).abs() < 1e-7 && (sigma - 0.004).abs() < 1e-7);
        assert_eq!(default_iso(&range("lambda2", -0.5, 0.0)).0, 0.1 * -0.5f64);
        let (iso, _) = default_iso(&range("q", -0.5, 0.04));
        assert!((iso - 0.004).abs() < 1e-7);
        assert_eq!(
            default_iso(&range("lambda2", 0.2, 0.4)).0,
            0.5 * (0.2f32 as f64 + 0.4f32 as f64)
        );
        // As the view's iso field (λ2 the only field), and by name, not by shape.
        let s = ViewState::default_for([0.0; 3], [1.0; 3], &[range("lambda2", -0.5, 0.04)]);
        s.validate().expect("valid");
        assert_eq!(s.iso_field, "lambda2");
        assert!((s.iso + 0.05).abs() < 1e-7);
        let (iso, _) = default_iso(&range("vorticity", 0.0, 1.4));
        assert!((iso - 0.14).abs() < 1e-7);
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
    fn an_iso_value_outside_the_range_is_named() {
        let mut s = ViewState::default_for([0.0; 3], [1.0; 3], &fields());
        assert_eq!(s.iso_outside_range(&fields()), None);
        s.set_iso(0.7);
        let w = s.iso_outside_range(&fields()).expect("warning");
        assert!(w.contains("0.7") && w.contains("q (-2 … 0.5)"), "{w}");
        s.set_iso(-2.5);
        assert!(s.iso_outside_range(&fields()).is_some());
        // A band that reaches into the range still draws something.
        s.mode = Mode::Dvr;
        s.transfer.sigma = 0.3;
        assert_eq!(s.iso_outside_range(&fields()), None);
        s.iso_field = "nope".into();
        assert_eq!(s.iso_outside_range(&fields()), None);
    }

    /// Surfaces are added at half the last value, translucent, up to the limit; removing
    /// the first makes the next one the first; the last one left stays.
    #[test]
    fn surfaces_are_added_and_removed() {
        let mut s = ViewState::default_for([0.0; 3], [1.0; 3], &fields());
        let iso = s.iso;
        assert!(s.add_surface());
        assert_eq!(
            s.more_isos,
            vec![IsoSurface {
                value: 0.5 * iso,
                opacity: NEW_SURFACE_OPACITY,
                colour: None
            }]
        );
        assert!(s.add_surface());
        assert_eq!(s.more_isos[1].value, 0.25 * iso);
        while s.add_surface() {}
        assert_eq!(s.surfaces().len(), MAX_ISO_SURFACES);
        s.validate().expect("valid with every surface");
        assert!(!s.remove_surface(MAX_ISO_SURFACES));
        assert!(s.remove_surface(2));
        assert_eq!(s.more_isos[1].value, 0.125 * iso);
        assert!(s.remove_surface(0));
        assert_eq!((s.iso, s.iso_opacity), (0.5 * iso, NEW_SURFACE_OPACITY));
        assert!((s.transfer.sigma - 0.08 * s.iso).abs() < 1e-15);
        while s.remove_surface(0) {}
        assert_eq!(s.surfaces().len(), 1);
        assert!(!s.remove_surface(0));
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
