//! The view one picture of one file draws, made the same way by every command that
//! renders a file from a state and flags (`qbricks-view render`, the Python module): a
//! picture from Python equals the CLI's because both go through here.

use std::path::{Path, PathBuf};

use super::{InvalidViewState, OverrideError, Overrides, UnknownField, ViewState};
use crate::mesh::Meshes;
use crate::render::Renderer;
use crate::volume::Volume;

/// A view state ready to render, with what the user should be told about it.
#[derive(Debug)]
pub struct ResolvedView {
    pub state: ViewState,
    /// Notes on the flags (e.g. a flag the state made moot).
    pub notes: Vec<String>,
    /// Warnings on the view (an iso value outside its field's range).
    pub warnings: Vec<String>,
}

/// Why a state and flags make no view of a file.
#[derive(Debug, thiserror::Error)]
pub enum ResolveError {
    #[error(transparent)]
    Override(#[from] OverrideError),
    /// `--iso-field` or `--colour-field` names no field of `file`.
    #[error("{}: {error}", file.display())]
    Field { file: PathBuf, error: UnknownField },
    #[error("view state: {0}")]
    Invalid(#[from] InvalidViewState),
    /// The picture would not fit in memory.
    #[error(transparent)]
    Limit(#[from] files::limits::LimitError),
}

impl Overrides {
    /// The view of `vol` (the file `file`) these flags ask for over `given` (a loaded
    /// state) or, without one, over the data's defaults — which are then framed on the
    /// surface the flags chose unless the flags place the camera. Validated, and refused
    /// when its picture would not fit in memory.
    pub fn resolve(
        &self,
        vol: &Volume,
        file: &Path,
        given: Option<ViewState>,
    ) -> Result<ResolvedView, ResolveError> {
        let from_file = given.is_some();
        let mut state = match given {
            Some(state) => state,
            // Framing reads the cells near the surface, which on a large file is most of
            // the set-up: it is done once, below, for the flags' own iso value, field and
            // size. Only a camera the flags place in part (`--up` alone, say) starts from
            // the defaults' framing; one placed in full needs none.
            None if self.places_camera() && !self.places_whole_camera() => {
                ViewState::default_for_volume(vol)
            }
            None => ViewState::default_unframed(vol),
        };
        let notes = self.apply(&mut state, from_file)?;
        self.apply_fields(&mut state, &vol.fields)
            .map_err(|error| ResolveError::Field {
                file: file.to_path_buf(),
                error,
            })?;
        if !from_file && !self.places_camera() {
            // The flags may have chosen another iso value, field or image size than the
            // defaults were framed for.
            state.frame_surface(vol);
        }
        state.validate()?;
        crate::film::check_frame_memory(state.width, state.height, 1)?;
        let warnings = state.iso_outside_range(&vol.fields).into_iter().collect();
        Ok(ResolvedView {
            state,
            notes,
            warnings,
        })
    }

    /// `--colour-range visible`: spreads the colour map over the colour field's values on
    /// the surfaces a first picture of `state` shows (nothing without that flag). Returns
    /// a note for the user when no surface shows, so the map keeps the field's range.
    pub fn fit_visible_colours(
        &self,
        renderer: &Renderer,
        vol: &Volume,
        state: &mut ViewState,
        meshes: &Meshes,
    ) -> Result<Option<String>, UnknownField> {
        if !self.wants_visible_range() {
            return Ok(None);
        }
        let range =
            renderer.fit_colours_to_visible(vol, state, meshes, |r| self.colour_scale(r))?;
        Ok(no_surface_note(range))
    }

    /// [`Overrides::fit_visible_colours`] from `frame`, a picture of
    /// [`crate::render::visible_range_view`] rendered elsewhere (over MPI ranks); `None`
    /// (nothing to fit) without the flag.
    pub fn fit_visible_colours_to(
        &self,
        frame: &crate::render::Frame,
        vol: &Volume,
        state: &mut ViewState,
    ) -> Result<Option<String>, UnknownField> {
        if !self.wants_visible_range() {
            return Ok(None);
        }
        let range =
            crate::render::fit_colours_to_frame(frame, vol, state, |r| self.colour_scale(r))?;
        Ok(no_surface_note(range))
    }
}

/// The note `--colour-range visible` leaves when no surface shows.
fn no_surface_note(range: Option<(f32, f32)>) -> Option<String> {
    range.is_none().then(|| {
        "--colour-range visible: no surface in the picture; the colour map keeps the field's \
         range"
            .to_string()
    })
}
