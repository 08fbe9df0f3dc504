//! Opens and validates a `.qbk` file.
//! (Provisional: reads into memory; the real reader memory-maps and checks the header.)

use std::path::{Path, PathBuf};

use rkyv::util::AlignedVec;

use crate::error::{FormatError, FormatErrorKind};
use crate::schema::ArchivedBrickFile;

/// Options for [`BrickFileView::open_with`].
#[derive(Debug, Clone)]
pub struct OpenOptions {
    /// Verify the payload checksum (validation of the archive always runs).
    pub verify_checksum: bool,
}

impl Default for OpenOptions {
    fn default() -> Self {
        Self {
            verify_checksum: true,
        }
    }
}

/// A validated `.qbk` file.
pub struct BrickFileView {
    path: PathBuf,
    bytes: AlignedVec<16>,
}

impl BrickFileView {
    pub fn open(path: &Path) -> Result<Self, FormatError> {
        Self::open_with(path, &OpenOptions::default())
    }

    pub fn open_with(path: &Path, _options: &OpenOptions) -> Result<Self, FormatError> {
        let data = std::fs::read(path).map_err(|e| FormatError {
            path: path.to_path_buf(),
            kind: e.into(),
        })?;
        Self::from_bytes(path, &data)
    }

    /// Validates an in-memory copy of a file (tests, fuzzing); `path` names it in errors.
    pub fn from_bytes(path: &Path, data: &[u8]) -> Result<Self, FormatError> {
        let mut bytes = AlignedVec::<16>::new();
        bytes.extend_from_slice(data);
        rkyv::access::<ArchivedBrickFile, rkyv::rancor::Error>(&bytes).map_err(|e| {
            FormatError {
                path: path.to_path_buf(),
                kind: FormatErrorKind::Invalid(e.to_string()),
            }
        })?;
        Ok(Self {
            path: path.to_path_buf(),
            bytes,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Size of the whole file in bytes.
    pub fn byte_len(&self) -> u64 {
        self.bytes.len() as u64
    }

    pub fn file(&self) -> &ArchivedBrickFile {
        // Validated in `from_bytes`; access again checks nothing new but stays safe.
        rkyv::access::<ArchivedBrickFile, rkyv::rancor::Error>(&self.bytes)
            .expect("validated at open")
    }
}
