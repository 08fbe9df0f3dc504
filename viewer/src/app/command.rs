//! What the window's panel asks for: the changes that are more than setting one value,
//! handled in one place ([`super::ViewerApp`]'s `handle`). Plain settings (a step, a
//! colour, a checkbox) the panel edits in place.

use super::dialogs::DialogPurpose;
use crate::view_state::ViewCommand;

/// A request of the panel (or a key) to the window.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum AppCommand {
    /// A change to the view that follows a rule: an iso or colour field, an iso value.
    /// The same rules as the command line's flags ([`crate::view_state::ViewState::apply`]).
    View(ViewCommand),
    /// Frame the whole data set (and put the lights back for the new camera).
    FrameData,
    /// Frame the iso surface of the view, as a new view is framed (the whole data when
    /// there is none).
    FrameSurface,
    /// Spread the colour map (the panel's preset) over the colour field's values on the
    /// surfaces of the finished picture (`--colour-range visible`).
    FitColoursToVisible,
    /// Put the lights where the rig says for the current camera.
    Relight,
    /// Open the file dialog for this purpose.
    Dialog(DialogPurpose),
    /// Open the frame the sequence player points at.
    ShowFrame,
    /// Add the mesh typed into the panel (`PATH[@x,y,z,scale]`).
    AddMesh,
    /// Remove, switch off or switch on again the mesh at this index (of the view's
    /// meshes, or of the switched-off ones for `ShowMesh`).
    RemoveMesh(usize),
    HideMesh(usize),
    ShowMesh(usize),
    /// Add an iso-surface ([`crate::view_state::ViewState::add_surface`]), or remove the
    /// one at this index (0: the first).
    AddSurface,
    RemoveSurface(usize),
    /// Add a clip plane or slice through the pivot, across the axis the view looks along
    /// most ([`crate::planes::Plane::facing_view`]), or remove the one at this index.
    AddPlane(Cut),
    RemovePlane(Cut, usize),
    /// Go back to the view before the last change, or forward again to one undone
    /// (see [`super::history`]).
    Undo,
    Redo,
    /// Show or hide the list of keys and mouse bindings.
    Help,
}

/// Which list of planes a command is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Cut {
    /// `clip`: planes that keep the side their normal points to.
    Clip,
    /// `slices`: planes coloured by the colour field.
    Slice,
}
