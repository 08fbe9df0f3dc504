//! OpenVDB files: the subset qbricks reads, and a small writer for synthetic scenes.
//!
//! The reader handles file format versions 222 to 225 (OpenVDB 6 to 12) holding
//! `Tree_{float,double,vec3s,vec3d}_5_4_3` grids, with zip, blosc (LZ4) or no compression,
//! active-mask compression, half-float storage, active tiles at every level, instanced grids
//! and duplicate names, in files with grid offsets or written to a stream (without them).
//! It works on the whole file, mapped (or read, for a pipe), through a bounds-checked
//! cursor: every count or size read from the file is checked against the bytes left before
//! anything is allocated from it.
//!
//! ```no_run
//! # fn main() -> Result<(), qbricks_preprocess::vdb::VdbError> {
//! let file = qbricks_preprocess::vdb::VdbFile::open("wake.vdb")?;
//! for (i, g) in file.grids().iter().enumerate() {
//!     println!("{} {:?} {:?}", g.name, g.value_type, g.transform);
//!     let grid = file.read_grid(i)?;
//! #   let _ = grid;
//! }
//! # Ok(()) }
//! ```

pub mod codec;
pub mod compress;
mod cursor;
pub mod error;
pub mod inspect;
pub mod located;
pub mod metadata;
mod transform;
pub mod tree;
mod values;
pub mod write;

use std::path::Path;
use std::sync::Arc;

use files::input::{map_whole, Limits, Whole};

pub use codec::MAGIC;
pub use error::{DecompressError, ErrorKind, Invalid, VdbError};
pub use located::{AnyLocated, LeafSource, Located};
pub use metadata::{MetaValue, Metadata};
pub use tree::LocatedLeaf;

use crate::grid::{AnyGrid, Grid, Transform};
use codec::{CompressionFlags, VdbValue};
use cursor::Cursor;
use error::{RawError, RawResult};
use values::Codec;

/// Oldest supported file format version (node mask compression, OpenVDB 3+).
pub(crate) const MIN_FILE_VERSION: u32 = 222;
/// Newest supported file format version (OpenVDB 12).
pub(crate) const MAX_FILE_VERSION: u32 = 225;

/// Grid value type, from the grid type name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ValueType {
    Float,
    Double,
    Vec3s,
    Vec3d,
    /// Any other grid type (points, bool, int...): listed but not readable.
    Unsupported(String),
}

impl ValueType {
    fn from_grid_type(t: &str) -> Self {
        match t {
            <f32 as VdbValue>::TREE_TYPE => ValueType::Float,
            <f64 as VdbValue>::TREE_TYPE => ValueType::Double,
            <[f32; 3] as VdbValue>::TREE_TYPE => ValueType::Vec3s,
            <[f64; 3] as VdbValue>::TREE_TYPE => ValueType::Vec3d,
            other => ValueType::Unsupported(other.to_string()),
        }
    }

    /// `float`, `double`, `vec3s`, `vec3d`, or the grid type name.
    pub fn name(&self) -> &str {
        match self {
            ValueType::Float => f32::VALUE_TYPE,
            ValueType::Double => f64::VALUE_TYPE,
            ValueType::Vec3s => <[f32; 3]>::VALUE_TYPE,
            ValueType::Vec3d => <[f64; 3]>::VALUE_TYPE,
            ValueType::Unsupported(t) => t,
        }
    }

    pub(crate) fn is_vector(&self) -> bool {
        matches!(self, ValueType::Vec3s | ValueType::Vec3d)
    }
}

