//! The "?" overlay: every key and mouse binding of the window, printed from the tables the
//! key handling uses ([`super::keys`]).

use eframe::egui::{self, RichText};

use super::keys::{self, KEYS, MOUSE};

/// Title of the overlay (and of the Help menu's entry that opens it).
pub(crate) const TITLE: &str = "Keys and mouse";

/// Draws the overlay while `open`; its close button clears `open`.
pub(crate) fn show(ctx: &egui::Context, open: &mut bool) {
    egui::Window::new(TITLE)
        .open(open)
        .collapsible(false)
        .resizable(false)
        .anchor(egui::Align2::CENTER_CENTER, egui::Vec2::ZERO)
        .show(ctx, |ui| {
            egui::Grid::new("keys")
                .num_columns(2)
                .striped(true)
                .show(ui, |ui| {
                    for b in KEYS {
                        ui.label(RichText::new(keys::shortcut_name(ctx, &b.shortcut)).monospace());
                        ui.label(b.what);
                        ui.end_row();
                    }
                    for (gesture, _, what) in MOUSE {
                        ui.label(RichText::new(*gesture).monospace());
                        ui.label(*what);
                        ui.end_row();
                    }
                });
        });
}
