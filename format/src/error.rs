//! Errors of the format crate: each names the file and holds what was expected and found.
//!
//! Messages are one line (the CLIs print `program: path: message` and exit 2).

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
#[error("{}: {kind}", path.display())]
pub struct FormatError {
    pub path: PathBuf,
    pub kind: FormatErrorKind,
}

impl FormatError {
    pub(crate) fn new(path: impl Into<PathBuf>, kind: FormatErrorKind) -> Self {
        Self {
            path: path.into(),
            kind,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum FormatErrorKind {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// Reading the file whole failed (a directory, a device over the size limit...).
    #[error("{0}")]
    Input(files::input::InputErrorKind),
    /// The archive passed rkyv's structural validation but breaks an invariant of the
    /// schema (the error names the element, e.g. `regions[12].bricks[3]`).
    #[error("archive is invalid: {0}")]
    Invalid(#[from] crate::validate::ValidationError),
    /// rkyv's structural validation (bytecheck) or deserialisation failed; the message is
    /// rkyv's trace, flattened onto one line.
    #[error("archive is invalid: {0}")]
    Structure(String),
    #[error("file too short for a .qbk header: expected at least {expected} bytes, found {found}")]
    TooShort { expected: u64, found: u64 },
    #[error(
        "not a .qbk file: expected magic \"QBRICKS\\0\", found {}",
        show_magic(found)
    )]
    BadMagic { found: [u8; 8] },
    #[error(
        "file has .qbk format version {found}, this build reads version {supported}; \
         re-bake it with a matching qbricks-bake"
    )]
    UnsupportedVersion { found: u32, supported: u32 },
    #[error("archive flags {found:#x} are not supported: this build reads flags {expected:#x}")]
    UnsupportedFlags { found: u32, expected: u32 },
    #[error("reserved header byte at offset {offset} is not zero")]
    ReservedNotZero { offset: usize },
    #[error(
        "file length does not match its header: expected {expected} bytes, found {found} \
         (truncated or appended to?)"
    )]
    LengthMismatch { expected: u64, found: u64 },
    #[error(
        "payload checksum mismatch: header says xxh3 {expected:#018x}, payload has \
         {found:#018x} (file corrupted)"
    )]
    ChecksumMismatch { expected: u64, found: u64 },
    #[error("cannot serialise the archive: {0}")]
    Serialize(String),
}

impl FormatErrorKind {
    /// An input error as this crate says it (a plain I/O error as before, the rest with
    /// the input's own message).
    pub(crate) fn from_input(kind: files::input::InputErrorKind) -> Self {
        match kind {
            files::input::InputErrorKind::Io(e) => FormatErrorKind::Io(e),
            other => FormatErrorKind::Input(other),
        }
    }
}

fn show_magic(b: &[u8; 8]) -> String {
    b.iter()
        .flat_map(|&c| std::ascii::escape_default(c))
        .map(char::from)
        .collect()
}

/// Flattens a possibly multi-line message (rkyv's validation traces) onto one line.
pub(crate) fn one_line(msg: impl std::fmt::Display) -> String {
    msg.to_string()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join("; ")
}
