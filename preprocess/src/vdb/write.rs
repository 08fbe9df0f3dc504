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
//! see [`NodeMeta`]), then the values it says must be stored, each block optionally
//! zlib-compressed behind an `i64` size (negative: stored raw).
//!
//! Output is deterministic (same grids → same bytes) and atomic: the file is written through
//! `format::output::write_atomic` (temporary name in the target directory, synced, renamed
//! over the target).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use flate2::write::ZlibEncoder;
use rayon::prelude::*;
use thiserror::Error;

use super::codec::{mask_is_on, CompressionFlags, NodeMeta, VdbValue, MAGIC};
use crate::grid::{AnyGrid, Grid, Leaf, Tile, Transform, LEAF_VOXELS};

/// `OPENVDB_FILE_VERSION_MULTIPASS_IO`: the newest format before half-float grid types.
pub const FILE_VERSION: u32 = 224;
/// Library version written into the header: qbricks' own, not an OpenVDB release.
pub const LIBRARY_VERSION: (u32, u32) = (0, 1);

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
    pub fn flags(self) -> CompressionFlags {
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

/// OpenVDB type name and little-endian bytes of a metadata value; `Other` (a type the
/// reader only names) cannot be written.
fn meta_encoding(value: &MetaValue) -> Result<(&'static str, Vec<u8>), String> {
    let mut b = Vec::new();
    let name = match value {
        MetaValue::Bool(v) => {
            b.push(u8::from(*v));
            "bool"
        }
        MetaValue::Int32(v) => {
            b.extend_from_slice(&v.to_le_bytes());
            "int32"
        }
        MetaValue::Int64(v) => {
            b.extend_from_slice(&v.to_le_bytes());
            "int64"
        }
        MetaValue::Float(v) => {
            b.extend_from_slice(&v.to_le_bytes());
            "float"
        }
        MetaValue::Double(v) => {
            b.extend_from_slice(&v.to_le_bytes());
            "double"
        }
        MetaValue::String(v) => {
            b.extend_from_slice(v.as_bytes());
            "string"
        }
        MetaValue::Vec3i(v) => {
            v.iter().for_each(|c| b.extend_from_slice(&c.to_le_bytes()));
            "vec3i"
        }
        MetaValue::Vec3s(v) => {
            v.iter().for_each(|c| b.extend_from_slice(&c.to_le_bytes()));
            "vec3s"
        }
        MetaValue::Vec3d(v) => {
            v.iter().for_each(|c| b.extend_from_slice(&c.to_le_bytes()));
            "vec3d"
        }
        MetaValue::Other(t) => return Err(format!("cannot write metadata of type {t:?}")),
    };
    Ok((name, b))
}

/// Metadata by name; a `BTreeMap` so entries come out sorted, as OpenVDB writes them.
pub type MetaMap = BTreeMap<String, MetaValue>;

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
        reason: String,
    },
    #[error("{}: file {reason}", path.display())]
    InvalidMetadata { path: PathBuf, reason: String },
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
    write_meta_map(&mut head, &file_meta).map_err(|reason| WriteError::InvalidMetadata {
        path: path.to_path_buf(),
        reason,
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

/// Writes through `f` with [`format::output::write_atomic`] (temporary file next to
/// `path`, synced, renamed over it; removed on error or SIGINT/SIGTERM).
fn write_atomically(
    path: &Path,
    f: impl FnOnce(&mut BufWriter<&mut File>) -> std::io::Result<()>,
) -> Result<(), WriteError> {
    format::output::write_atomic(path, |file| {
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

fn write_string(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

fn write_meta_map(out: &mut Vec<u8>, meta: &MetaMap) -> Result<(), String> {
    out.extend_from_slice(&(meta.len() as u32).to_le_bytes());
    for (name, value) in meta {
        let (type_name, bytes) =
            meta_encoding(value).map_err(|e| format!("metadata {name:?}: {e}"))?;
        write_string(out, name);
        write_string(out, type_name);
        out.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
        out.extend_from_slice(&bytes);
    }
    Ok(())
}

/// Leaves, lower internal nodes (16³ children of 8³) and upper internal nodes (32³
/// children of 128³), keyed by their index inside the parent, in the order OpenVDB visits
/// them.
struct Lower<'a, V> {
    leaves: BTreeMap<usize, &'a Leaf<V>>,
    tiles: BTreeMap<usize, V>,
}

struct Upper<'a, V> {
    children: BTreeMap<usize, Lower<'a, V>>,
    tiles: BTreeMap<usize, V>,
}

enum RootEntry<'a, V> {
    Child(Upper<'a, V>),
    Tile(V),
}

struct EncodedGrid {
    /// Compression flags, metadata, transform, topology.
    head: Vec<u8>,
    /// Leaf buffers in tree order.
    buffers: Vec<Vec<u8>>,
}

fn upper_index(p: [i32; 3]) -> usize {
    (((p[0] & 4095) >> 7) as usize) << 10
        | (((p[1] & 4095) >> 7) as usize) << 5
        | ((p[2] & 4095) >> 7) as usize
}

fn lower_index(p: [i32; 3]) -> usize {
    (((p[0] & 127) >> 3) as usize) << 8
        | (((p[1] & 127) >> 3) as usize) << 4
        | ((p[2] & 127) >> 3) as usize
}

fn root_key(p: [i32; 3]) -> [i32; 3] {
    p.map(|v| v & !4095)
}

fn build_tree<V: VdbValue>(grid: &Grid<V>) -> Result<Root<'_, V>, String> {
    let mut root: Root<'_, V> = BTreeMap::new();
    // Root tiles first, so that anything placed inside one is reported.
    for t in grid.tiles.iter().filter(|t| t.size == 4096) {
        check_aligned(t.origin, 4096, "tile")?;
        if root.insert(t.origin, RootEntry::Tile(t.value)).is_some() {
            return Err(format!("two tiles at {:?}", t.origin));
        }
    }
    for t in grid.tiles.iter().filter(|t| t.size != 4096) {
        match t.size {
            128 => {
                check_aligned(t.origin, 128, "tile")?;
                let u = upper_of(&mut root, t.origin)?;
                if u.tiles.insert(upper_index(t.origin), t.value).is_some() {
                    return Err(format!("two tiles at {:?}", t.origin));
                }
            }
            8 => {
                check_aligned(t.origin, 8, "tile")?;
                let u = upper_of(&mut root, t.origin)?;
                let ui = upper_index(t.origin);
                if u.tiles.contains_key(&ui) {
                    return Err(format!("tile at {:?} lies inside a 128³ tile", t.origin));
                }
                let lower = u.children.entry(ui).or_insert_with(|| Lower {
                    leaves: BTreeMap::new(),
                    tiles: BTreeMap::new(),
                });
                if lower.tiles.insert(lower_index(t.origin), t.value).is_some() {
                    return Err(format!("two tiles at {:?}", t.origin));
                }
            }
            other => {
                return Err(format!(
                    "tile at {:?} has size {other}, expected 8, 128 or 4096",
                    t.origin
                ))
            }
        }
    }
    for leaf in &grid.leaves {
        check_aligned(leaf.origin, 8, "leaf")?;
        let u = upper_of(&mut root, leaf.origin)?;
        let ui = upper_index(leaf.origin);
        if u.tiles.contains_key(&ui) {
            return Err(format!("leaf at {:?} lies inside a 128³ tile", leaf.origin));
        }
        let lower = u.children.entry(ui).or_insert_with(|| Lower {
            leaves: BTreeMap::new(),
            tiles: BTreeMap::new(),
        });
        let li = lower_index(leaf.origin);
        if lower.tiles.contains_key(&li) {
            return Err(format!("leaf at {:?} lies inside an 8³ tile", leaf.origin));
        }
        if lower.leaves.insert(li, leaf).is_some() {
            return Err(format!("two leaves at {:?}", leaf.origin));
        }
    }
    Ok(root)
}

type Root<'a, V> = BTreeMap<[i32; 3], RootEntry<'a, V>>;

/// The upper internal node holding `origin`, created if missing.
fn upper_of<'m, 'a, V>(
    root: &'m mut Root<'a, V>,
    origin: [i32; 3],
) -> Result<&'m mut Upper<'a, V>, String> {
    let entry = root.entry(root_key(origin)).or_insert_with(|| {
        RootEntry::Child(Upper {
            children: BTreeMap::new(),
            tiles: BTreeMap::new(),
        })
    });
    match entry {
        RootEntry::Child(u) => Ok(u),
        RootEntry::Tile(_) => Err(format!("{origin:?} lies inside a 4096³ tile")),
    }
}

fn check_aligned(origin: [i32; 3], size: i32, what: &str) -> Result<(), String> {
    if origin.iter().any(|v| v.rem_euclid(size) != 0) {
        return Err(format!(
            "{what} origin {origin:?} is not a multiple of {size}"
        ));
    }
    Ok(())
}

fn encode_grid<V: VdbValue>(
    grid: &Grid<V>,
    compression: Compression,
    extra: Option<&MetaMap>,
) -> Result<EncodedGrid, String> {
    let t = grid.transform;
    if !(t.voxel_size.iter().all(|v| v.is_finite() && *v > 0.0)
        && t.translation.iter().all(|v| v.is_finite()))
    {
        return Err(format!(
            "transform {t:?} is not a positive finite scale + translation"
        ));
    }
    let root = build_tree(grid)?;
    let flags = compression.flags();
    let mut head = Vec::new();
    head.extend_from_slice(&flags.0.to_le_bytes());
    write_meta_map(&mut head, &grid_metadata(grid, compression, extra))?;
    write_transform(&mut head, &t);

    // Topology.
    head.extend_from_slice(&1i32.to_le_bytes()); // buffer count
    grid.background.put(&mut head);
    let tiles = root
        .values()
        .filter(|e| matches!(e, RootEntry::Tile(_)))
        .count() as u32;
    let children = root.len() as u32 - tiles;
    head.extend_from_slice(&tiles.to_le_bytes());
    head.extend_from_slice(&children.to_le_bytes());
    for (key, entry) in &root {
        if let RootEntry::Tile(v) = entry {
            key.iter()
                .for_each(|c| head.extend_from_slice(&c.to_le_bytes()));
            v.put(&mut head);
            head.push(1); // active
        }
    }
    let mut leaves: Vec<&Leaf<V>> = Vec::with_capacity(grid.leaves.len());
    for (key, entry) in &root {
        let RootEntry::Child(upper) = entry else {
            continue;
        };
        key.iter()
            .for_each(|c| head.extend_from_slice(&c.to_le_bytes()));
        let children: Vec<usize> = upper.children.keys().copied().collect();
        write_internal(
            &mut head,
            32 * 32 * 32,
            &children,
            &upper.tiles,
            grid.background,
            flags,
        );
        for lower in upper.children.values() {
            let children: Vec<usize> = lower.leaves.keys().copied().collect();
            write_internal(
                &mut head,
                16 * 16 * 16,
                &children,
                &lower.tiles,
                grid.background,
                flags,
            );
            for leaf in lower.leaves.values() {
                leaf.active
                    .iter()
                    .for_each(|w| head.extend_from_slice(&w.to_le_bytes()));
                leaves.push(leaf);
            }
        }
    }

    // Leaf buffers, encoded in parallel, kept in order.
    let buffers = leaves
        .par_iter()
        .map(|leaf| {
            let mut out = Vec::with_capacity(64 + 1 + LEAF_VOXELS * V::SIZE);
            leaf.active
                .iter()
                .for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
            write_values(
                &mut out,
                &leaf.values[..],
                &leaf.active[..],
                None,
                grid.background,
                flags,
            );
            out
        })
        .collect();
    Ok(EncodedGrid { head, buffers })
}

fn grid_metadata<V: VdbValue>(
    grid: &Grid<V>,
    compression: Compression,
    extra: Option<&MetaMap>,
) -> MetaMap {
    let mut meta = MetaMap::new();
    let s = |v: &str| MetaValue::String(v.to_string());
    meta.insert("class".into(), s("unknown"));
    meta.insert("name".into(), s(&grid.name));
    meta.insert("file_compression".into(), s(compression.describe()));
    meta.insert("is_saved_as_half_float".into(), MetaValue::Bool(false));
    meta.insert("value_type".into(), s(V::VALUE_TYPE));
    meta.insert("dx".into(), MetaValue::Double(grid.transform.voxel_size[0]));
    if V::IS_VECTOR {
        meta.insert("vector_type".into(), s("invariant"));
    }
    meta.insert(
        "file_voxel_count".into(),
        MetaValue::Int64(grid.active_voxel_count() as i64),
    );
    if let Some((lo, hi)) = active_bbox(grid) {
        meta.insert("file_bbox_min".into(), MetaValue::Vec3i(lo));
        meta.insert("file_bbox_max".into(), MetaValue::Vec3i(hi));
    }
    if let Some(extra) = extra {
        for (k, v) in extra {
            meta.insert(k.clone(), v.clone());
        }
    }
    meta
}

/// Inclusive index-space bounding box of the active voxels and tiles.
fn active_bbox<V: VdbValue>(grid: &Grid<V>) -> Option<([i32; 3], [i32; 3])> {
    let mut lo = [i32::MAX; 3];
    let mut hi = [i32::MIN; 3];
    let mut any = false;
    let mut add = |a: [i32; 3], b: [i32; 3]| {
        any = true;
        for i in 0..3 {
            lo[i] = lo[i].min(a[i]);
            hi[i] = hi[i].max(b[i]);
        }
    };
    for leaf in &grid.leaves {
        for (ijk, _) in leaf.active_voxels() {
            add(ijk, ijk);
        }
    }
    for t in &grid.tiles {
        let Tile { origin, size, .. } = *t;
        let far = origin.map(|v| v.saturating_add(size as i32 - 1));
        add(origin, far);
    }
    any.then_some((lo, hi))
}

fn write_transform(out: &mut Vec<u8>, t: &Transform) {
    let s = t.voxel_size;
    let uniform = s[0] == s[1] && s[1] == s[2];
    write_string(
        out,
        if uniform {
            "UniformScaleTranslateMap"
        } else {
            "ScaleTranslateMap"
        },
    );
    // translation, scale, voxel size, 1/scale, 1/scale², 1/(2 scale)
    let rows = [
        t.translation,
        s,
        s,
        s.map(|v| 1.0 / v),
        s.map(|v| 1.0 / (v * v)),
        s.map(|v| 0.5 / v),
    ];
    for row in rows {
        row.iter()
            .for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
    }
}

/// Child mask, value mask and compressed values of an internal node with `size` slots.
fn write_internal<V: VdbValue>(
    out: &mut Vec<u8>,
    size: usize,
    children: &[usize],
    tiles: &BTreeMap<usize, V>,
    background: V,
    flags: CompressionFlags,
) {
    let words = size / 64;
    let mut child_mask = vec![0u64; words];
    let mut value_mask = vec![0u64; words];
    for &c in children {
        child_mask[c >> 6] |= 1 << (c & 63);
    }
    // Slots that are neither children nor tiles hold the background; child slots hold zero.
    let mut values = vec![background; size];
    for &c in children {
        values[c] = V::default();
    }
    for (&i, &v) in tiles {
        value_mask[i >> 6] |= 1 << (i & 63);
        values[i] = v;
    }
    child_mask
        .iter()
        .for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
    value_mask
        .iter()
        .for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
    write_values(
        out,
        &values,
        &value_mask,
        Some(&child_mask),
        background,
        flags,
    );
}

/// OpenVDB's `writeCompressedValues`: metadata byte, the inactive values it needs, an
/// optional selection mask, then the stored values (zlib-compressed if asked).
fn write_values<V: VdbValue>(
    out: &mut Vec<u8>,
    values: &[V],
    active: &[u64],
    children: Option<&[u64]>,
    background: V,
    flags: CompressionFlags,
) {
    let is_on = |n: usize| mask_is_on(active, n);
    let is_child = |n: usize| children.is_some_and(|c| mask_is_on(c, n));
    let mut stored: Vec<V> = Vec::with_capacity(values.len());
    if !flags.contains(CompressionFlags::ACTIVE_MASK) {
        out.push(NodeMeta::NoMaskAndAllVals as u8);
        stored.extend_from_slice(values);
    } else {
        // Classify the inactive values (child slots excluded), as MaskCompress does.
        let mut inactive = [background; 2];
        let mut unique = 0;
        for (n, v) in values.iter().enumerate() {
            if unique >= 3 {
                break;
            }
            if is_on(n) || is_child(n) {
                continue;
            }
            let seen = (unique > 0 && *v == inactive[0]) || (unique > 1 && *v == inactive[1]);
            if !seen {
                if unique < 2 {
                    inactive[unique] = *v;
                }
                unique += 1;
            }
        }
        let neg_bg = background.negate();
        let meta = match unique {
            0 => NodeMeta::NoMaskOrInactiveVals,
            1 if inactive[0] == background => NodeMeta::NoMaskOrInactiveVals,
            1 if inactive[0] == neg_bg => NodeMeta::NoMaskAndMinusBg,
            1 => NodeMeta::NoMaskAndOneInactiveVal,
            2 if inactive[0] != background && inactive[1] != background => {
                NodeMeta::MaskAndTwoInactiveVals
            }
            2 if inactive[1] == background => {
                if inactive[0] == neg_bg {
                    NodeMeta::MaskAndNoInactiveVals
                } else {
                    NodeMeta::MaskAndOneInactiveVal
                }
            }
            2 => {
                // inactive[0] is the background: the other value goes first.
                inactive.swap(0, 1);
                if inactive[0] == neg_bg {
                    NodeMeta::MaskAndNoInactiveVals
                } else {
                    NodeMeta::MaskAndOneInactiveVal
                }
            }
            _ => NodeMeta::NoMaskAndAllVals,
        };
        out.push(meta as u8);
        match meta {
            NodeMeta::NoMaskAndOneInactiveVal | NodeMeta::MaskAndOneInactiveVal => {
                inactive[0].put(out)
            }
            NodeMeta::MaskAndTwoInactiveVals => {
                inactive[0].put(out);
                inactive[1].put(out);
            }
            _ => {}
        }
        match meta {
            NodeMeta::NoMaskAndAllVals => stored.extend_from_slice(values),
            NodeMeta::NoMaskOrInactiveVals
            | NodeMeta::NoMaskAndMinusBg
            | NodeMeta::NoMaskAndOneInactiveVal => {
                stored.extend((0..values.len()).filter(|&n| is_on(n)).map(|n| values[n]));
            }
            NodeMeta::MaskAndNoInactiveVals
            | NodeMeta::MaskAndOneInactiveVal
            | NodeMeta::MaskAndTwoInactiveVals => {
                // Selection bit set where an inactive value equals inactive[1].
                let mut selection = vec![0u64; values.len().div_ceil(64)];
                for (n, v) in values.iter().enumerate() {
                    if is_on(n) {
                        stored.push(*v);
                    } else if *v == inactive[1] {
                        selection[n >> 6] |= 1 << (n & 63);
                    }
                }
                selection
                    .iter()
                    .for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
            }
        }
    }
    let mut raw = Vec::with_capacity(stored.len() * V::SIZE);
    stored.iter().for_each(|v| v.put(&mut raw));
    if flags.contains(CompressionFlags::ZIP) {
        write_zipped(out, &raw);
    } else {
        out.extend_from_slice(&raw);
    }
}

/// `zipToStream`: `i64` size then zlib data, or `-size` then the raw bytes when zlib does
/// not make them smaller.
fn write_zipped(out: &mut Vec<u8>, raw: &[u8]) {
    let mut enc = ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    let zipped = enc.write_all(raw).and_then(|()| enc.finish());
    match zipped {
        Ok(z) if z.len() < raw.len() => {
            out.extend_from_slice(&(z.len() as i64).to_le_bytes());
            out.extend_from_slice(&z);
        }
        _ => {
            out.extend_from_slice(&(-(raw.len() as i64)).to_le_bytes());
            out.extend_from_slice(raw);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metadata_encodes_as_openvdb_types_and_refuses_unknown_ones() {
        let mut out = Vec::new();
        let mut meta = MetaMap::new();
        meta.insert("dx".into(), MetaValue::Double(0.5));
        write_meta_map(&mut out, &meta).expect("double metadata");
        let mut want = 1u32.to_le_bytes().to_vec();
        for s in ["dx", "double"] {
            want.extend_from_slice(&(s.len() as u32).to_le_bytes());
            want.extend_from_slice(s.as_bytes());
        }
        want.extend_from_slice(&8u32.to_le_bytes());
        want.extend_from_slice(&0.5f64.to_le_bytes());
        assert_eq!(out, want);

        meta.insert("m".into(), MetaValue::Other("mat4d".into()));
        let err = write_meta_map(&mut Vec::new(), &meta).expect_err("unknown type");
        assert!(err.contains("\"m\"") && err.contains("mat4d"), "{err}");
    }

    #[test]
    fn node_indices_follow_openvdb_bit_layout() {
        assert_eq!(upper_index([0, 0, 0]), 0);
        assert_eq!(upper_index([128, 0, 0]), 1 << 10);
        assert_eq!(upper_index([0, 128, 0]), 1 << 5);
        assert_eq!(upper_index([0, 0, 128]), 1);
        assert_eq!(upper_index([-128, -128, -128]), 31 << 10 | 31 << 5 | 31);
        assert_eq!(lower_index([8, 16, 24]), 1 << 8 | 2 << 4 | 3);
        assert_eq!(lower_index([-8, 0, 0]), 15 << 8);
        assert_eq!(root_key([-1, 4095, 4096]), [-4096, 0, 4096]);
    }

    fn classify(values: &[f32], active: &[u64], bg: f32) -> (u8, Vec<u8>) {
        let mut out = Vec::new();
        write_values(
            &mut out,
            values,
            active,
            None,
            bg,
            CompressionFlags::ACTIVE_MASK,
        );
        (out[0], out)
    }

    #[test]
    fn mask_compression_picks_the_openvdb_case() {
        let mut active = [0u64; 8];
        active[0] = 1; // voxel 0 active
        let bg = 2.0f32;
        let mut v = vec![bg; 512];
        v[0] = 7.0;
        assert_eq!(classify(&v, &active, bg).0, 0);
        let all_minus: Vec<f32> = (0..512).map(|n| if n == 0 { 7.0 } else { -bg }).collect();
        assert_eq!(classify(&all_minus, &active, bg).0, 1);
        let one_other: Vec<f32> = (0..512).map(|n| if n == 0 { 7.0 } else { 5.0 }).collect();
        let (m, bytes) = classify(&one_other, &active, bg);
        assert_eq!(m, 2);
        assert_eq!(&bytes[1..5], &5.0f32.to_le_bytes());
        let mut two = vec![bg; 512];
        two[0] = 7.0;
        two[3] = -bg;
        assert_eq!(classify(&two, &active, bg).0, 3);
        two[3] = 9.0;
        let (m, bytes) = classify(&two, &active, bg);
        assert_eq!(m, 4);
        assert_eq!(&bytes[1..5], &9.0f32.to_le_bytes());
        // 1 + 4 (value) + 64 (selection mask) + 4 (one active value)
        assert_eq!(bytes.len(), 73);
        two.iter_mut().skip(1).for_each(|x| *x = 9.0);
        two[5] = 11.0;
        assert_eq!(classify(&two, &active, bg).0, 5);
        two[6] = 12.0;
        let (m, bytes) = classify(&two, &active, bg);
        assert_eq!(m, 6);
        assert_eq!(bytes.len(), 1 + 512 * 4);
    }

    #[test]
    fn zip_falls_back_to_raw_when_it_does_not_help() {
        let mut out = Vec::new();
        write_zipped(&mut out, &[]);
        assert_eq!(out, 0i64.to_le_bytes());
        let mut out = Vec::new();
        write_zipped(&mut out, &[0u8; 4096]);
        let n = i64::from_le_bytes(out[..8].try_into().expect("8 bytes"));
        assert!(n > 0 && (n as usize) < 4096 && out.len() == 8 + n as usize);
    }

    #[test]
    fn overlapping_or_misaligned_nodes_are_refused() {
        let leaf = |origin| Leaf {
            origin,
            active: [u64::MAX; 8],
            values: Box::new([0.0f32; LEAF_VOXELS]),
        };
        let mut g = Grid {
            name: "g".into(),
            transform: Transform {
                voxel_size: [1.0; 3],
                translation: [0.0; 3],
            },
            background: 0.0f32,
            leaves: vec![leaf([0, 0, 0]), leaf([0, 0, 0])],
            tiles: Vec::new(),
        };
        assert!(build_tree(&g).is_err());
        g.leaves = vec![leaf([4, 0, 0])];
        assert!(build_tree(&g).is_err());
        g.leaves = vec![leaf([8, 0, 0])];
        g.tiles = vec![Tile {
            origin: [0, 0, 0],
            size: 128,
            value: 1.0,
        }];
        assert!(build_tree(&g).is_err());
        g.tiles[0].origin = [128, 0, 0];
        assert!(build_tree(&g).is_ok());
    }
}
