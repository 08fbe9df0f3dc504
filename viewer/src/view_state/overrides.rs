//! Command-line flags that change a view state (`qbricks-view render` and the window),
//! and how they are applied.

use super::{default_iso, FieldRange, Mode, Strategy, ViewState};
use crate::camera::Projection;
use crate::colormap::ColorMap;
use crate::fields::UnknownField;
use crate::mesh::{MeshInstance, MeshSpecError};

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
    /// Iso value of the iso field.
    #[arg(long, allow_hyphen_values = true)]
    pub iso: Option<f64>,
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
}

/// A `--mesh`, `--eye`, `--look-at` or `--up` flag that does not parse.
#[derive(Debug, thiserror::Error)]
pub enum OverrideError {
    #[error("--mesh: {0}")]
    Mesh(MeshSpecError),
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
        if let Some(v) = self.iso {
            if from_file {
                state.iso = v;
            } else {
                state.set_iso(v);
            }
        }
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
    /// Applies `--iso-field` and `--colour-field` against the fields the data has
    /// (`fields`: their ranges, a sequence's ranges for a sequence), after
    /// [`Overrides::apply`]. A field that changes gets a fresh start from its range: the
    /// iso value (unless `--iso` was given) and band as [`default_iso`], the colour map's
    /// points as [`ColorMap::default_for_range`], since values meant for another field
    /// would show nothing useful. An unknown name is an error listing the fields.
    pub fn apply_fields(
        &self,
        state: &mut ViewState,
        fields: &[FieldRange],
    ) -> Result<(), UnknownField> {
        let find = |flag: &'static str, name: &str| {
            crate::fields::find(fields, name)
                .map(|(_, f)| f)
                .map_err(|e| e.named_by(flag))
        };
        if let Some(name) = &self.iso_field {
            let f = find("--iso-field", name)?;
            if *name != state.iso_field {
                state.iso_field = name.clone();
                let (iso, sigma) = default_iso(f);
                if self.iso.is_none() {
                    state.iso = iso;
                    state.transfer.sigma = sigma;
                }
            }
        }
        if let Some(name) = &self.colour_field {
            let f = find("--colour-field", name)?;
            if *name != state.colormap.field {
                state.colormap = ColorMap::default_for_range(name, f.min, f.max);
            }
        }
        Ok(())
    }
}
