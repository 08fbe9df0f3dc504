//! Command-line flags that change a view state (`qbricks-view render` and the window),
//! and how they are applied: plain settings are set, and the changes that follow a rule
//! (the iso value, the iso and colour fields) go through [`ViewState::apply`], as the
//! window's panel does.

use super::{FieldRange, IsoSurface, Mode, Strategy, ViewCommand, ViewState, MAX_ISO_SURFACES};
use crate::camera::Projection;
use crate::fields::UnknownField;
use crate::mesh::{MeshInstance, MeshSpecError};
use crate::overlay::Overlays;
use crate::palette::{Palette, PaletteSpec};
use crate::planes::{Plane, Slice, MAX_CLIP_PLANES, MAX_SLICES};

/// Command-line changes to a view state (`qbricks-view render` flags). They live here,
/// next to the state they change, so the window and the headless renderer apply the same
/// rules.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct Overrides {
    /// Image width in pixels.
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels.
    #[arg(long)]
    pub height: Option<u32>,
    /// Render mode.
    #[arg(long, value_enum)]
    pub mode: Option<Mode>,
    /// Iso value(s) of the iso field: V or V1,V2,… (up to 8 surfaces, drawn together in
    /// ray order; see --iso-opacity).
    #[arg(long, allow_hyphen_values = true)]
    pub iso: Option<IsoValues>,
    /// Opacity of each iso-surface, A1,A2,… in (0, 1] in the order of --iso [default: 1]:
    /// e.g. `--iso 0.02,0.1 --iso-opacity 0.3` shows an opaque Q = 0.1 core through a
    /// translucent Q = 0.02 shell.
    #[arg(long = "iso-opacity", value_delimiter = ',')]
    pub iso_opacity: Vec<f64>,
    /// Colour of each iso-surface, C1,C2,… in the order of --iso: `#rrggbb`, or `map`
    /// for the colour map's colour of the colour field [default: map].
    #[arg(long = "iso-colour", alias = "iso-color", value_delimiter = ',')]
    pub iso_colour: Vec<SurfaceColour>,
    /// Clip plane OX,OY,OZ:NX,NY,NZ (a point and a normal; the side the normal points to
    /// is kept) or `x>1.5`, `z<0`. Repeatable, up to 6; replaces the state's clip planes.
    #[arg(long = "clip", allow_hyphen_values = true)]
    pub clip: Vec<Plane>,
    /// Slice plane OX,OY,OZ:NX,NY,NZ or `z>0` (the normal's sign does not matter),
    /// coloured by the colour field. Repeatable, up to 3; replaces the state's slices.
    #[arg(long = "slice", allow_hyphen_values = true)]
    pub slices: Vec<Plane>,
    /// Opacity of the --slice planes, in (0, 1] [default: 1].
    #[arg(long = "slice-opacity")]
    pub slice_opacity: Option<f64>,
    /// Draw the iso values' contour lines on the --slice planes.
    #[arg(long = "slice-contours")]
    pub slice_contours: bool,
    /// The --slice planes also remove what lies between them and the camera.
    #[arg(long = "slice-clip")]
    pub slice_clip: bool,
    /// Sampling strategy (`exact` is for iso mode; in dvr it samples as `uniform`, or as
    /// `bisect` with --no-preintegrated).
    #[arg(long, value_enum)]
    pub strategy: Option<Strategy>,
    /// Sample step in units of the local cell width.
    #[arg(long, allow_hyphen_values = true)]
    pub step: Option<f64>,
    /// Jittered rays per pixel.
    #[arg(long)]
    pub spp: Option<u32>,
    /// Shadow rays towards every light (through meshes and the volume).
    #[arg(long)]
    pub shadows: bool,
    /// Dvr: pre-integrated opacity, so a band thinner than the step still counts fully
    /// (the default for new views; a state file may have it off).
    #[arg(long, conflicts_with = "no_preintegrated")]
    pub preintegrated: bool,
    /// Dvr: point-sampled opacity (pre-integration off).
    #[arg(long)]
    pub no_preintegrated: bool,
    /// OBJ mesh, optionally placed: PATH[@x,y,z,scale]. Repeatable; replaces the state's meshes.
    #[arg(long = "mesh")]
    pub meshes: Vec<String>,
    /// Camera position x,y,z (world units).
    #[arg(long, allow_hyphen_values = true)]
    pub eye: Option<String>,
    /// Point the camera looks at, x,y,z.
    #[arg(long = "look-at", allow_hyphen_values = true)]
    pub look_at: Option<String>,
    /// Camera up vector x,y,z.
    #[arg(long, allow_hyphen_values = true)]
    pub up: Option<String>,
    /// Orthographic projection with this view width (world units).
    #[arg(long, conflicts_with = "fov")]
    pub ortho: Option<f64>,
    /// Perspective projection with this vertical field of view (degrees).
    #[arg(long)]
    pub fov: Option<f64>,
    /// Field that drives the colour (e.g. `speed`, `density`). Without --state the colour
    /// map's points are spread over that field's range (a sequence's range for a sequence).
    #[arg(long = "colour-field", alias = "color-field")]
    pub colour_field: Option<String>,
    /// Field the iso value applies to (e.g. `q`, `density`). Without --iso the iso value
    /// starts at 10 % of that field's maximum (else the middle of its range).
    #[arg(long = "iso-field")]
    pub iso_field: Option<String>,
    /// Colour map: viridis, magma, cividis, coolwarm (diverging) or speed (the default
    /// blue-green-red); add _r to reverse. Spread over the colour field's range unless
    /// --colour-range says otherwise.
    #[arg(long = "colormap", alias = "colourmap")]
    pub colormap: Option<PaletteSpec>,
    /// Values at the ends of the colour map: LO,HI, or `visible` for the range of the
    /// colour field over the surfaces the picture shows (rendered twice).
    #[arg(
        long = "colour-range",
        alias = "color-range",
        allow_hyphen_values = true
    )]
    pub colour_range: Option<ColourRange>,
    /// Diverging maps (coolwarm): the value in the middle of the map [default: 0 when the
    /// range holds it, else the middle of the range].
    #[arg(
        long = "colour-centre",
        alias = "color-center",
        allow_hyphen_values = true
    )]
    pub colour_centre: Option<f32>,
    /// Space the colour map's colours evenly in log10 of the value (positive ranges).
    #[arg(long)]
    pub log: bool,
    /// What the picture carries besides the data: `none` or a comma-separated list of
    /// legend, axes, box, scale, title [default: legend,axes,box,scale].
    #[arg(long)]
    pub overlays: Option<Overlays>,
}

