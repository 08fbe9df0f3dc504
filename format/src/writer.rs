//! Serialises a [`BrickFile`] and writes it atomically.
//! (Provisional: no header yet; the real writer replaces this.)

use std::path::Path;

use crate::error::{FormatError, FormatErrorKind};
use crate::schema::BrickFile;

/// Bytes of a complete `.qbk` file for `file`.
pub fn to_bytes(file: &BrickFile) -> Result<Vec<u8>, FormatErrorKind> {
    rkyv::to_bytes::<rkyv::rancor::Error>(file)
        .map(|b| b.to_vec())
        .map_err(|e| FormatErrorKind::Invalid(e.to_string()))
}

/// Writes `file` to `path`; returns the number of bytes written.
pub fn write(path: &Path, file: &BrickFile) -> Result<u64, FormatError> {
    let err = |kind| FormatError {
        path: path.to_path_buf(),
        kind,
    };
    let bytes = to_bytes(file).map_err(err)?;
    std::fs::write(path, &bytes).map_err(|e| err(e.into()))?;
    Ok(bytes.len() as u64)
}
