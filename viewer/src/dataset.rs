//! An opened `.qbk` file together with the ray caster's view of it, owned as one value.
//!
//! [`Volume`] borrows its field values from the memory-mapped archive (zero copy). The
//! window renders on worker threads that outlive any one UI frame, so it needs the file
//! and its volume in one owned, shareable value: `Arc<Dataset>`. `self_cell` keeps the
//! borrowing volume next to the view it borrows from.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use format::{BrickFileView, FormatError, OpenOptions};

use crate::accel::AccelCache;
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

/// How every command that renders opens its files: the checksum verified or not as asked,
/// and the bricks, regions and KD-tree checked where a frame first reads them
/// ([`format::Structure::OnUse`], see [`Volume::structure_error`]), so that opening costs
/// the same for a billion cells as for a thousand. A command reports a part that failed
/// after its frame ([`Volume::check_structure`]).
pub fn render_options(verify_checksum: bool) -> OpenOptions {
    OpenOptions {
        verify_checksum,
        structure: format::Structure::OnUse,
    }
}

/// Runs `work` while the checksum of `view` is verified on a thread of its own (when
/// `verify`, and not verified at open already): a command that opens a file without the
/// checksum and hands this the frames it renders costs the larger of hash and frames, not
/// their sum, and opening costs the same at any size. `work` must write nothing: its
/// result is returned only when the checksum matches, else the checksum's error (the one
/// an open with the checksum gives), so a damaged file gives no output.
pub fn beside_checksum<R, E: From<format::FormatError>>(
    view: &BrickFileView,
    verify: bool,
    work: impl FnOnce() -> Result<R, E>,
) -> Result<R, E> {
    if !verify || view.checksum_verified() {
        return work();
    }
    std::thread::scope(|s| {
        // One core, below the frames' priority: the frames are what the user waits for.
        let sum = std::thread::Builder::new()
            .name("qbricks-checksum".to_string())
            .spawn_scoped(s, || {
                crate::render::lower_priority();
                view.verify_checksum()
            });
        let out = work();
        let checked = match sum {
            Ok(handle) => handle.join().unwrap_or_else(|_| view.verify_checksum()),
            // No thread to be had: verify here.
            Err(_) => view.verify_checksum(),
        };
        checked?;
        out
    })
}

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

/// The accelerations of the recent views of one dataset ([`AccelCache`]), for a thread
/// that is handed views of whatever dataset is open (the window's render thread, its
/// picks): a view of another dataset starts the cache over. Holding the dataset keeps
/// the identity check sound (a dropped dataset's address could be reused).
#[derive(Default)]
pub(crate) struct DatasetAccels {
    dataset: Option<Arc<Dataset>>,
    cache: AccelCache,
}

impl DatasetAccels {
    /// Whether the accelerations held are `dataset`'s.
    pub(crate) fn holds(&self, dataset: &Arc<Dataset>) -> bool {
        self.dataset
            .as_ref()
            .is_some_and(|d| Arc::ptr_eq(d, dataset))
    }

    /// The cache of `dataset`'s volume: the kept one if it is the same dataset, else a
    /// new one.
    pub(crate) fn of(&mut self, dataset: &Arc<Dataset>) -> &mut AccelCache {
        if !self.holds(dataset) {
            self.cache.clear();
            self.dataset = Some(Arc::clone(dataset));
        }
        &mut self.cache
    }
}