/// `--colour-range`: two values, or the range of what the picture shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ColourRange {
    Values(f32, f32),
    Visible,
}

/// Why a `--colour-range` is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("expected LO,HI (finite numbers, LO < HI) or `visible`, found `{text}`")]
pub struct ColourRangeError {
    pub text: String,
}

impl std::str::FromStr for ColourRange {
    type Err = ColourRangeError;
    fn from_str(s: &str) -> Result<Self, ColourRangeError> {
        let bad = || ColourRangeError {
            text: s.to_string(),
        };
        if s.trim() == "visible" {
            return Ok(ColourRange::Visible);
        }
        let (lo, hi) = s.split_once(',').ok_or_else(bad)?;
        let lo: f32 = lo.trim().parse().map_err(|_| bad())?;
        let hi: f32 = hi.trim().parse().map_err(|_| bad())?;
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(bad());
        }
        Ok(ColourRange::Values(lo, hi))
    }
}

/// `--iso`: one or more iso values.
#[derive(Debug, Clone, PartialEq)]
pub struct IsoValues(pub Vec<f64>);

impl From<f64> for IsoValues {
    fn from(v: f64) -> Self {
        IsoValues(vec![v])
    }
}

/// Why an `--iso` list is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("expected V or V1,V2,… (finite numbers, at most {MAX_ISO_SURFACES}), found `{text}`")]
pub struct IsoValuesError {
    pub text: String,
}

