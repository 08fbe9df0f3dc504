//! File and grid metadata ([`Metadata`]): a count, then name, type name, byte size and value
//! per entry. Types we don't know are kept as their type name; OpenVDB's temporary entries
//! (type names starting with `__`, e.g. delayed-load tables) are skipped.

use std::collections::BTreeMap;

use super::cursor::Cursor;
use super::error::{Invalid, RawError, RawResult};

/// One metadata value.
#[derive(Debug, Clone, PartialEq)]
pub enum MetaValue {
    Bool(bool),
    Int32(i32),
    Int64(i64),
    Float(f32),
    Double(f64),
    String(String),
    Vec3i([i32; 3]),
    Vec3s([f32; 3]),
    Vec3d([f64; 3]),
    /// A type this reader does not decode (mat4d, vec2s, ...): its type name.
    Other(String),
}

/// Metadata entries by name (sorted, so output is deterministic).
pub type Metadata = BTreeMap<String, MetaValue>;

const WHAT: &str = "metadata";

pub(crate) fn read_metadata(cur: &mut Cursor<'_>) -> RawResult<Metadata> {
    let start = cur.pos();
    let count = cur.u32("metadata count")? as usize;
    // Each entry takes at least 12 bytes (three u32 sizes).
    if count > cur.left() / 12 {
        return Err(cur.truncated(WHAT, format!("{count} metadata entries"))).map_err(|e| {
            RawError {
                offset: start as u64,
                ..e
            }
        });
    }
    let mut out = Metadata::new();
    for _ in 0..count {
        let entry = cur.pos();
        let name = cur.string("metadata name")?;
        let type_name = cur.string("metadata type name")?;
        let bytes = cur.bytes_with_len("metadata value")?;
        if type_name.starts_with("__") {
            continue;
        }
        let value = decode(&type_name, bytes).ok_or_else(|| {
            RawError::invalid(
                entry,
                WHAT,
                Invalid::MetadataSize {
                    name: name.to_string(),
                    type_name: type_name.to_string(),
                    len: bytes.len(),
                },
            )
        })?;
        out.insert(name, value);
    }
    Ok(out)
}

fn arr<const N: usize>(b: &[u8], at: usize) -> Option<[u8; N]> {
    b.get(at..at + N)?.try_into().ok()
}

fn decode(type_name: &str, b: &[u8]) -> Option<MetaValue> {
    let exact = |n: usize| (b.len() == n).then_some(());
    let i32_at = |at| arr::<4>(b, at).map(i32::from_le_bytes);
    let f32_at = |at| arr::<4>(b, at).map(f32::from_le_bytes);
    let f64_at = |at| arr::<8>(b, at).map(f64::from_le_bytes);
    Some(match type_name {
        "bool" => {
            exact(1)?;
            MetaValue::Bool(b[0] != 0)
        }
        "int32" => {
            exact(4)?;
            MetaValue::Int32(i32_at(0)?)
        }
        "int64" => {
            exact(8)?;
            MetaValue::Int64(i64::from_le_bytes(arr::<8>(b, 0)?))
        }
        "float" => {
            exact(4)?;
            MetaValue::Float(f32_at(0)?)
        }
        "double" => {
            exact(8)?;
            MetaValue::Double(f64_at(0)?)
        }
        "string" => MetaValue::String(String::from_utf8_lossy(b).into_owned()),
        "vec3i" => {
            exact(12)?;
            MetaValue::Vec3i([i32_at(0)?, i32_at(4)?, i32_at(8)?])
        }
        "vec3s" => {
            exact(12)?;
            MetaValue::Vec3s([f32_at(0)?, f32_at(4)?, f32_at(8)?])
        }
        "vec3d" => {
            exact(24)?;
            MetaValue::Vec3d([f64_at(0)?, f64_at(8)?, f64_at(16)?])
        }
        other => MetaValue::Other(other.to_string()),
    })
}
