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
    /// A value that cannot be right (negative count, misaligned node, bad offset...).
    /// Boxed: the largest reasons would double the size of every reader result.
    #[error("{0}")]
    Invalid(Box<Invalid>),
    /// Zip or blosc data that does not decode to the expected size.
    #[error("{0}")]
    Decompress(DecompressError),
    /// A grid index outside `0..grids().len()`.
    #[error("no grid with index {index} (the file has {count})")]
    NoSuchGrid { index: usize, count: usize },
    /// Decoding would take more memory than the shared limit allows (compressed leaves
    /// can decode to a hundred times their size in the file).
    /// Boxed: as large as the largest other reasons.
    #[error("{0}")]
    Memory(Box<files::limits::LimitError>),
}

/// What makes a value read from the file impossible.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Invalid {
    #[error("expected an uncompressed chunk of {expected} bytes, found {found} bytes")]
    ChunkSize { expected: usize, found: u64 },
    #[error("mask-compression code {code} is not one of 0 to 6")]
    MaskCompression { code: u8 },
    /// A metadata value whose size does not fit its type.
    #[error("entry \"{name}\" of type {type_name} has {len} bytes")]
    MetadataSize {
        name: String,
        type_name: String,
        len: usize,
    },
    /// A zero, negative or non-finite voxel size, or a non-finite translation.
    #[error("voxel size {scale:?} / translation {translation:?} must be finite and positive")]
    Transform {
        scale: [f64; 3],
        translation: [f64; 3],
    },
    #[error("{count} grids cannot fit in {left} bytes")]
    GridCount { count: i32, left: usize },
    #[error("offset {offset} is outside the {len}-byte file")]
    Offset { offset: i64, len: usize },
    #[error(
        "offsets grid {grid}, buffers {buffers}, end {end} are out of order (descriptor ends at byte {here})"
    )]
    OffsetOrder {
        grid: u64,
        buffers: u64,
        end: u64,
        here: u64,
    },
    #[error("unknown flags {flags:#x} for grid {grid:?}")]
    CompressionFlags { flags: u32, grid: String },
    #[error("grid {grid:?} is an instance of missing grid {parent:?}")]
    MissingParent { grid: String, parent: String },
    #[error("grid {grid:?} is an instance of an instance")]
    NestedInstance { grid: String },
    /// A grid without a transform of its own or from its parent.
    #[error("missing")]
    MissingTransform,
    #[error("instance of a {parent} grid has type {own}")]
    InstanceType { parent: String, own: String },
    #[error("expected 1 buffer per node, found {count}")]
    BufferCount { count: i32 },
    /// A root tile or child not on the 4096-voxel lattice of root entries.
    #[error("origin {origin:?} is not a multiple of 4096")]
    RootOrigin { origin: [i32; 3] },
    #[error("two entries at origin {origin:?}")]
    DuplicateRootEntry { origin: [i32; 3] },
}

/// Why zip or blosc data does not decode to the size the file says. The zip and LZ4
/// decoders' own errors are kept as their text, so that reader errors stay comparable
/// and cloneable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecompressError {
    #[error("zip data does not decode: {message}")]
    Zip { message: String },
    #[error("zip data decodes to {found} bytes, expected {expected}")]
    ZipSize { found: usize, expected: usize },
    /// A header field or block offset past the end of the frame.
    #[error("blosc frame ends at byte {at} of {len}")]
    BloscEnds { at: usize, len: usize },
    #[error("blosc frame of {len} bytes is shorter than its 16-byte header")]
    BloscShort { len: usize },
    #[error("blosc frame holds {total} bytes, expected {expected}")]
    BloscTotal { total: usize, expected: usize },
    #[error("blosc frame claims {claimed} bytes, chunk has {len}")]
    BloscClaims { claimed: usize, len: usize },
    #[error("blosc frame claims {claimed} bytes, shorter than its 16-byte header")]
    BloscClaimsBelowHeader { claimed: usize },
    #[error("blosc frame marked uncompressed is too short")]
    BloscCopyShort,
    #[error("blosc codec {codec} is not supported (OpenVDB writes LZ4, codec 1)")]
    BloscCodec { codec: u8 },
    #[error("blosc bit shuffle is not supported (OpenVDB writes byte shuffle)")]
    BloscBitShuffle,
    #[error("blosc block size {blocksize} or type size {typesize} is zero")]
    BloscZeroSize { blocksize: usize, typesize: usize },
    #[error("blosc frame claims {blocks} blocks, too many for {len} bytes")]
    BloscBlocks { blocks: usize, len: usize },
    #[error("blosc block {block} runs past the frame end")]
    BloscPastEnd { block: usize },
    #[error("blosc block {block}: LZ4 data does not decode: {message}")]
    Lz4 { block: usize, message: String },
    #[error("blosc block {block}: LZ4 data decodes to {found} bytes, expected {expected}")]
    Lz4Size {
        block: usize,
        found: usize,
        expected: usize,
    },
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
    pub(crate) fn new(offset: usize, what: &'static str, kind: ErrorKind) -> Self {
        RawError {
            offset: offset as u64,
            what,
            kind,
        }
    }

    pub(crate) fn invalid(offset: usize, what: &'static str, invalid: Invalid) -> Self {
        Self::new(offset, what, ErrorKind::Invalid(Box::new(invalid)))
    }

    pub(crate) fn locate(self, file: &str, grid: Option<&str>) -> VdbError {
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
