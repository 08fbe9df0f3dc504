//! The interactive window: an eframe/egui front end on the render core.
//!
//! The window owns a [`ViewState`](crate::view_state::ViewState) — every control in the
//! side panel edits one of its fields — and hands each new state to the
//! [`Progressive`](crate::progressive::Progressive) renderer, which renders off the UI
//! thread and answers with ever better images. Saving the state from the window and
//! rendering it with `qbricks-view render --state` gives the same pixels.
//!
//! Only this folder knows about egui; the render core does not.
//!
//! One file per concern: `viewer` is the window and the one place that handles what the
//! panel asks for (`command`); `document` the open data, `view` the window's own view
//! settings, `frames` the renderer and its images, `background` the work the window
//! does beside drawing (opening a file, `framing` the camera to the surface), `dialogs` the file dialogs, `picking`
//! the values under the cursor, `history` undo and redo of the view, `keys` the table of
//! key and mouse bindings; `menu`, `panel` (with its `surfaces` and `cuts`), `canvas`,
//! `status`, `help` and `widgets` draw; the rest (`navigation`, `player`, `script`, `options`) is state and rules without
//! egui where it can be.

mod background;
mod canvas;
mod command;
mod cuts;
mod dialogs;
mod document;
mod frames;
mod framing;
mod help;
mod history;
mod keys;
mod menu;
mod navigation;
mod options;
mod panel;
mod picking;
mod player;
mod script;
mod status;
mod surfaces;
#[cfg(test)]
mod tests;
mod view;
mod viewer;
mod widgets;

use std::sync::{Arc, Mutex};

pub use navigation::{orbit, pan};
pub use options::WindowOptions;
pub use script::{OrbitReport, Script};
pub use viewer::ViewerApp;

/// Opens the window and runs until it is closed (or the script is done). Returns the
/// script's report, if one ran.
pub fn run(options: WindowOptions) -> anyhow::Result<Option<OrbitReport>> {
    let size = options.size;
    let native = eframe::NativeOptions {
        viewport: eframe::egui::ViewportBuilder::default()
            .with_inner_size(size)
            .with_title("qbricks")
            .with_drag_and_drop(true),
        ..Default::default()
    };
    let outcome: Arc<Mutex<Option<anyhow::Result<Option<OrbitReport>>>>> = Arc::default();
    let out = Arc::clone(&outcome);
    eframe::run_native(
        "qbricks",
        native,
        Box::new(move |cc| {
            let app = ViewerApp::new(cc.egui_ctx.clone(), options, out)?;
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| anyhow::anyhow!("window: {e}"))?;
    let result = outcome.lock().map(|mut g| g.take()).unwrap_or(None);
    result.unwrap_or(Ok(None))
}
