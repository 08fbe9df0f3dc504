//! Errors of the VDB reader: one line naming the file, the grid, the byte offset and what
//! was expected and found.

use std::fmt;

/// What went wrong, without the location (see [`VdbError`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ErrorKind {
    /// The file could not be read from disk.
    #[error("{0}")]
    Io(String),
    /// A read ran past the end of the data.
    #[error("expected {expected}, found {left} bytes left")]
    Truncated { expected: String, left: u64 },
    /// The first eight bytes are not OpenVDB's magic number.
    #[error("not an OpenVDB file (magic number {0:#x})")]
    BadMagic(u64),
    /// A file format version outside the supported range.
    #[error(
        "file format version {0} is not supported (versions 222 to 225, OpenVDB 6 to 12, are)"
    )]
    UnsupportedVersion(u32),
    /// A grid type other than the four supported 5-4-3 trees.
    #[error("grid type \"{0}\" is not supported (Tree_float_5_4_3, Tree_double_5_4_3, Tree_vec3s_5_4_3 and Tree_vec3d_5_4_3 are)")]
    UnsupportedGridType(String),
    /// A transform map other than scale and/or translation.
    #[error("transform \"{0}\" is not supported (only scale and translation maps are: UniformScaleTranslateMap, ScaleTranslateMap, UniformScaleMap, ScaleMap, TranslationMap)")]
    UnsupportedTransform(String),
    /// A feature of the format this reader does not handle.
    #[error("{0}")]
    Unsupported(String),
    /// A value that cannot be right (negative count, misaligned node, bad offset...).
    #[error("{0}")]
    Invalid(String),
    /// Zip or blosc data that does not decode to the expected size.
    #[error("{0}")]
    Decompress(String),
    /// A grid index outside `0..grids().len()`.
    #[error("no grid with index {index} (the file has {count})")]
    NoSuchGrid { index: usize, count: usize },
}

/// A reader error located in a file: `file: grid "name": what at byte N: kind`.
#[derive(Debug, Clone, PartialEq)]
pub struct VdbError {
    /// File name as given to [`super::VdbFile::open`] or [`super::VdbFile::from_bytes`].
    pub file: String,
    /// The grid being read, when there is one.
    pub grid: Option<String>,
    /// Byte offset in the file where the failing item starts.
    pub offset: u64,
    /// The item being read ("leaf buffer", "grid descriptor", ...).
    pub what: &'static str,
    pub kind: ErrorKind,
}

impl fmt::Display for VdbError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: ", self.file)?;
        if let ErrorKind::Io(msg) = &self.kind {
            // Nothing was parsed yet: no grid, item or offset to name.
            return write!(f, "{msg}");
        }
        if let Some(grid) = &self.grid {
            write!(f, "grid {grid:?}: ")?;
        }
        write!(f, "{} at byte {}: {}", self.what, self.offset, self.kind)
    }
}

impl std::error::Error for VdbError {}

/// An error before file and grid are attached (inside the parsers).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RawError {
    pub offset: u64,
    pub what: &'static str,
    pub kind: ErrorKind,
}

impl RawError {
    pub fn new(offset: usize, what: &'static str, kind: ErrorKind) -> Self {
        RawError {
            offset: offset as u64,
            what,
            kind,
        }
    }

    pub fn invalid(offset: usize, what: &'static str, msg: impl Into<String>) -> Self {
        Self::new(offset, what, ErrorKind::Invalid(msg.into()))
    }

    pub fn locate(self, file: &str, grid: Option<&str>) -> VdbError {
        VdbError {
            file: file.to_string(),
            grid: grid.map(str::to_string),
            offset: self.offset,
            what: self.what,
            kind: self.kind,
        }
    }
}

pub(crate) type RawResult<T> = Result<T, RawError>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_is_one_line_with_file_grid_offset() {
        let e = RawError::new(
            1234,
            "leaf buffer",
            ErrorKind::Truncated {
                expected: "512 values".into(),
                left: 12,
            },
        )
        .locate("data.vdb", Some("vel"));
        assert_eq!(
            e.to_string(),
            "data.vdb: grid \"vel\": leaf buffer at byte 1234: expected 512 values, found 12 bytes left"
        );
        let e = RawError::new(0, "file header", ErrorKind::BadMagic(7)).locate("x.vdb", None);
        assert_eq!(
            e.to_string(),
            "x.vdb: file header at byte 0: not an OpenVDB file (magic number 0x7)"
        );
    }
}