/// What the file says about one grid, read when the file is opened (no tree data).
#[derive(Debug, Clone, PartialEq)]
pub struct GridDescriptor {
    /// Grid name (duplicate names are kept; see `unique_name`).
    pub name: String,
    /// Name as stored, with OpenVDB's `\x1e<n>` suffix for duplicates.
    pub unique_name: String,
    /// Grid type name as stored, without the `_HalfFloat` suffix.
    pub(crate) grid_type: String,
    pub value_type: ValueType,
    /// Map type name (e.g. `UniformScaleTranslateMap`).
    pub map_type: String,
    /// `None` when the map rotates or shears (reading the grid then fails).
    pub transform: Option<Transform>,
    /// Compression flags as stored; see [`GridDescriptor::compression_flags`].
    pub compression: u32,
    /// Values stored as 16-bit floats.
    pub half_float: bool,
    /// Grid metadata (name → value).
    pub metadata: Metadata,
    /// Index of the grid whose tree this one shares, for instanced grids.
    pub instance_of: Option<usize>,
    /// Byte offsets from the grid descriptor: grid start, tree buffers, end.
    pub grid_pos: u64,
    pub(crate) block_pos: u64,
    pub end_pos: u64,
    /// Where the tree topology starts (after compression flags, metadata and transform).
    tree_pos: usize,
    transform_error: Option<RawError>,
}

impl GridDescriptor {
    /// The grid class (metadata `class`: `unknown`, `level set`, `fog volume`,
    /// `staggered`); `unknown` when the entry is missing or not a string, as in OpenVDB.
    pub(crate) fn class(&self) -> &str {
        match self.metadata.get("class") {
            Some(MetaValue::String(s)) => s,
            _ => "unknown",
        }
    }

    /// The compression flags, checked when the file was opened (no unknown bits).
    pub(crate) fn compression_flags(&self) -> CompressionFlags {
        CompressionFlags(self.compression)
    }

    /// A MAC grid: vector components on the lower cell faces (see [`crate::derive`]).
    pub fn is_staggered(&self) -> bool {
        self.class() == "staggered"
    }
}

/// An opened VDB file: header, file metadata and grid descriptors. Grids are decoded on
/// demand with [`VdbFile::read_grid`].
#[derive(Debug)]
pub struct VdbFile {
    name: String,
    /// Shared with the grids located in it ([`LeafSource`]), which decode from it later.
    data: Arc<Whole>,
    pub file_version: u32,
    pub library_version: (u32, u32),
    pub(crate) uuid: String,
    pub metadata: Metadata,
    grids: Vec<GridDescriptor>,
}

impl VdbFile {
    /// Maps the file (or reads it, when it is no regular file) and parses its header and
    /// grid descriptors.
    ///
    /// A regular file is mapped read-only ([`files::input::map_whole`]), whatever its size
    /// ([`Limits::mapped`]): its pages are read as the grids are located and decoded and let
    /// go behind, so a file is never held whole, and a bake decodes a batch of leaves at a
    /// time ([`located`]), so one larger than the machine's memory bakes too (decoding a
    /// grid whole, as `read_grid` does, is checked against the memory limit by its leaves).
    /// A device or pipe is read only up to a cap (`/dev/zero` would otherwise be read until
    /// memory runs out).
    pub fn open(path: impl AsRef<Path>) -> Result<VdbFile, VdbError> {
        let path = path.as_ref();
        let name = path.display().to_string();
        let data = map_whole(path, Limits::mapped()).map_err(|e| VdbError {
            file: name.clone(),
            grid: None,
            offset: 0,
            what: "file",
            kind: ErrorKind::Io(e.kind.to_string()),
        })?;
        Self::parse(name, data)
    }

    /// Parses a file held in memory; `name` is used in error messages.
    pub fn from_bytes(name: impl Into<String>, data: Vec<u8>) -> Result<VdbFile, VdbError> {
        Self::parse(name.into(), Whole::Read(data))
    }

    fn parse(name: String, data: Whole) -> Result<VdbFile, VdbError> {
        let mut file = VdbFile {
            name,
            data: Arc::new(data),
            file_version: 0,
            library_version: (0, 0),
            uuid: String::new(),
            metadata: Metadata::new(),
            grids: Vec::new(),
        };
        file.parse_header()
            .map_err(|e| e.locate(&file.name, None))?;
        Ok(file)
    }

    /// The file name given at open.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Grid descriptors in file order.
    pub fn grids(&self) -> &[GridDescriptor] {
        &self.grids
    }

    fn parse_header(&mut self) -> RawResult<()> {
        let data = Arc::clone(&self.data);
        self.parse_header_in(&data)
    }

