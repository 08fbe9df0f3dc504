//! How the window starts.

use std::path::PathBuf;

use super::script::Script;

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
