//! The open data: a file (or the current frame of a sequence), what the panel shows about
//! it, the field ranges the view's rules use, and the files a save must not overwrite.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use format::sequence::FieldRange;

use super::background::{Pending, Poll};
use super::player::Player;
use crate::dataset::Dataset;
use crate::mesh::MeshInstance;

/// The bundled sample, opened when no file is given.
pub(crate) const DEFAULT_FILE: &str = "data/wake_small.qbk";

/// An open file and what the panel shows about it.
pub(crate) struct Doc {
    pub dataset: Arc<Dataset>,
    pub path: PathBuf,
    pub cells: u64,
    pub bricks: usize,
    pub regions: usize,
    /// Per field: name, range and histogram (bins over `min..=max`).
    pub fields: Vec<FieldSummary>,
    /// The payload checksum, verified on a thread of its own while the window frames and
    /// renders the file (see [`Checksum`]).
    pub checksum: Checksum,
}

/// Where the window's check of a file's checksum is: it reads every byte (seconds for a
/// large file whose pages are not cached), so it starts once the camera is framed (a
/// hash beside the fit slowed the fit by 15 % on a billion warm cells) and runs beside
/// the first frames, on one core below their priority; a file that fails is refused once
/// it is known (its error shown, nothing more rendered or saved), and a scripted run
/// writes nothing before it passed.
pub(crate) enum Checksum {
    /// Not started: the camera is being framed.
    Waiting,
    Pending(Pending<Result<(), String>>),
    Passed,
    Failed(String),
}

impl Checksum {
    /// Starts the hash of `dataset`'s payload if it has not started.
    pub(crate) fn start(&mut self, dataset: &Arc<Dataset>) {
        if !matches!(self, Checksum::Waiting) {
            return;
        }
        let hashed = Arc::clone(dataset);
        *self = Checksum::Pending(Pending::start("qbricks-checksum", move || {
            crate::render::lower_priority();
            hashed.view().verify_checksum().map_err(|e| e.to_string())
        }));
    }

    /// Takes the result if it has come.
    pub(crate) fn poll(&mut self) {
        if let Checksum::Pending(job) = self {
            match job.poll() {
                Poll::Pending => {}
                Poll::Done(Ok(())) => *self = Checksum::Passed,
                Poll::Done(Err(e)) => *self = Checksum::Failed(e),
                Poll::Failed => *self = Checksum::Failed("the checksum failed to run".into()),
            }
        }
    }
}

pub(crate) struct FieldSummary {
    pub name: String,
    pub min: f32,
    pub max: f32,
    pub histogram: Vec<u64>,
}

/// A file being opened off the UI thread (see `background`).
pub(crate) struct Opening {
    pub path: PathBuf,
    pub job: Pending<Result<Doc, String>>,
    /// The window's own first file: its error is the startup error, and `state` (the
    /// `--state` file) is loaded once it is open.
    pub startup: bool,
    pub state: Option<PathBuf>,
    /// A frame of the sequence shown: it keeps the view.
    pub frame: bool,
}

impl Opening {
    /// Opens a file, its checksum verified once its camera is framed.
    pub(crate) fn start(path: &Path) -> Opening {
        Self::open(path, false)
    }

    /// Opens a frame of a sequence, its checksum verified as it opens: playback steps on
    /// once a frame is shown, and hashes left running behind it would pile up.
    pub(crate) fn start_frame(path: &Path) -> Opening {
        Self::open(path, true)
    }

    fn open(path: &Path, frame: bool) -> Opening {
        let p = path.to_path_buf();
        Opening {
            path: path.to_path_buf(),
            job: Pending::start("qbricks-open", move || Doc::open(&p, frame)),
            startup: false,
            state: None,
            frame,
        }
    }
}

impl Doc {
    /// Opens, validates and summarises `path`; the error is one line naming the file.
    /// `checksum_now`: verify the checksum as it opens, else leave it [`Checksum::Waiting`].
    pub(crate) fn open(path: &Path, checksum_now: bool) -> Result<Doc, String> {
        // As every render opens: the structure checked where frames read it, and the
        // checksum, but for a sequence's frames, beside the first frames, so that a
        // billion cells open as fast as a thousand.
        let dataset = Arc::new(
            Dataset::open_with(path, &crate::dataset::render_options(checksum_now))
                .map_err(|e| e.to_string())?,
        );
        let checksum = if checksum_now {
            Checksum::Passed
        } else {
            Checksum::Waiting
        };
        let file = dataset.view().file();
        let cells = file.levels.iter().map(|l| l.cells.to_native()).sum();
        let fields = file
            .fields
            .iter()
            .map(|f| FieldSummary {
                name: f.name.to_string(),
                min: f.min.to_native(),
                max: f.max.to_native(),
                histogram: f.histogram.iter().map(|c| c.to_native()).collect(),
            })
            .collect();
        Ok(Doc {
            bricks: file.bricks.len(),
            regions: file.regions.len(),
            cells,
            fields,
            path: path.to_path_buf(),
            dataset,
            checksum,
        })
    }