impl std::str::FromStr for IsoValues {
    type Err = IsoValuesError;
    fn from_str(s: &str) -> Result<Self, IsoValuesError> {
        let bad = || IsoValuesError {
            text: s.to_string(),
        };
        let values = s
            .split(',')
            .map(|v| v.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(bad)?;
        if values.is_empty() || values.len() > MAX_ISO_SURFACES {
            return Err(bad());
        }
        Ok(IsoValues(values))
    }
}

/// `--iso-colour`: a fixed colour, or the colour map's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SurfaceColour {
    Map,
    Fixed([f32; 3]),
}

/// Why an `--iso-colour` entry is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("expected `map` or a colour #rrggbb, found `{text}`")]
pub struct SurfaceColourError {
    pub text: String,
}

impl std::str::FromStr for SurfaceColour {
    type Err = SurfaceColourError;
    fn from_str(s: &str) -> Result<Self, SurfaceColourError> {
        let bad = || SurfaceColourError {
            text: s.to_string(),
        };
        let t = s.trim();
        if t.eq_ignore_ascii_case("map") {
            return Ok(SurfaceColour::Map);
        }
        let hex = t.strip_prefix('#').ok_or_else(bad)?;
        if hex.len() != 6 || !hex.is_ascii() {
            return Err(bad());
        }
        let channel = |i: usize| {
            u8::from_str_radix(&hex[i..i + 2], 16)
                .map(|v| f32::from(v) / 255.0)
                .map_err(|_| bad())
        };
        Ok(SurfaceColour::Fixed([
            channel(0)?,
            channel(2)?,
            channel(4)?,
        ]))
    }
}

/// A `--mesh`, `--eye`, `--look-at` or `--up` flag that does not parse.
#[derive(Debug, thiserror::Error)]
pub enum OverrideError {
    #[error("--mesh: {0}")]
    Mesh(MeshSpecError),
    /// `--iso-opacity` or `--iso-colour` with more entries than surfaces, or a count
    /// flag over its limit; `flag` without its dashes.
    #[error("--{flag}: expected at most {most} entries, found {found}")]
    TooMany {
        flag: &'static str,
        most: usize,
        found: usize,
    },
    #[error("--iso-opacity: expected opacities in (0, 1], found {0}")]
    Opacity(f64),
    #[error("--slice-opacity: expected an opacity in (0, 1], found {0}")]
    SliceOpacity(f64),
    /// `flag` without its dashes (`eye`, `look-at`, `up`).
    #[error("--{flag}: {error}")]
    Point {
        flag: &'static str,
        error: crate::probe::PointError,
    },
}

