//! Opens and validates a `.qbk` file.
//!
//! [`BrickFileView::open`] memory-maps the file and, in this order, checks the header
//! (magic, version, flags, reserved bytes — see [`crate::header`]), the file length against
//! the header's payload length, the payload checksum (unless
//! [`OpenOptions::verify_checksum`] is off), rkyv's structural validation (bytecheck) and
//! the schema invariants ([`crate::validate`]): all of them, or with
//! [`Structure::OnUse`] only those that do not grow with the data, the reader then
//! checking each region and the KD-tree where it reads them (so that opening a billion
//! cells costs what opening a thousand does). Only then is the archived root handed out.
//! The validated reference is stored next to the mapping (a self-referential pair built
//! with `self_cell`), so [`BrickFileView::file`] costs nothing: callers can fetch
//! `&ArchivedBrickFile` once per frame, or per ray, without re-validating.
//!
//! # If the file changes while it is mapped
//!
//! The mapping shows the file's current contents; it is not a snapshot.
//! - `qbricks-bake` never modifies a `.qbk` in place: it writes a new file and renames it
//!   over the old one, so a running viewer keeps the old, complete, validated inode.
//! - If another process **truncates** the mapped file, any later read of a page past the
//!   new end raises `SIGBUS` and the process is killed. This cannot be caught safely in
//!   Rust, and the checksum (verified at open) cannot help after open. If files may be
//!   truncated or rewritten in place while viewed (network shares, other tools), copy the
//!   file first or open it with [`BrickFileView::open_in_memory`], which reads it into
//!   memory instead of mapping it.
//! - If another process **overwrites** bytes in place, reads see the new bytes; they were
//!   not validated, but all archive accesses in this crate are bounds-checked slices of
//!   the mapping, so the result is wrong numbers (or a panic on an index derived from
//!   them), never an access outside the mapping.

use std::path::{Path, PathBuf};

use memmap2::Mmap;
use rkyv::rancor;
use rkyv::util::AlignedVec;

use crate::error::{one_line, FormatError, FormatErrorKind};
use crate::header::{Header, HEADER_LEN, PAYLOAD_ALIGN};
use crate::schema::{ArchivedBrickFile, BrickFile};
use files::input::{map_read_only, read_whole, Limits};

/// Options for [`BrickFileView::open_with`].
#[derive(Debug, Clone)]
pub struct OpenOptions {
    /// Verify the payload checksum (reads every byte once at open). Validation of the
    /// archive always runs; skipping the checksum only saves the hashing of huge files.
    pub verify_checksum: bool,
    /// Where the schema invariants of the bricks, regions and KD-tree are checked.
    pub structure: Structure,
}

impl Default for OpenOptions {
    fn default() -> Self {
        Self {
            verify_checksum: true,
            structure: Structure::AtOpen,
        }
    }
}

/// Where a view's bricks, regions and KD-tree are checked against the schema's invariants
/// ([`crate::validate`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Structure {
    /// All of them at open ([`crate::validate::check`]): linear in the structure, about
    /// 10 ms for 134 M cells, 0.15 s (warm) to 1 s (cold) for a billion. A view opened so
    /// may be indexed directly anywhere.
    #[default]
    AtOpen,
    /// Only what does not grow with the data at open ([`crate::validate::check_top`]), so
    /// that opening costs the same for any size; the reader checks each region
    /// ([`crate::validate::check_region`], with its bricks) and the KD-tree
    /// ([`crate::validate::check_kd`]) before it indexes with them. The viewer's volume
    /// does (`viewer::volume::Volume`), once each.
    OnUse,
}

/// The bytes a view borrows from: a read-only map of the whole file, or an aligned copy
/// of the payload.
enum Backing {
    Mapped(Mmap),
    Owned(AlignedVec<PAYLOAD_ALIGN>),
}

impl Backing {
    fn payload(&self) -> &[u8] {
        match self {
            Backing::Mapped(map) => map.get(HEADER_LEN..).unwrap_or_default(),
            Backing::Owned(bytes) => bytes.as_slice(),
        }
    }
}

type FileRef<'a> = &'a ArchivedBrickFile;