    /// Why the file is refused after it opened: its checksum failed, or a part its frames
    /// read failed its check (the message an open that checked everything gives).
    pub(crate) fn failure(&self) -> Option<String> {
        if let Checksum::Failed(e) = &self.checksum {
            return Some(e.clone());
        }
        let e = self.dataset.volume().check_structure(&self.path).err()?;
        Some(e.to_string())
    }

    /// Whether the checksum is still to be verified.
    pub(crate) fn checksum_pending(&self) -> bool {
        matches!(self.checksum, Checksum::Waiting | Checksum::Pending(_))
    }

    pub(crate) fn field(&self, name: &str) -> Option<&FieldSummary> {
        self.fields.iter().find(|f| f.name == name)
    }
}

/// The message for an OpenVDB file the window was asked to open: the window reads baked
/// `.qbk` files only (the VDB reader is not linked into it), so say how to bake it.
/// `None` for any other file.
pub(crate) fn bake_hint(path: &Path) -> Option<String> {
    let ext = path.extension()?.to_str()?;
    if !ext.eq_ignore_ascii_case("vdb") {
        return None;
    }
    let out = path.with_extension("qbk");
    Some(format!(
        "{}: an OpenVDB file; the window opens baked .qbk files. Bake it first with \
         `qbricks-bake bake {} -o {}`, then open {}",
        path.display(),
        shell_word(path),
        shell_word(&out),
        out.display()
    ))
}

/// `path` as one word of a shell command line: quoted when it holds anything but
/// letters, digits and `_./-+,=:@`.
fn shell_word(path: &Path) -> String {
    let s = path.to_string_lossy();
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "_./-+,=:@".contains(c));
    if plain {
        s.into_owned()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// What the window has open.
#[derive(Default)]
pub(crate) struct Document {
    /// The file shown (a sequence's current frame), if one opened.
    pub doc: Option<Doc>,
    /// The fields and ranges the view's rules use ([`crate::view_state::ViewCommand`]):
    /// the open file's, or a whole sequence's, as `render` uses them, so that choosing a
    /// field in the window starts where `--iso-field` starts.
    pub ranges: Vec<FieldRange>,
    /// The view state file loaded last (an input: saves must not overwrite it).
    pub state_file: Option<PathBuf>,
}

impl Document {
    /// Refuses to save over a file the window reads: the open file (every frame of an open
    /// `sequence`), the view state it loaded, the `meshes` (shown or hidden). The same
    /// guard every command's outputs go through.
    pub(crate) fn check_output<'m>(
        &self,
        sequence: Option<&Player>,
        meshes: impl Iterator<Item = &'m MeshInstance>,
        role: &str,
        path: &Path,
    ) -> Result<(), String> {
        let mut guard = files::guard::Guard::new();
        if let Some(doc) = &self.doc {
            guard.input("open file", &doc.path);
        }
        if let Some(p) = sequence {
            for (f, path) in &p.frames {
                guard.input(format!("frame {f}"), path);
            }
        }
        if let Some(s) = &self.state_file {
            guard.input("view state", s);
        }
        for m in meshes {
            guard.input("mesh", &m.path);
        }
        guard.output(role, path);
        guard.check().map_err(|e| e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vdb_file_gets_the_command_that_bakes_it() {
        let hint = bake_hint(Path::new("data/wake_small.vdb")).expect("a hint");
        assert!(
            hint.contains("`qbricks-bake bake data/wake_small.vdb -o data/wake_small.qbk`"),
            "{hint}"
        );
        let hint = bake_hint(Path::new("my runs/frame_####.VDB")).expect("a hint");
        assert!(
            hint.contains(
                "`qbricks-bake bake 'my runs/frame_####.VDB' -o 'my runs/frame_####.qbk'`"
            ),
            "{hint}"
        );
        assert!(bake_hint(Path::new("a.qbk")).is_none());
        assert_eq!(shell_word(Path::new("it's")), r"'it'\''s'");
    }
}