impl Overrides {
    /// Applies the flags to `state`. `from_file`: the state came from a state file, so
    /// its lights and band are the user's; otherwise the data-derived defaults follow
    /// the flags (lights over the viewer's shoulder after `--eye`, σ at 8 % of `--iso`).
    /// Returns notes worth telling the user.
    pub fn apply(
        &self,
        state: &mut ViewState,
        from_file: bool,
    ) -> Result<Vec<String>, OverrideError> {
        let mut notes = Vec::new();
        if let Some(v) = self.width {
            state.width = v;
        }
        if let Some(v) = self.height {
            state.height = v;
        }
        if let Some(v) = self.mode {
            state.mode = v;
        }
        self.apply_surfaces(state, from_file)?;
        self.apply_planes(state)?;
        if let Some(v) = self.strategy {
            state.strategy = v;
        }
        if let Some(v) = self.step {
            state.step = v;
        }
        if let Some(v) = self.spp {
            state.spp = v;
        }
        if self.shadows {
            state.shadows = true;
        }
        if self.preintegrated {
            state.preintegrated = true;
        }
        if self.no_preintegrated {
            state.preintegrated = false;
        }
        if !self.meshes.is_empty() {
            state.meshes = self
                .meshes
                .iter()
                .map(|m| MeshInstance::parse(m).map_err(OverrideError::Mesh))
                .collect::<Result<_, _>>()?;
        }
        let vec = |flag: &'static str, s: &str| {
            crate::probe::parse_xyz(s).map_err(|error| OverrideError::Point { flag, error })
        };
        if let Some(s) = &self.eye {
            state.camera.eye = vec("eye", s)?;
        }
        if let Some(s) = &self.look_at {
            state.camera.look_at = vec("look-at", s)?;
        }
        if let Some(s) = &self.up {
            state.camera.up = vec("up", s)?;
        }
        if let Some(w) = self.ortho {
            state.camera.projection = Projection::Orthographic { width: w };
        }
        if let Some(f) = self.fov {
            state.camera.projection = Projection::Perspective { fov_deg: f };
        }
        if !from_file {
            state.lights_follow_camera();
        }
        if let Some(f) = &self.iso_field {
            if from_file && self.iso.is_none() && *f != state.iso_field {
                // The state file's iso value belongs to another field.
                notes.push(format!(
                    "--iso-field {f}: the iso value starts over from that field's range \
                     (give --iso to choose it)"
                ));
            }
        }
        if state.mode == Mode::Dvr && state.strategy == Strategy::Exact {
            let used = state.effective_strategy();
            if self.strategy.is_none() {
                // The default strategy (exact) is for iso mode; a dvr request without an
                // explicit strategy gets the one dvr uses anyway, without a note.
                state.strategy = used;
            } else {
                notes.push(format!(
                    "`exact` is an iso-surface strategy; dvr samples as `{used}`"
                ));
            }
        }
        Ok(notes)
    }
}

impl Overrides {
    /// `--iso`, `--iso-opacity`, `--iso-colour`: the list of iso-surfaces. Opacities and
    /// colours apply to the surfaces in order (those of `--iso`, else the state's); a
    /// surface without one keeps its own (a new one: opaque, coloured by the map).
    fn apply_surfaces(&self, state: &mut ViewState, from_file: bool) -> Result<(), OverrideError> {
        let mut surfaces = state.surfaces();
        if let Some(IsoValues(values)) = &self.iso {
            if values.len() > MAX_ISO_SURFACES {
                return Err(OverrideError::TooMany {
                    flag: "iso",
                    most: MAX_ISO_SURFACES,
                    found: values.len(),
                });
            }
            surfaces = values
                .iter()
                .enumerate()
                .map(|(i, &value)| IsoSurface {
                    value,
                    ..surfaces.get(i).copied().unwrap_or(IsoSurface {
                        value,
                        opacity: 1.0,
                        colour: None,
                    })
                })
                .collect();
        }
        for (flag, found) in [
            ("iso-opacity", self.iso_opacity.len()),
            ("iso-colour", self.iso_colour.len()),
        ] {
            if found > surfaces.len() {
                return Err(OverrideError::TooMany {
                    flag,
                    most: surfaces.len(),
                    found,
                });
            }
        }
        for (s, &a) in surfaces.iter_mut().zip(&self.iso_opacity) {
            if !(a > 0.0 && a <= 1.0) {
                return Err(OverrideError::Opacity(a));
            }
            s.opacity = a;
        }
        for (s, c) in surfaces.iter_mut().zip(&self.iso_colour) {
            s.colour = match c {
                SurfaceColour::Map => None,
                SurfaceColour::Fixed(c) => Some(*c),
            };
        }
        if let Some((first, _)) = surfaces.split_first() {
            if self.iso.is_some() {
                // A state file's band is the user's; a new view's follows the iso value.
                let iso = ViewCommand::Iso {
                    value: first.value,
                    band_follows: !from_file,
                };
                // Setting the iso value names no field: it cannot fail.
                let _ = state.apply(&iso, &[]);
            }
            state.iso_opacity = first.opacity;
            state.iso_colour = first.colour;
            state.more_isos = surfaces[1..].to_vec();
        }
        Ok(())
    }