    fn parse_header_in(&mut self, data: &[u8]) -> RawResult<()> {
        let mut cur = Cursor::new(data, 0);
        // Header: magic, format version, library version, offsets flag, UUID.
        let magic = cur.i64("file header")? as u64;
        if magic != MAGIC {
            return Err(RawError::new(0, "file header", ErrorKind::BadMagic(magic)));
        }
        let version = cur.u32("file version")?;
        if !(MIN_FILE_VERSION..=MAX_FILE_VERSION).contains(&version) {
            return Err(RawError::new(
                8,
                "file version",
                ErrorKind::UnsupportedVersion(version),
            ));
        }
        self.file_version = version;
        self.library_version = (cur.u32("library version")?, cur.u32("library version")?);
        let offsets_at = cur.pos();
        let has_offsets = cur.u8("file header")? != 0;
        self.uuid = String::from_utf8_lossy(cur.take(36, "file UUID")?).into_owned();
        self.metadata = metadata::read_metadata(&mut cur)?;
        let _ = offsets_at;

        // Grid descriptors: name, type, instance parent, three offsets.
        let count_at = cur.pos();
        let count = cur.i32("grid count")?;
        // A descriptor takes at least three strings and three offsets (36 bytes).
        if count < 0 || count as usize > cur.left() / 36 {
            return Err(RawError::invalid(
                count_at,
                "grid count",
                Invalid::GridCount {
                    count,
                    left: cur.left(),
                },
            ));
        }
        let mut parents = Vec::new();
        for _ in 0..count {
            let at = cur.pos();
            let unique_name = cur.string("grid descriptor")?;
            let mut grid_type = cur.string("grid descriptor")?;
            let half_float = grid_type.ends_with("_HalfFloat");
            if half_float {
                grid_type.truncate(grid_type.len() - "_HalfFloat".len());
            }
            let parent = cur.string("grid descriptor")?;
            let raw = [
                cur.i64("grid descriptor")?,
                cur.i64("grid descriptor")?,
                cur.i64("grid descriptor")?,
            ];
            let (grid_pos, block_pos, end_pos) = if has_offsets {
                let pos = |p: i64| -> RawResult<u64> {
                    u64::try_from(p)
                        .ok()
                        .filter(|&p| p <= data.len() as u64)
                        .ok_or_else(|| {
                            RawError::invalid(
                                at,
                                "grid descriptor",
                                Invalid::Offset {
                                    offset: p,
                                    len: data.len(),
                                },
                            )
                        })
                };
                (pos(raw[0])?, pos(raw[1])?, pos(raw[2])?)
            } else {
                // Written to a stream: the offsets are placeholders and the grid follows
                // its descriptor; walk it to find where it ends.
                let ty = ValueType::from_grid_type(&grid_type);
                let (block, end) = scan_grid(data, cur.pos(), &ty, half_float, !parent.is_empty())?;
                (cur.pos() as u64, block, end)
            };
            // Each grid follows its descriptor and the next descriptor follows the grid, so
            // offsets only grow; this also keeps the work linear in the file size.
            let here = cur.pos() as u64;
            // (Instances have no tree and store 0 as their buffer offset.)
            let block_ok = block_pos == 0 || (grid_pos <= block_pos && block_pos <= end_pos);
            if !(here <= grid_pos && grid_pos <= end_pos && block_ok) {
                return Err(RawError::invalid(
                    at,
                    "grid descriptor",
                    Invalid::OffsetOrder {
                        grid: grid_pos,
                        buffers: block_pos,
                        end: end_pos,
                        here,
                    },
                ));
            }
            let name = match unique_name.find('\u{1e}') {
                Some(i) => unique_name[..i].to_string(),
                None => unique_name.clone(),
            };
            parents.push(parent);
            self.grids.push(GridDescriptor {
                name,
                unique_name,
                value_type: ValueType::from_grid_type(&grid_type),
                grid_type,
                map_type: String::new(),
                transform: None,
                compression: 0,
                half_float,
                metadata: Metadata::new(),
                instance_of: None,
                grid_pos,
                block_pos,
                end_pos,
                tree_pos: 0,
                transform_error: None,
            });
            // The next descriptor follows this grid's data.
            cur = Cursor::new(data, end_pos as usize);
        }

        // Per grid: compression flags, metadata, transform.
        for (i, parent) in parents.iter().enumerate() {
            let g = &self.grids[i];
            let name = g.name.clone();
            // A grid's header and tree never extend past its end offset.
            let mut cur = Cursor::new(&data[..g.end_pos as usize], g.grid_pos as usize);
            let compression = cur.u32("grid compression flags")?;
            if !CompressionFlags(compression).is_known() {
                return Err(RawError::invalid(
                    g.grid_pos as usize,
                    "grid compression flags",
                    Invalid::CompressionFlags {
                        flags: compression,
                        grid: name.to_string(),
                    },
                ));
            }
            let meta = metadata::read_metadata(&mut cur)?;
            let (map_type, transform, transform_error) = match transform::read_transform(&mut cur) {
                Ok((m, t)) => (m, Some(t), None),
                Err(
                    e @ RawError {
                        kind: ErrorKind::UnsupportedTransform(_),
                        ..
                    },
                ) => {
                    let map = match &e.kind {
                        ErrorKind::UnsupportedTransform(m) => m.clone(),
                        _ => String::new(),
                    };
                    (map, None, Some(e))
                }
                Err(e) => return Err(e),
            };
            let instance_of = if parent.is_empty() {
                None
            } else {
                let p = self
                    .grids
                    .iter()
                    .position(|o| &o.unique_name == parent)
                    .ok_or_else(|| {
                        RawError::invalid(
                            g.grid_pos as usize,
                            "grid descriptor",
                            Invalid::MissingParent {
                                grid: name.to_string(),
                                parent: parent.to_string(),
                            },
                        )
                    })?;
                Some(p)
            };
            let g = &mut self.grids[i];
            g.compression = compression;
            g.metadata = meta;
            g.map_type = map_type;
            g.transform = transform;
            g.transform_error = transform_error;
            g.instance_of = instance_of;
            g.tree_pos = if transform.is_some() { cur.pos() } else { 0 };
        }
        // An instance must point at a grid that holds a tree itself.
        for (i, g) in self.grids.iter().enumerate() {
            if let Some(p) = g.instance_of {
                if self.grids[p].instance_of.is_some() || p == i {
                    return Err(RawError::invalid(
                        g.grid_pos as usize,
                        "grid descriptor",
                        Invalid::NestedInstance {
                            grid: g.name.to_string(),
                        },
                    ));
                }
            }
        }
        Ok(())
    }

