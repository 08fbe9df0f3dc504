//! An opened `.qbk` file together with the ray caster's view of it, owned as one value.
//!
//! [`Volume`] borrows its field values from the memory-mapped archive (zero copy). The
//! window renders on worker threads that outlive any one UI frame, so it needs the file
//! and its volume in one owned, shareable value: `Arc<Dataset>`. `self_cell` keeps the
//! borrowing volume next to the view it borrows from.

use std::path::{Path, PathBuf};
use std::time::Instant;

use format::{BrickFileView, FormatError, OpenOptions};

use crate::volume::{Volume, VolumeError};

self_cell::self_cell!(
    struct Cell {
        owner: BrickFileView,
        #[covariant]
        dependent: Volume,
    }
);

/// Why a file could not be opened for viewing.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error(transparent)]
    Format(#[from] FormatError),
    #[error("{}: {error}", path.display())]
    Volume { path: PathBuf, error: VolumeError },
}

/// A validated, memory-mapped `.qbk` file and its volume.
pub struct Dataset {
    cell: Cell,
    /// Time to open, validate and build the volume tables, ms.
    pub open_ms: f64,
}

// Render threads share one dataset.
const _: fn() = || {
    fn shared<T: Send + Sync>() {}
    shared::<Dataset>();
};

impl Dataset {
    /// Opens, validates (checksum included) and prepares `path` for rendering.
    pub fn open(path: &Path) -> Result<Dataset, OpenError> {
        Self::open_with(path, &OpenOptions::default())
    }

    pub fn open_with(path: &Path, options: &OpenOptions) -> Result<Dataset, OpenError> {
        let t = Instant::now();
        let view = BrickFileView::open_with(path, options)?;
        Self::from_view(view, t)
    }

    /// Wraps an already opened view (e.g. one read into memory by a test).
    pub fn from_view(view: BrickFileView, started: Instant) -> Result<Dataset, OpenError> {
        let path = view.path().to_path_buf();
        let cell = Cell::try_new(view, |v| Volume::new(v))
            .map_err(|error| OpenError::Volume { path, error })?;
        Ok(Dataset {
            cell,
            open_ms: started.elapsed().as_secs_f64() * 1e3,
        })
    }

    pub fn volume(&self) -> &Volume<'_> {
        self.cell.borrow_dependent()
    }

    pub fn view(&self) -> &BrickFileView {
        self.cell.borrow_owner()
    }
}