    /// `--clip` and `--slice` with their options: given, they replace the state's.
    fn apply_planes(&self, state: &mut ViewState) -> Result<(), OverrideError> {
        for (flag, most, found) in [
            ("clip", MAX_CLIP_PLANES, self.clip.len()),
            ("slice", MAX_SLICES, self.slices.len()),
        ] {
            if found > most {
                return Err(OverrideError::TooMany { flag, most, found });
            }
        }
        if !self.clip.is_empty() {
            state.clip = self.clip.clone();
        }
        if let Some(a) = self.slice_opacity {
            if !(a > 0.0 && a <= 1.0) {
                return Err(OverrideError::SliceOpacity(a));
            }
        }
        if !self.slices.is_empty() {
            state.slices = self.slices.iter().map(|p| Slice::new(*p)).collect();
        }
        for s in &mut state.slices {
            if let Some(a) = self.slice_opacity {
                s.opacity = a;
            }
            s.contours |= self.slice_contours;
            s.clip |= self.slice_clip;
        }
        Ok(())
    }

    /// Whether the flags place the camera (`--eye`, `--look-at`, `--up`, `--ortho`):
    /// without them and without a state file, a new view frames the iso surface the
    /// flags chose ([`ViewState::frame_surface`]) for the image size they chose.
    pub fn places_camera(&self) -> bool {
        self.eye.is_some() || self.look_at.is_some() || self.up.is_some() || self.ortho.is_some()
    }

    /// Whether the flags give the camera's whole pose (`--eye`, `--look-at` and `--up`),
    /// so that nothing of a framed camera but its projection would be left.
    pub fn places_whole_camera(&self) -> bool {
        self.eye.is_some() && self.look_at.is_some() && self.up.is_some()
    }

    /// Applies `--iso-field` and `--colour-field` against the fields the data has
    /// (`fields`: their ranges, a sequence's ranges for a sequence), after
    /// [`Overrides::apply`], as [`ViewCommand::IsoField`] and [`ViewCommand::ColourField`]:
    /// a field that changes gets a fresh start from its range (the iso value unless
    /// `--iso` was given). An unknown name is an error naming the flag and listing the
    /// fields.
    pub fn apply_fields(
        &self,
        state: &mut ViewState,
        fields: &[FieldRange],
    ) -> Result<(), UnknownField> {
        if let Some(name) = &self.iso_field {
            let command = ViewCommand::IsoField {
                name: name.clone(),
                keep_iso: self.iso.is_some(),
            };
            state
                .apply(&command, fields)
                .map_err(|e| e.named_by("--iso-field"))?;
        }
        if let Some(name) = &self.colour_field {
            let command = ViewCommand::ColourField { name: name.clone() };
            state
                .apply(&command, fields)
                .map_err(|e| e.named_by("--colour-field"))?;
        }
        let range = match self.colour_range {
            Some(ColourRange::Values(lo, hi)) => Some((lo, hi)),
            _ => None,
        };
        if let Some(command) = self.colour_scale(range) {
            // Names no field: cannot fail.
            let _ = state.apply(&command, fields);
        }
        if let Some(o) = self.overlays {
            let _ = state.apply(&ViewCommand::Overlays(o), fields);
        }
        Ok(())
    }

