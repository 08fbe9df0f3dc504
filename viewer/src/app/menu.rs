//! The menu bar: File, Edit (undo, redo; add a surface, a clip plane, a slice), Help. Each entry is an [`AppCommand`] the window handles
//! like the panel's, and shows the keys of the same command from [`super::keys`].

use eframe::egui::{self, Button};

use super::command::{AppCommand, Cut};
use super::cuts;
use super::dialogs::DialogPurpose;
use super::help;
use super::keys::{self, KeyAction};
use super::surfaces;

/// The File menu's entry that opens a file; the empty window's hint names it.
pub(crate) const OPEN: &str = "Open…";

/// What the menus need to know to draw their entries.
pub(crate) struct MenuState {
    pub can_undo: bool,
    pub can_redo: bool,
    /// A file (or frame) is open: there is something to save.
    pub has_data: bool,
    /// Below the library's limits (and, for surfaces, in iso mode).
    pub can_add_surface: bool,
    pub can_add_clip: bool,
    pub can_add_slice: bool,
}

/// Draws the menu bar; what was chosen in it.
pub(crate) fn show(m: &MenuState, ui: &mut egui::Ui) -> Vec<AppCommand> {
    let mut out = Vec::new();
    let ctx = ui.ctx().clone();
    egui::MenuBar::new().ui(ui, |ui| {
        ui.menu_button("File", |ui| {
            for (label, purpose, enabled) in [
                (OPEN, DialogPurpose::OpenFile, true),
                ("Save image…", DialogPurpose::SavePng, m.has_data),
                ("Save view…", DialogPurpose::SaveState, m.has_data),
                ("Load view…", DialogPurpose::LoadState, m.has_data),
                ("Add mesh…", DialogPurpose::AddMesh, true),
            ] {
                if ui.add_enabled(enabled, Button::new(label)).clicked() {
                    out.push(AppCommand::Dialog(purpose));
                }
            }
        });
        ui.menu_button("Edit", |ui| {
            for (label, action, enabled, command) in [
                ("Undo", KeyAction::Undo, m.can_undo, AppCommand::Undo),
                ("Redo", KeyAction::Redo, m.can_redo, AppCommand::Redo),
            ] {
                let b = Button::new(label).shortcut_text(keys::shortcut_text(&ctx, action));
                if ui.add_enabled(enabled, b).clicked() {
                    out.push(command);
                }
            }
            ui.separator();
            for (label, enabled, tip, command) in [
                (
                    "Add surface",
                    m.can_add_surface,
                    surfaces::ADD_TIP,
                    AppCommand::AddSurface,
                ),
                (
                    "Add clip plane",
                    m.can_add_clip,
                    cuts::ADD_CLIP_TIP,
                    AppCommand::AddPlane(Cut::Clip),
                ),
                (
                    "Add slice",
                    m.can_add_slice,
                    cuts::ADD_SLICE_TIP,
                    AppCommand::AddPlane(Cut::Slice),
                ),
            ] {
                if ui
                    .add_enabled(enabled, Button::new(label))
                    .on_hover_text(tip)
                    .clicked()
                {
                    out.push(command);
                }
            }
        });
        ui.menu_button("Help", |ui| {
            let b = Button::new(format!("{}…", help::TITLE))
                .shortcut_text(keys::shortcut_text(&ctx, KeyAction::Help));
            if ui.add(b).clicked() {
                out.push(AppCommand::Help);
            }
        });
        if ui
            .button("?")
            .on_hover_text(format!(
                "{} ({})",
                help::TITLE,
                keys::shortcut_text(&ctx, KeyAction::Help)
            ))
            .clicked()
        {
            out.push(AppCommand::Help);
        }
    });
    out
}