self_cell::self_cell!(
    struct ValidatedArchive {
        owner: Backing,
        #[covariant]
        dependent: FileRef,
    }
);

/// A validated `.qbk` file.
pub struct BrickFileView {
    path: PathBuf,
    header: Header,
    checksum_verified: bool,
    structure: Structure,
    archive: ValidatedArchive,
}

// The viewer renders from many threads through one shared view.
const _: fn() = || {
    fn shared<T: Send + Sync>() {}
    shared::<BrickFileView>();
};

impl BrickFileView {
    /// Opens `path` with the default options (checksum verified).
    pub fn open(path: &Path) -> Result<Self, FormatError> {
        Self::open_with(path, &OpenOptions::default())
    }

    /// Memory-maps `path` and validates it; see the module docs for the checks.
    pub fn open_with(path: &Path, options: &OpenOptions) -> Result<Self, FormatError> {
        let err = |kind| FormatError::new(path, kind);
        // Opened without blocking: a FIFO with no writer must not hang the open.
        let (file, meta, kind) =
            files::input::open(path).map_err(|k| err(FormatErrorKind::from_input(k)))?;
        if kind != files::input::Kind::Regular {
            // A pipe or device cannot be mapped (mmap says "No such device"): read it,
            // within the stream limit.
            drop(file);
            return Self::open_in_memory(path, options);
        }
        let len = meta.len();
        if len < HEADER_LEN as u64 {
            return Err(err(FormatErrorKind::TooShort {
                expected: HEADER_LEN as u64,
                found: len,
            }));
        }
        let map = map_read_only(&file).map_err(|e| err(e.into()))?;
        let (header, verified) = check_frame(&map, options).map_err(err)?;
        Self::validate(
            path,
            header,
            verified,
            options.structure,
            Backing::Mapped(map),
        )
    }

    /// Reads `path` into memory (no mapping) and validates it. Immune to the file being
    /// truncated later, at the cost of reading and holding the whole file.
    pub(crate) fn open_in_memory(path: &Path, options: &OpenOptions) -> Result<Self, FormatError> {
        let data = read_whole(path, Limits::memory())
            .map_err(|e| FormatError::new(path, FormatErrorKind::Input(e.kind)))?;
        Self::from_bytes_with(path, &data, options)
    }

    /// Validates an in-memory copy of a whole file (tests, fuzzing); `path` names it in
    /// errors. The payload is copied once into an aligned buffer.
    pub fn from_bytes(path: &Path, data: &[u8]) -> Result<Self, FormatError> {
        Self::from_bytes_with(path, data, &OpenOptions::default())
    }

    /// [`BrickFileView::from_bytes`] with options.
    pub fn from_bytes_with(
        path: &Path,
        data: &[u8],
        options: &OpenOptions,
    ) -> Result<Self, FormatError> {
        let (header, verified) =
            check_frame(data, options).map_err(|k| FormatError::new(path, k))?;
        let mut bytes = AlignedVec::<PAYLOAD_ALIGN>::new();
        bytes.extend_from_slice(data.get(HEADER_LEN..).unwrap_or_default());
        Self::validate(
            path,
            header,
            verified,
            options.structure,
            Backing::Owned(bytes),
        )
    }

