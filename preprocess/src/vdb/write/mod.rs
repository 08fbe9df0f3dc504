//! A small OpenVDB writer: enough to write what `synth` makes, in a form real OpenVDB reads.
//!
//! Writes file format version 224 (`OPENVDB_FILE_VERSION_MULTIPASS_IO`, read by OpenVDB 6
//! and later) with standard 5-4-3 trees (`Tree_float_5_4_3`, `Tree_double_5_4_3`,
//! `Tree_vec3s_5_4_3`, `Tree_vec3d_5_4_3`), full-precision values, a uniform scale +
//! translation transform per grid, grid offsets (so readers can seek), and per-grid
//! compression `none`, active-mask only, or zlib + active mask. Leaves and active tiles at
//! every level (8³, 128³ and 4096³ voxels) are written as given.
//!
//! Layout, in byte order (all little-endian; strings are a `u32` length then bytes):
//! 1. header: magic `0x56444220` as `i64`, file version `u32`, library major/minor `u32`
//!    (this writer puts qbricks' own version there, 0.1), has-grid-offsets `u8` = 1,
//!    36-character UUID (deterministic: a hash of the grids' names and shapes);
//! 2. file metadata (`u32` count, then name, type name, `u32` size, value);
//! 3. `i32` grid count, then per grid: unique name, tree type name, instance parent
//!    name (empty), grid / block / end offsets (`i64`), compression flags (`u32`), grid
//!    metadata, transform (map type name + map), topology (`i32` buffer count = 1, root
//!    node: background, tile and child counts, tiles, then each child's masks and
//!    values down to the leaves' value masks), then the leaf buffers (value mask +
//!    compressed values) in the same depth-first order.
//!
//! Per-node values go through OpenVDB's node-value compression: one metadata byte (0–6,
//! see [`NodeMeta`](super::codec::NodeMeta)), then the values it says must be stored, each
//! block optionally zlib-compressed behind an `i64` size (negative: stored raw).
//!
//! Output is deterministic (same grids → same bytes) and atomic: the file is written through
//! `files::output::write_atomic` (temporary name in the target directory, synced, renamed
//! over the target).
//!
//! The modules mirror the reader's, record by record: this one writes the header and the
//! grid descriptors and puts each grid's record together; [`metadata`], [`transform`] and
//! [`tree`] write those parts of a grid, [`values`] the values of one node, [`compress`] one
//! block of them. What both sides share (magic, flags, node metadata codes, value types)
//! is in [`super::codec`].

mod compress;
mod metadata;
mod transform;
mod tree;
mod values;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use thiserror::Error;

use super::codec::{CompressionFlags, VdbValue, MAGIC};
use crate::grid::{AnyGrid, Grid, Transform};

/// `OPENVDB_FILE_VERSION_MULTIPASS_IO`: the newest format before half-float grid types.
pub(crate) const FILE_VERSION: u32 = 224;
/// Library version written into the header: qbricks' own, not an OpenVDB release.
pub(crate) const LIBRARY_VERSION: (u32, u32) = (0, 1);

/// Per-grid compression of node values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    /// Every node stores all its values raw (metadata byte 6).
    None,
    /// Only active values are stored (plus inactive ones when they are not the background).
    ActiveMask,
    /// zlib over the active values: OpenVDB's usual setting when built without Blosc.
    Zip,
}

impl Compression {
    /// The flags written into the file.
    pub(crate) fn flags(self) -> CompressionFlags {
        match self {
            Compression::None => CompressionFlags::NONE,
            Compression::ActiveMask => CompressionFlags::ACTIVE_MASK,
            Compression::Zip => CompressionFlags::ZIP.union(CompressionFlags::ACTIVE_MASK),
        }
    }

    /// OpenVDB's description of the flags (`file_compression` metadata).
    pub fn describe(self) -> &'static str {
        match self {
            Compression::None => "none",
            Compression::ActiveMask => "active values",
            Compression::Zip => "zip + active values",
        }
    }
}

/// The reader's metadata value type: what `inspect` shows is what the writer takes.
pub use super::metadata::MetaValue;

/// Metadata by name: the reader's [`Metadata`](super::Metadata), a `BTreeMap` so entries
/// come out sorted, as OpenVDB writes them.
pub type MetaMap = super::Metadata;

/// Options beyond the compression.
#[derive(Debug, Clone, PartialEq)]
pub struct WriteOptions {
    pub compression: Compression,
    /// File-level metadata (OpenVDB's "file metadata"); `creator` is added if absent.
    pub file_metadata: MetaMap,
    /// Extra metadata per grid, by grid index (may be shorter than the grid list). Entries
    /// override the ones the writer adds (`class`, `name`, `dx`, …).
    pub grid_metadata: Vec<MetaMap>,
}

