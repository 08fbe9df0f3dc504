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
//! Grids are written from [`source::GridSource`]s: their shapes (leaf origins and masks)
//! are placed and the topology written first, then the leaf values are asked for and
//! encoded one batch of [`BATCH_LEAVES`] at a time, so memory holds the shapes and one
//! batch, never the file. The grid descriptors' offsets, known only once a grid's buffers
//! are written, are filled in at the end (OpenVDB's own writer seeks back the same way).
//!
//! The modules mirror the reader's, record by record: this one writes the header and the
//! grid descriptors and puts each grid's record together; [`metadata`], [`transform`] and
//! [`tree`] write those parts of a grid, [`values`] the values of one node, [`compress`] one
//! block of them. What both sides share (magic, flags, node metadata codes, value types)
//! is in [`super::codec`].

mod compress;
mod metadata;
pub mod source;
mod transform;
mod tree;
mod values;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use thiserror::Error;

use super::codec::{CompressionFlags, VdbValue, MAGIC};
use crate::grid::{AnyGrid, Transform};
use source::{with_source, AnySource, GridSource};

/// Leaves whose values are made and encoded together (in parallel) before they are
/// written: 4096 leaves of 3-vectors are 25 MB of values, and as much again encoded.
pub const BATCH_LEAVES: usize = 4096;

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
    let sources: Vec<AnySource<'_>> = grids.iter().map(AnySource::of).collect();
    write_sources(path, &sources, options, &mut |_| {})
}