    fn validate(
        path: &Path,
        header: Header,
        checksum_verified: bool,
        structure: Structure,
        backing: Backing,
    ) -> Result<Self, FormatError> {
        let archive = ValidatedArchive::try_new(backing, |b| {
            // Validate with rancor's zero-sized `Failure` first: it keeps no trace, so
            // the per-element checks of the big value arrays compile to almost nothing
            // (with a tracing error type every element's check goes through a call that
            // records where it failed — half of the time to open a large file). Only an
            // invalid file pays for a second pass that says where and why.
            let file = match rkyv::access::<ArchivedBrickFile, rancor::Failure>(b.payload()) {
                Ok(file) => file,
                Err(_) => {
                    let e = rkyv::access::<ArchivedBrickFile, CheckError>(b.payload())
                        .err()
                        .map_or_else(|| "validation failed".to_string(), one_line);
                    return Err(FormatErrorKind::Structure(e));
                }
            };
            match structure {
                Structure::AtOpen => crate::validate::check(file)?,
                Structure::OnUse => crate::validate::check_top(file)?,
            }
            Ok::<_, FormatErrorKind>(file)
        })
        .map_err(|k| FormatError::new(path, k))?;
        Ok(Self {
            path: path.to_path_buf(),
            header,
            checksum_verified,
            structure,
            archive,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Size of the whole file in bytes (header + payload).
    pub fn byte_len(&self) -> u64 {
        HEADER_LEN as u64 + self.header.payload_len
    }

    /// The decoded header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// Whether the payload checksum was verified at open.
    pub fn checksum_verified(&self) -> bool {
        self.checksum_verified
    }

    /// Verifies the payload checksum now, on the calling thread alone: for a view opened
    /// without it, so that the hash of a large file (it reads every byte) can run beside
    /// other work, on one core, instead of before it on all. The error is the one an open
    /// with the checksum gives.
    pub fn verify_checksum(&self) -> Result<(), FormatError> {
        let found = crate::header::checksum_on(self.payload(), 1);
        if found != self.header.checksum {
            return Err(FormatError::new(
                &self.path,
                FormatErrorKind::ChecksumMismatch {
                    expected: self.header.checksum,
                    found,
                },
            ));
        }
        Ok(())
    }

    /// Where the bricks, regions and KD-tree were or are to be checked: with
    /// [`Structure::OnUse`], a reader must check what it indexes with (see
    /// [`crate::validate`]).
    pub fn structure(&self) -> Structure {
        self.structure
    }

    /// Whether the view is backed by a memory map (rather than a copy in memory).
    pub fn is_mapped(&self) -> bool {
        matches!(self.archive.borrow_owner(), Backing::Mapped(_))
    }

    /// The validated archive root. Free: validation ran once at open (all of it, or
    /// with [`Structure::OnUse`] the part that does not grow with the data).
    pub fn file(&self) -> &ArchivedBrickFile {
        self.archive.borrow_dependent()
    }

    /// The archive's bytes (payload after the header).
    pub fn payload(&self) -> &[u8] {
        self.archive.borrow_owner().payload()
    }

    /// Deserialises the whole file into owned memory.
    pub fn to_brick_file(&self) -> Result<BrickFile, FormatError> {
        rkyv::deserialize::<BrickFile, CheckError>(self.file())
            .map_err(|e| FormatError::new(&self.path, FormatErrorKind::Structure(one_line(e))))
    }
}

impl std::fmt::Debug for BrickFileView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BrickFileView")
            .field("path", &self.path)
            .field("header", &self.header)
            .field("checksum_verified", &self.checksum_verified)
            .field("structure", &self.structure)
            .field("mapped", &self.is_mapped())
            .finish_non_exhaustive()
    }
}

/// rkyv's validation error as a message: what failed and the chain of places it failed in
/// (`invalid UTF-8 in field "name" of fields[2] …`). rancor's own `Error` keeps nothing of
/// either in release builds ("failed without error information"), and its `BoxedError`
/// keeps only the innermost cause.
#[derive(Debug)]
struct CheckError {
    error: String,
    context: Vec<String>,
}

impl std::fmt::Display for CheckError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.error)?;
        for (i, c) in self.context.iter().enumerate() {
            write!(f, "{}{c}", if i == 0 { " (" } else { "; " })?;
        }
        if !self.context.is_empty() {
            write!(f, ")")?;
        }
        Ok(())
    }
}

impl std::error::Error for CheckError {}

impl rancor::Trace for CheckError {
    fn trace<R>(mut self, trace: R) -> Self
    where
        R: std::fmt::Debug + std::fmt::Display + Send + Sync + 'static,
    {
        self.context.push(one_line(trace));
        self
    }
}

impl rancor::Source for CheckError {
    fn new<T: std::error::Error + Send + Sync + 'static>(source: T) -> Self {
        Self {
            error: one_line(source),
            context: Vec::new(),
        }
    }
}

/// Header, length and (optionally) checksum of a whole file's bytes.
fn check_frame(data: &[u8], options: &OpenOptions) -> Result<(Header, bool), FormatErrorKind> {
    let header = Header::parse(data)?;
    header.payload(data, options.verify_checksum)?;
    Ok((header, options.verify_checksum))
}