    /// Decodes grid `index` (voxels and tiles).
    pub fn read_grid(&self, index: usize) -> Result<AnyGrid, VdbError> {
        self.locate_grid(index)?.decode()
    }

    /// Reads grid `index`'s tiles and topology and finds its leaf buffers, without decoding
    /// them: see [`located`].
    pub fn locate_grid(&self, index: usize) -> Result<AnyLocated, VdbError> {
        let g = self.grids.get(index).ok_or_else(|| VdbError {
            file: self.name.clone(),
            grid: None,
            offset: 0,
            what: "grid index",
            kind: ErrorKind::NoSuchGrid {
                index,
                count: self.grids.len(),
            },
        })?;
        self.locate_grid_raw(g)
            .map_err(|e| e.locate(&self.name, Some(&g.name)))
    }

    /// Decodes every grid, in file order. A tree shared by instanced grids is decoded once
    /// and copied.
    pub fn read_all(&self) -> Result<Vec<AnyGrid>, VdbError> {
        let mut out: Vec<AnyGrid> = Vec::with_capacity(self.grids.len());
        for (i, g) in self.grids.iter().enumerate() {
            let decoded = match (g.instance_of, g.transform) {
                (Some(p), Some(t)) if p < i && self.grids[p].value_type == g.value_type => {
                    let mut copy = out[p].clone();
                    copy.rename(&g.name, t);
                    copy
                }
                _ => self.read_grid(i)?,
            };
            out.push(decoded);
        }
        Ok(out)
    }