    /// The colour map the colour flags ask for, over `range` (`None`: the map's current
    /// range); `None` when no colour flag was given. `--colour-range`, `--colour-centre`
    /// and `--log` without `--colormap` rebuild the default `speed` map.
    pub fn colour_scale(&self, range: Option<(f32, f32)>) -> Option<ViewCommand> {
        let asked = self.colormap.is_some()
            || self.colour_range.is_some()
            || self.colour_centre.is_some()
            || self.log;
        asked.then(|| ViewCommand::ColourScale {
            palette: self.colormap.unwrap_or(PaletteSpec {
                palette: Palette::Speed,
                reversed: false,
            }),
            range,
            centre: self.colour_centre,
            log: self.log,
        })
    }

    /// Whether the colour map's range is to be taken from a first picture
    /// (`--colour-range visible`).
    pub fn wants_visible_range(&self) -> bool {
        self.colour_range == Some(ColourRange::Visible)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colormap::ColorMap;
    use crate::view_state::tests::fields;

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
            iso: iso.map(IsoValues::from),
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

    /// `--colormap`, `--colour-range`, `--colour-centre`, `--log` and `--overlays` reach
    /// the state through the flags, keeping the colour field.
    #[test]
    fn colour_flags_rebuild_the_map_and_overlays_are_set() {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            view: Overrides,
        }
        let fields = fields();
        let run = |args: &[&str]| {
            let cli = Cli::try_parse_from(std::iter::once("x").chain(args.iter().copied()))
                .map_err(|e| e.to_string())?;
            let mut s = ViewState::default_for([0.0; 3], [1.0; 3], &fields);
            cli.view.apply(&mut s, false).map_err(|e| e.to_string())?;
            cli.view
                .apply_fields(&mut s, &fields)
                .map_err(|e| e.to_string())?;
            Ok::<_, String>((s, cli.view))
        };
        let (plain, _) = run(&[]).expect("no flags");
        let field = plain.colormap.field.clone();
        let (s, _) = run(&["--colormap", "viridis", "--colour-range", "0.5,2"]).expect("viridis");
        assert_eq!(s.colormap.field, field);
        assert_eq!(s.colormap.range(), (0.5, 2.0));
        assert_ne!(s.colormap.points, plain.colormap.points);
        // Reversed: the same colours the other way round.
        let (r, _) = run(&["--colormap", "viridis_r", "--colour-range", "0.5,2"]).expect("_r");
        assert_eq!(
            r.colormap.points.first().map(|p| p.colour),
            s.colormap.points.last().map(|p| p.colour)
        );
        // A diverging map centred on a value is symmetric around it.
        let (d, _) = run(&[
            "--colormap",
            "coolwarm",
            "--colour-range=-1,3",
            "--colour-centre=0",
        ])
        .expect("coolwarm");
        assert_eq!(d.colormap.range(), (-3.0, 3.0));
        // Log spacing: the middle point is the geometric mean.
        let (l, _) =
            run(&["--colormap", "magma", "--colour-range", "0.01,100", "--log"]).expect("log");
        let mid = l.colormap.points[l.colormap.points.len() / 2].value;
        assert!((mid - 1.0).abs() < 1e-3, "{mid}");
        // Overlays.
        let (o, _) = run(&["--overlays", "legend,title"]).expect("overlays");
        assert!(o.overlays.legend && o.overlays.title && !o.overlays.axes);
        let (n, _) = run(&["--overlays", "none"]).expect("none");
        assert!(!n.overlays.any());
        assert_eq!(plain.overlays, Overlays::default());
        // `visible` asks for a first picture and keeps the map until then.
        let (v, view) = run(&["--colour-range", "visible"]).expect("visible");
        assert!(view.wants_visible_range());
        assert_eq!(v.colormap.range(), plain.colormap.range());
        for bad in [
            &["--colour-range", "2,1"][..],
            &["--colour-range", "nan,1"],
            &["--colour-range", "1"],
            &["--colormap", "jet"],
            &["--overlays", "legend,grid"],
        ] {
            let e = run(bad).expect_err("refused");
            assert!(e.contains(bad[0]) && e.contains("expected"), "{e}");
        }
    }