/// Writes `grids` to `path`, asking for their leaf values a batch at a time (see the module
/// docs); `progress` is told the leaves written so far, of all grids, after every batch.
/// Returns the file size in bytes.
pub fn write_sources(
    path: &Path,
    grids: &[AnySource<'_>],
    options: &WriteOptions,
    progress: &mut dyn FnMut(u64),
) -> Result<u64, WriteError> {
    // Every grid's head (metadata, transform, topology) first: whatever a grid cannot hold
    // is found before a byte is written.
    let names = unique_names(grids);
    let mut heads = Vec::with_capacity(grids.len());
    for (index, grid) in grids.iter().enumerate() {
        let extra = options.grid_metadata.get(index);
        let head = with_source!(grid, g => encode_head(g, options.compression, extra)).map_err(
            |reason| WriteError::InvalidGrid {
                path: path.to_path_buf(),
                grid: grid.name().to_string(),
                reason,
            },
        )?;
        heads.push(head);
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

    let flags = options.compression.flags();
    write_atomically(path, |out| {
        out.write_all(&head)?;
        let mut pos = head.len() as u64;
        let mut done = 0u64;
        // Where each descriptor's three offsets go, and their values.
        let mut offsets: Vec<(u64, [u64; 3])> = Vec::with_capacity(grids.len());
        for ((grid, name), (grid_head, order)) in grids.iter().zip(&names).zip(&heads) {
            let mut desc = Vec::new();
            write_string(&mut desc, name);
            write_string(&mut desc, tree_type(grid));
            write_string(&mut desc, ""); // instance parent
            let at = pos + desc.len() as u64;
            desc.extend_from_slice(&[0; 24]); // grid, block and end offsets, filled in below
            out.write_all(&desc)?;
            pos += desc.len() as u64;
            let grid_pos = pos;
            out.write_all(grid_head)?;
            pos += grid_head.len() as u64;
            let block_pos = pos;
            for batch in order.chunks(BATCH_LEAVES) {
                let buffers = with_source!(grid, g => tree::leaf_buffers(g, batch, flags));
                for b in &buffers {
                    out.write_all(b)?;
                    pos += b.len() as u64;
                }
                done += batch.len() as u64;
                progress(done);
            }
            offsets.push((at, [grid_pos, block_pos, pos]));
        }
        for (at, values) in offsets {
            out.seek(SeekFrom::Start(at))?;
            for p in values {
                out.write_all(&(p as i64).to_le_bytes())?;
            }
        }
        out.seek(SeekFrom::Start(pos))?;
        Ok(pos)
    })
}

/// Most bytes [`write_sources`] writes for `grids` with any compression: every value
/// stored raw, internal nodes' included, and room for the file's and grids' metadata.
/// What a disk must have free for the file.
pub fn size_bound(grids: &[AnySource<'_>]) -> u64 {
    grids.iter().fold(FILE_META_BYTES, |acc, grid| {
        let (value, leaves, tiles) = with_source!(grid, g => (
            std::mem::size_of_val(&g.background) as u64,
            &g.leaves,
            g.tiles.len() as u64,
        ));
        let nodes = |shift: u32| {
            let mut keys: Vec<[i32; 3]> = leaves
                .iter()
                .map(|l| l.origin.map(|v| v >> shift))
                .collect();
            keys.sort_unstable();
            keys.dedup();
            keys.len() as u64
        };
        let counts = NodeCounts {
            leaves: leaves.len() as u64,
            lower: nodes(7),
            upper: nodes(12),
            tiles,
        };
        acc.saturating_add(counts.bound(value))
    })
}

/// Room for a file's header and metadata, and for one grid's descriptor, metadata and
/// transform: what [`NodeCounts::bound`] adds besides the nodes.
const FILE_META_BYTES: u64 = 64 << 10;

/// How many nodes of each kind a grid has: what bounds its size in a file.
#[derive(Debug, Clone, Copy, Default)]
pub struct NodeCounts {
    pub leaves: u64,
    /// Lower internal nodes (128³ voxels each).
    pub lower: u64,
    /// Upper internal nodes (4096³ voxels each), the root's children.
    pub upper: u64,
    /// Active tiles at any level.
    pub tiles: u64,
}

impl NodeCounts {
    /// Most bytes the grid takes in a file, with values of `value_bytes` each stored raw:
    /// per node its masks, compression byte and values, and a compressed block's size
    /// prefix; per leaf also its mask in the topology.
    pub fn bound(&self, value_bytes: u64) -> u64 {
        let node = |slots: u64| slots / 4 + 1 + 8 + slots * value_bytes;
        [
            (self.upper, node(32 * 32 * 32) + 12),
            (self.lower, node(16 * 16 * 16)),
            (self.leaves, 64 + node(512)),
            (self.tiles, 12 + value_bytes + 1),
        ]
        .iter()
        .fold(FILE_META_BYTES, |acc, &(n, bytes)| {
            acc.saturating_add(n.saturating_mul(bytes))
        })
    }
}

fn tree_type(grid: &AnySource<'_>) -> &'static str {
    match grid {
        AnySource::Float(_) => f32::TREE_TYPE,
        AnySource::Double(_) => f64::TREE_TYPE,
        AnySource::Vec3s(_) => <[f32; 3]>::TREE_TYPE,
        AnySource::Vec3d(_) => <[f64; 3]>::TREE_TYPE,
    }
}

/// Descriptor names as OpenVDB makes them: a name used more than once, or empty, gets a
/// suffix `"\x1e<n>"` so every descriptor is unique.
fn unique_names(grids: &[AnySource<'_>]) -> Vec<String> {
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
fn write_atomically<T>(
    path: &Path,
    f: impl FnOnce(&mut BufWriter<&mut File>) -> std::io::Result<T>,
) -> Result<T, WriteError> {
    files::output::write_atomic(path, |file| {
        let mut out = BufWriter::with_capacity(1 << 20, file);
        let value = f(&mut out)?;
        out.flush()?;
        Ok(value)
    })
    .map_err(|source| WriteError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// A deterministic UUID-shaped tag: two FNV-1a hashes of the grid names and shapes.
fn uuid(grids: &[AnySource<'_>], names: &[String]) -> String {
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

/// A grid's record after its descriptor up to its leaf buffers (compression flags, grid
/// metadata, transform, topology), and the order in which the buffers follow it (leaf
/// indices of the source).
fn encode_head<V: VdbValue>(
    grid: &GridSource<'_, V>,
    compression: Compression,
    extra: Option<&MetaMap>,
) -> Result<(Vec<u8>, Vec<usize>), Unwritable> {
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
    let order = tree::write_topology(&mut head, &nodes, &grid.leaves, flags);
    Ok((head, order))
}
