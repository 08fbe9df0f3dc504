//! The window's file dialog and what it was opened for.

use std::path::PathBuf;

use eframe::egui;
use egui_file_dialog::FileDialog;

/// What a file dialog was opened for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum DialogPurpose {
    OpenFile,
    SavePng,
    SaveState,
    LoadState,
    AddMesh,
}

/// The one file dialog of the window.
pub(crate) struct Dialogs {
    dialog: FileDialog,
    purpose: Option<DialogPurpose>,
}

impl Dialogs {
    pub(crate) fn new() -> Dialogs {
        Dialogs {
            dialog: FileDialog::new(),
            purpose: None,
        }
    }

    /// Opens the dialog for `purpose` (a save dialog for the outputs).
    pub(crate) fn open(&mut self, purpose: DialogPurpose) {
        self.purpose = Some(purpose);
        match purpose {
            DialogPurpose::SavePng | DialogPurpose::SaveState => self.dialog.save_file(),
            _ => self.dialog.pick_file(),
        }
    }

    /// Draws the dialog; the file picked in it this frame, with what it was for.
    pub(crate) fn update(&mut self, ctx: &egui::Context) -> Option<(DialogPurpose, PathBuf)> {
        self.dialog.update(ctx);
        let path = self.dialog.take_picked()?;
        Some((self.purpose.take()?, path))
    }
}