    /// Issue 27: the cutting flags build the surfaces and planes, round-trip through the
    /// state's JSON, and refuse what is out of bounds naming the flag.
    #[test]
    fn surfaces_and_planes_from_flags() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            view: Overrides,
        }
        use clap::Parser;
        let fields = crate::view_state::tests::fields();
        let run = |args: &[&str]| {
            let cli = Cli::try_parse_from(std::iter::once("x").chain(args.iter().copied()))
                .map_err(|e| e.to_string())?;
            let mut s = ViewState::default_for([0.0; 3], [1.0; 3], &fields);
            cli.view.apply(&mut s, false).map_err(|e| e.to_string())?;
            s.validate().map_err(|e| e.to_string())?;
            Ok::<_, String>(s)
        };
        let s = run(&[
            "--iso",
            "0.1,0.02,-0.5",
            "--iso-opacity",
            "1,0.3",
            "--iso-colour",
            "map,#ff8000",
            "--clip",
            "x>1.5",
            "--clip",
            "0,0,0:0,0,-2",
            "--slice",
            "z>0",
            "--slice",
            "1,2,3:1,1,0",
            "--slice-opacity",
            "0.5",
            "--slice-contours",
            "--slice-clip",
        ])
        .expect("valid");
        assert_eq!(s.iso, 0.1);
        assert!(
            (s.transfer.sigma - 0.008).abs() < 1e-12,
            "the band follows --iso"
        );
        let surfaces = s.surfaces();
        assert_eq!(surfaces.len(), 3);
        assert_eq!(
            surfaces
                .iter()
                .map(|s| (s.value, s.opacity))
                .collect::<Vec<_>>(),
            [(0.1, 1.0), (0.02, 0.3), (-0.5, 1.0)]
        );
        assert_eq!(surfaces[0].colour, None);
        assert_eq!(surfaces[1].colour, Some([1.0, 128.0 / 255.0, 0.0]));
        assert_eq!(s.clip.len(), 2);
        assert_eq!(s.clip[1].unit_normal(), [0.0, 0.0, -1.0]);
        assert_eq!(s.slices.len(), 2);
        assert!(s
            .slices
            .iter()
            .all(|l| l.opacity == 0.5 && l.contours && l.clip));
        // The state file holds all of it and reads back the same.
        let back =
            ViewState::from_json(std::path::Path::new("s.json"), &s.to_json()).expect("round trip");
        assert_eq!(back, s);
        // A state without any of it writes none of the new keys (files stay as they were).
        let plain = run(&[]).expect("plain");
        let json = plain.to_json();
        for key in ["iso_opacity", "iso_colour", "more_isos", "clip", "slices"] {
            assert!(!json.contains(&format!("\"{key}\"")), "{key} in {json}");
        }
        // --iso-opacity alone styles the state's surfaces.
        let o = run(&["--iso-opacity", "0.5"]).expect("opacity");
        assert_eq!((o.iso, o.iso_opacity), (plain.iso, 0.5));
        let seven_clips: Vec<&str> = ["--clip", "x>0"].repeat(7);
        for (bad, want) in [
            (&["--iso", "1,2,3,4,5,6,7,8,9"][..], "--iso"),
            (&["--iso", "1,nan"], "--iso"),
            (
                &["--iso", "1", "--iso-opacity", "1,1"],
                "--iso-opacity: expected at most 1",
            ),
            (&["--iso-opacity", "0"], "--iso-opacity"),
            (&["--iso-colour", "red"], "--iso-colour"),
            (&["--clip", "w>1"], "--clip"),
            (&["--slice", "0,0,0:0,0,0"], "--slice"),
            (
                &["--slice", "z>0", "--slice-opacity", "1.5"],
                "--slice-opacity",
            ),
            (&seven_clips, "--clip: expected at most 6"),
        ] {
            let e = run(bad).expect_err("refused");
            assert!(e.contains(want), "{bad:?}: {e}");
        }
    }
}