impl WriteOptions {
    pub fn new(compression: Compression) -> Self {
        WriteOptions {
            compression,
            file_metadata: MetaMap::new(),
            grid_metadata: Vec::new(),
        }
    }
}

#[derive(Debug, Error)]
pub enum WriteError {
    #[error("{}: cannot write", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: grid {grid:?}: {reason}", path.display())]
    InvalidGrid {
        path: PathBuf,
        grid: String,
        reason: Unwritable,
    },
    #[error("{}: file {reason}", path.display())]
    InvalidMetadata { path: PathBuf, reason: Unwritable },
}

/// What in a grid or its metadata an OpenVDB file cannot hold, found before anything is
/// written.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum Unwritable {
    /// OpenVDB could not invert (zero, negative or non-finite scale) or place (non-finite
    /// translation) the transform.
    #[error("transform {transform:?} is not a positive finite scale + translation")]
    Transform { transform: Transform },
    /// A metadata entry of a type the reader only names.
    #[error("metadata {name:?}: cannot write metadata of type {type_name:?}")]
    MetadataType { name: String, type_name: String },
    /// `what` (`tile` or `leaf`) does not start on a multiple of its node's size.
    #[error("{what} origin {origin:?} is not a multiple of {size}")]
    Misaligned {
        what: &'static str,
        origin: [i32; 3],
        size: i32,
    },
    #[error("tile at {origin:?} has size {size}, expected 8, 128 or 4096")]
    TileSize { origin: [i32; 3], size: u32 },
    #[error("two tiles at {origin:?}")]
    TwoTiles { origin: [i32; 3] },
    #[error("two leaves at {origin:?}")]
    TwoLeaves { origin: [i32; 3] },
    /// `what` (`tile` or `leaf`) inside a tile of the upper internal level.
    #[error("{what} at {origin:?} lies inside a 128³ tile")]
    InsideUpperTile {
        what: &'static str,
        origin: [i32; 3],
    },
    /// A leaf inside a tile of the lower internal level.
    #[error("leaf at {origin:?} lies inside an 8³ tile")]
    InsideLowerTile { origin: [i32; 3] },
    /// Anything inside a root tile (4096³).
    #[error("{origin:?} lies inside a 4096³ tile")]
    InsideRootTile { origin: [i32; 3] },
}

/// Writes `grids` to `path` with the given compression. Returns the file size in bytes.
pub fn write_vdb(
    path: &Path,
    grids: &[AnyGrid],
    compression: Compression,
) -> Result<u64, WriteError> {
    write_vdb_with(path, grids, &WriteOptions::new(compression))
}

/// Writes `grids` to `path`. Returns the file size in bytes.
pub fn write_vdb_with(
    path: &Path,
    grids: &[AnyGrid],
    options: &WriteOptions,
) -> Result<u64, WriteError> {
    // Encode every grid in memory first: offsets are then known before anything is written.
    let names = unique_names(grids);
    let mut bodies = Vec::with_capacity(grids.len());
    for (index, grid) in grids.iter().enumerate() {
        let extra = options.grid_metadata.get(index);
        let body = match grid {
            AnyGrid::Float(g) => encode_grid(g, options.compression, extra),
            AnyGrid::Double(g) => encode_grid(g, options.compression, extra),
            AnyGrid::Vec3s(g) => encode_grid(g, options.compression, extra),
            AnyGrid::Vec3d(g) => encode_grid(g, options.compression, extra),
        }
        .map_err(|reason| WriteError::InvalidGrid {
            path: path.to_path_buf(),
            grid: grid.name().to_string(),
            reason,
        })?;
        bodies.push(body);
    }

    // Header and file metadata.
    let mut head = Vec::new();
    head.extend_from_slice(&MAGIC.to_le_bytes());
    head.extend_from_slice(&FILE_VERSION.to_le_bytes());
    head.extend_from_slice(&LIBRARY_VERSION.0.to_le_bytes());
    head.extend_from_slice(&LIBRARY_VERSION.1.to_le_bytes());
    head.push(1); // has grid offsets
    head.extend_from_slice(uuid(grids, &names).as_bytes());
    let mut file_meta = options.file_metadata.clone();
    file_meta
        .entry("creator".to_string())
        .or_insert_with(|| MetaValue::String(format!("qbricks {}", env!("CARGO_PKG_VERSION"))));
    metadata::write_meta_map(&mut head, &file_meta).map_err(|reason| {
        WriteError::InvalidMetadata {
            path: path.to_path_buf(),
            reason,
        }
    })?;
    head.extend_from_slice(&(grids.len() as i32).to_le_bytes());

    // Grid descriptors with their offsets, each followed by the grid body.
    let mut pos = head.len() as u64;
    let mut chunks: Vec<Vec<u8>> = Vec::with_capacity(grids.len());
    for ((grid, name), body) in grids.iter().zip(&names).zip(&bodies) {
        let mut desc = Vec::new();
        write_string(&mut desc, name);
        write_string(&mut desc, tree_type(grid));
        write_string(&mut desc, ""); // instance parent
        let grid_pos = pos + desc.len() as u64 + 24;
        let block_pos = grid_pos + body.head.len() as u64;
        let end_pos = block_pos + body.buffers.iter().map(|b| b.len() as u64).sum::<u64>();
        for p in [grid_pos, block_pos, end_pos] {
            desc.extend_from_slice(&(p as i64).to_le_bytes());
        }
        pos = end_pos;
        chunks.push(desc);
    }

    write_atomically(path, |out| {
        out.write_all(&head)?;
        for (desc, body) in chunks.iter().zip(&bodies) {
            out.write_all(desc)?;
            out.write_all(&body.head)?;
            for b in &body.buffers {
                out.write_all(b)?;
            }
        }
        Ok(())
    })?;
    Ok(pos)
}