    fn locate_grid_raw(&self, g: &GridDescriptor) -> RawResult<AnyLocated> {
        if let ValueType::Unsupported(t) = &g.value_type {
            return Err(RawError::new(
                g.grid_pos as usize,
                "grid descriptor",
                ErrorKind::UnsupportedGridType(t.clone()),
            ));
        }
        let transform = match (g.transform, &g.transform_error) {
            (Some(t), _) => t,
            (None, Some(e)) => return Err(e.clone()),
            (None, None) => {
                return Err(RawError::invalid(
                    g.grid_pos as usize,
                    "transform",
                    Invalid::MissingTransform,
                ))
            }
        };
        // An instance reads its parent's tree with the parent's settings.
        let tree_owner = match g.instance_of {
            Some(p) => &self.grids[p],
            None => g,
        };
        if tree_owner.value_type != g.value_type {
            return Err(RawError::invalid(
                g.grid_pos as usize,
                "grid descriptor",
                Invalid::InstanceType {
                    parent: tree_owner.value_type.name().to_string(),
                    own: g.value_type.name().to_string(),
                },
            ));
        }
        if tree_owner.tree_pos == 0 {
            if let Some(e) = &tree_owner.transform_error {
                return Err(e.clone());
            }
        }
        let codec = Codec {
            flags: tree_owner.compression_flags(),
            half: tree_owner.half_float,
        };
        let end = tree_owner.end_pos as usize;
        let mut cur = Cursor::new(&self.data[..end], tree_owner.tree_pos);
        let source = located::source(&self.data, end, codec, &self.name, &g.name);
        let name = g.name.clone();
        let c = &mut cur;
        let r = &|range| self.data.release(range);
        Ok(match &g.value_type {
            ValueType::Float => AnyLocated::Float(locate(c, codec, name, transform, source, r)?),
            ValueType::Double => AnyLocated::Double(locate(c, codec, name, transform, source, r)?),
            ValueType::Vec3s => AnyLocated::Vec3s(locate(c, codec, name, transform, source, r)?),
            ValueType::Vec3d => AnyLocated::Vec3d(locate(c, codec, name, transform, source, r)?),
            ValueType::Unsupported(t) => {
                return Err(RawError::new(
                    g.grid_pos as usize,
                    "grid descriptor",
                    ErrorKind::UnsupportedGridType(t.clone()),
                ))
            }
        })
    }
}

/// Walks one grid of a stream-written file (compression flags, metadata, transform, tree)
/// without decoding leaf values; returns (buffer start, end) offsets.
fn scan_grid(
    data: &[u8],
    start: usize,
    ty: &ValueType,
    half: bool,
    instance: bool,
) -> RawResult<(u64, u64)> {
    let mut cur = Cursor::new(data, start);
    let flags = cur.u32("grid compression flags")?;
    metadata::read_metadata(&mut cur)?;
    transform::read_transform(&mut cur)?;
    if instance {
        return Ok((0, cur.pos() as u64));
    }
    let codec = Codec {
        flags: CompressionFlags(flags),
        half,
    };
    match ty {
        ValueType::Float => drop(tree::locate_tree::<f32>(&mut cur, codec, &|_| ())?),
        ValueType::Double => drop(tree::locate_tree::<f64>(&mut cur, codec, &|_| ())?),
        ValueType::Vec3s => drop(tree::locate_tree::<[f32; 3]>(&mut cur, codec, &|_| ())?),
        ValueType::Vec3d => drop(tree::locate_tree::<[f64; 3]>(&mut cur, codec, &|_| ())?),
        ValueType::Unsupported(t) => {
            return Err(RawError::new(
                start,
                "grid descriptor",
                ErrorKind::UnsupportedGridType(t.clone()),
            ))
        }
    }
    // OpenVDB does not record where buffers start in a stream; any offset inside the grid
    // is fine for us.
    Ok((start as u64, cur.pos() as u64))
}

fn locate<V: VdbValue>(
    cur: &mut Cursor<'_>,
    codec: Codec,
    name: String,
    transform: Transform,
    source: LeafSource,
    release: &dyn Fn(std::ops::Range<usize>),
) -> RawResult<Located<V>> {
    let t = tree::locate_tree::<V>(cur, codec, release)?;
    Ok(Located {
        grid: Grid {
            name,
            transform,
            background: t.background,
            leaves: t.leaves,
            tiles: t.tiles,
        },
        source,
    })
}
