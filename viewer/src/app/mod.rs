//! The interactive window: an eframe/egui front end on the render core.
//!
//! The window owns a [`ViewState`](crate::view_state::ViewState) — every control in the
//! side panel edits one of its fields — and hands each new state to the
//! [`Progressive`](crate::progressive::Progressive) renderer, which renders off the UI
//! thread and answers with ever better images. Saving the state from the window and
//! rendering it with `qbricks-view render --state` gives the same pixels.
//!
//! Only this folder knows about egui; the render core does not.

mod navigation;
mod panel;
mod player;
mod script;
mod viewer;
mod widgets;

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

pub use navigation::{orbit, pan};
pub use script::{OrbitReport, Script};
pub use viewer::ViewerApp;

/// How the window starts.
#[derive(Debug, Clone, Default)]
pub struct WindowOptions {
    /// `.qbk` file to open.
    pub file: Option<PathBuf>,
    /// View state to start from.
    pub state: Option<PathBuf>,
    /// Render threads (`None`: one per core).
    pub threads: Option<usize>,
    /// Inner window size in points.
    pub size: [f32; 2],
    /// What to do without a user, then exit.
    pub script: Option<Script>,
}

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
