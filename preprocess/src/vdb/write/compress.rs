//! Per-buffer compression, the writer's side of [`crate::vdb::compress`]: each block of node
//! values raw, or (with [`CompressionFlags::ZIP`]) zlib data behind its signed 64-bit size.
//! Blosc is not written: OpenVDB reads zip everywhere, blosc only when built with it.

use std::io::Write;

use flate2::write::ZlibEncoder;

use crate::vdb::codec::CompressionFlags;

/// One block of node values as `flags` ask (OpenVDB `writeData`).
pub(super) fn write_chunk(out: &mut Vec<u8>, raw: &[u8], flags: CompressionFlags) {
    if flags.contains(CompressionFlags::ZIP) {
        write_zipped(out, raw);
    } else {
        out.extend_from_slice(raw);
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
    fn zip_falls_back_to_raw_when_it_does_not_help() {
        let mut out = Vec::new();
        write_zipped(&mut out, &[]);
        assert_eq!(out, 0i64.to_le_bytes());
        let mut out = Vec::new();
        write_zipped(&mut out, &[0u8; 4096]);
        let n = i64::from_le_bytes(out[..8].try_into().expect("8 bytes"));
        assert!(n > 0 && (n as usize) < 4096 && out.len() == 8 + n as usize);
    }
}
