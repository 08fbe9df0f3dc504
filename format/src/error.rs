//! Errors of the format crate: each names the file and holds what was expected and found.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
#[error("{}: {kind}", path.display())]
pub struct FormatError {
    pub path: PathBuf,
    pub kind: FormatErrorKind,
}

#[derive(Debug, thiserror::Error)]
pub enum FormatErrorKind {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("archive is invalid: {0}")]
    Invalid(String),
}