fn tree_type(grid: &AnyGrid) -> &'static str {
    match grid {
        AnyGrid::Float(_) => f32::TREE_TYPE,
        AnyGrid::Double(_) => f64::TREE_TYPE,
        AnyGrid::Vec3s(_) => <[f32; 3]>::TREE_TYPE,
        AnyGrid::Vec3d(_) => <[f64; 3]>::TREE_TYPE,
    }
}

/// Descriptor names as OpenVDB makes them: a name used more than once, or empty, gets a
/// suffix `"\x1e<n>"` so every descriptor is unique.
fn unique_names(grids: &[AnyGrid]) -> Vec<String> {
    let mut count: BTreeMap<&str, usize> = BTreeMap::new();
    for g in grids {
        *count.entry(g.name()).or_default() += 1;
    }
    let mut used = std::collections::BTreeSet::new();
    grids
        .iter()
        .map(|g| {
            let base = g.name();
            let mut name = base.to_string();
            if base.is_empty() || count[base] > 1 {
                name = format!("{base}\x1e0");
            }
            let mut n = 1;
            while used.contains(&name) {
                name = format!("{base}\x1e{n}");
                n += 1;
            }
            used.insert(name.clone());
            name
        })
        .collect()
}

/// Writes through `f` with [`files::output::write_atomic`] (temporary file next to
/// `path`, synced, renamed over it; removed on error or SIGINT/SIGTERM).
fn write_atomically(
    path: &Path,
    f: impl FnOnce(&mut BufWriter<&mut File>) -> std::io::Result<()>,
) -> Result<(), WriteError> {
    files::output::write_atomic(path, |file| {
        let mut out = BufWriter::with_capacity(1 << 20, file);
        f(&mut out)?;
        out.flush()
    })
    .map_err(|source| WriteError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// A deterministic UUID-shaped tag: two FNV-1a hashes of the grid names and shapes.
fn uuid(grids: &[AnyGrid], names: &[String]) -> String {
    let mut text = String::new();
    for (g, name) in grids.iter().zip(names) {
        let (t, leaves, tiles) = (g.transform(), g.leaf_count(), g.tile_count());
        text.push_str(&format!(
            "{name}/{}/{:?}/{:?}/{leaves}/{tiles};",
            tree_type(g),
            t.voxel_size,
            t.translation
        ));
    }
    let fnv = |seed: u64| {
        text.bytes().fold(seed, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01B3)
        })
    };
    let hex = format!(
        "{:016X}{:016X}",
        fnv(0xCBF2_9CE4_8422_2325),
        fnv(0x84222325_CBF29CE4)
    );
    format!(
        "{}-{}-{}-{}-{}",
        &hex[0..8],
        &hex[8..12],
        &hex[12..16],
        &hex[16..20],
        &hex[20..32]
    )
}

/// A string as OpenVDB stores it: `u32` length, then the bytes.
fn write_string(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

/// A grid's record after its descriptor, encoded: offsets follow from the lengths.
struct EncodedGrid {
    /// Compression flags, metadata, transform, topology.
    head: Vec<u8>,
    /// Leaf buffers in tree order.
    buffers: Vec<Vec<u8>>,
}

/// Compression flags, grid metadata, transform, then the tree (see [`tree`]).
fn encode_grid<V: VdbValue>(
    grid: &Grid<V>,
    compression: Compression,
    extra: Option<&MetaMap>,
) -> Result<EncodedGrid, Unwritable> {
    let t = grid.transform;
    transform::check_transform(&t)?;
    let nodes = tree::build_tree(grid)?;
    let flags = compression.flags();
    let mut head = Vec::new();
    head.extend_from_slice(&flags.0.to_le_bytes());
    metadata::write_meta_map(
        &mut head,
        &metadata::grid_metadata(grid, compression, extra),
    )?;
    transform::write_transform(&mut head, &t);
    let buffers = tree::write_tree(&mut head, &nodes, flags);
    Ok(EncodedGrid { head, buffers })
}
