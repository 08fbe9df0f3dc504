//! File and grid metadata, the writer's side of [`crate::vdb::metadata`]: a count, then per
//! entry name, OpenVDB type name, byte size and little-endian value. Besides what the
//! caller gives, every grid gets the entries OpenVDB itself writes (`class`, `value_type`,
//! `file_bbox_min`, …) so that OpenVDB tools show the file as they would one of their own.

use super::source::{GridSource, LeafShape};
use super::{write_string, Compression, MetaMap, MetaValue, Unwritable};
use crate::grid::Tile;
use crate::vdb::codec::VdbValue;

/// OpenVDB type name and little-endian bytes of a metadata value; `None` for `Other` (a
/// type the reader only names, which cannot be written).
fn meta_encoding(value: &MetaValue) -> Option<(&'static str, Vec<u8>)> {
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
        MetaValue::Other(_) => return None,
    };
    Some((name, b))
}

pub(super) fn write_meta_map(out: &mut Vec<u8>, meta: &MetaMap) -> Result<(), Unwritable> {
    out.extend_from_slice(&(meta.len() as u32).to_le_bytes());
    for (name, value) in meta {
        let Some((type_name, bytes)) = meta_encoding(value) else {
            let type_name = match value {
                MetaValue::Other(t) => t.clone(),
                _ => String::new(),
            };
            return Err(Unwritable::MetadataType {
                name: name.clone(),
                type_name,
            });
        };
        write_string(out, name);
        write_string(out, type_name);
        out.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
        out.extend_from_slice(&bytes);
    }
    Ok(())
}

/// The entries OpenVDB writes for a grid, then `extra` (which overrides them).
pub(super) fn grid_metadata<V: VdbValue>(
    grid: &GridSource<'_, V>,
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
fn active_bbox<V: VdbValue>(grid: &GridSource<'_, V>) -> Option<([i32; 3], [i32; 3])> {
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
        if let Some((a, b)) = leaf_bbox(leaf) {
            add(a, b);
        }
    }
    for t in grid.tiles.iter() {
        let Tile { origin, size, .. } = *t;
        let far = origin.map(|v| v.saturating_add(size as i32 - 1));
        add(origin, far);
    }
    any.then_some((lo, hi))
}

/// Inclusive box of a leaf's active voxels, read from its mask a word at a time: voxel
/// `n = x·64 + y·8 + z` is bit `n % 64` of word `x`, so word `x` is active when non-zero,
/// `y` when byte `y` of the words' union is, and `z` when bit `z` of its bytes' union is.
fn leaf_bbox(leaf: &LeafShape) -> Option<([i32; 3], [i32; 3])> {
    let xs: Vec<i32> = (0..8)
        .filter(|&x| leaf.active[x] != 0)
        .map(|x| x as i32)
        .collect();
    let (&x0, &x1) = (xs.first()?, xs.last()?);
    let union = leaf.active.iter().fold(0u64, |a, w| a | w);
    let bytes = union.to_le_bytes();
    let ys: Vec<i32> = (0..8)
        .filter(|&y| bytes[y] != 0)
        .map(|y| y as i32)
        .collect();
    let zbits = bytes.iter().fold(0u8, |a, b| a | b);
    let (z0, z1) = (
        zbits.trailing_zeros() as i32,
        7 - zbits.leading_zeros() as i32,
    );
    let o = leaf.origin;
    Some((
        [o[0] + x0, o[1] + ys[0], o[2] + z0],
        [o[0] + x1, o[1] + ys[ys.len() - 1], o[2] + z1],
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The mask-word box equals the box of the voxels `Leaf::active_voxels` lists.
    #[test]
    fn leaf_box_from_mask_words_equals_voxel_box() {
        use crate::grid::{Leaf, LEAF_VOXELS};
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        for case in 0..400 {
            let mut active = [0u64; 8];
            // Sparse, dense, single voxels and empty leaves.
            let voxels = [0, 1, 2, 5, 40, 300][case % 6];
            for _ in 0..voxels {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let n = (state % LEAF_VOXELS as u64) as usize;
                active[n >> 6] |= 1 << (n & 63);
            }
            let origin = [8 * (case as i32 % 5) - 16, -8, 4096];
            let leaf = Leaf {
                origin,
                active,
                values: Box::new([0.0f32; LEAF_VOXELS]),
            };
            let mut want: Option<([i32; 3], [i32; 3])> = None;
            for (p, _) in leaf.active_voxels() {
                let (lo, hi) = want.get_or_insert((p, p));
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
            assert_eq!(
                leaf_bbox(&LeafShape { origin, active }),
                want,
                "case {case}"
            );
        }
    }

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
        assert_eq!(
            err,
            Unwritable::MetadataType {
                name: "m".into(),
                type_name: "mat4d".into()
            }
        );
        assert_eq!(
            err.to_string(),
            "metadata \"m\": cannot write metadata of type \"mat4d\""
        );
    }
}
