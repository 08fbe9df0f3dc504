//! The fixed 48-byte header in front of the rkyv archive.
//!
//! ```text
//! offset  size  field           value
//!      0     8  magic           b"QBRICKS\0"
//!      8     4  format_version  u32 LE, FORMAT_VERSION
//!     12     4  flags           u32 LE, the rkyv layout the payload was written with (FLAGS)
//!     16     8  payload_len     u64 LE, bytes after the header; the file is exactly 48 + this
//!     24     8  checksum        u64 LE, see [`checksum`]: xxh3-64 of the payload's 1 MiB chunks' xxh3-64s
//!     32    16  reserved        zero; a reader rejects anything else
//!     48     …  payload         the rkyv archive of `BrickFile` (root object at its end)
//! ```
//!
//! Why this layout:
//! - The header lives *outside* the archive so that the version can be checked before a
//!   single byte of the archive is interpreted: a version-2 file must give a clear
//!   "version 2, this build reads version 1" message, not a confusing validation error.
//! - The payload starts at offset 48, a multiple of 16. A memory map starts on a page
//!   boundary, so the archive is 16-aligned in memory without copying; rkyv's validation
//!   requires every archived `f64`/`u64` to be 8-aligned and we keep 16 for headroom (SIMD
//!   loads of value slices).
//! - rkyv puts the root object at the *end* of the buffer, so the payload slice handed to
//!   validation must be exact: the explicit length catches truncated and over-long files
//!   before validation and gives a better message than "root out of bounds".
//! - xxh3-64 runs at memory bandwidth (several GB/s), so verifying the checksum is cheap
//!   next to reading the file from disk; it can be skipped for huge files, validation cannot.
//!   Since version 3 the payload is hashed in 1 MiB chunks and the chunk hashes hashed
//!   again, so that the chunks are hashed on all cores at open (one xxh3 stream over
//!   60 MB took 13 ms of a 24 ms open on a 2-core machine).
//! - `flags` records the rkyv format options the archive depends on (endianness,
//!   alignment, pointer width are rkyv crate features); a file written by a build with other
//!   options is refused instead of failing validation obscurely.
//! - Reserved bytes must be zero so that a later version can give them a meaning and an
//!   old reader notices.
//!
//! Version history:
//!
//! | version | change |
//! |---|---|
//! | 1 | first version: header above, schema of `format::schema` |
//! | 2 | per-node value ranges and fullness of the KD-tree (`kd_ranges`, `kd_full`), so the viewer traverses the archive without building tables at open |
//! | 3 | lean structure: regions without boxes (a region's box is its KD leaf's cell) and without `finest_level`, 16-byte inner KD nodes with leaves as child references (`kd_root`, `kd_axes`), no stored per-node ranges; the checksum hashes 1 MiB chunks |
//! | 4 | 64-bit relative pointers (rkyv `pointer_width_64`, flag bit 3 instead of bit 2): an archive may pass 2 GiB, as a billion cells' fields do; the schema is that of version 3 |
//!
//! ```
//! use qbricks_format::header::{Header, HEADER_LEN, MAGIC};
//! let h = Header::for_payload(b"payload");
//! let bytes = h.to_bytes();
//! assert_eq!(bytes.len(), HEADER_LEN);
//! assert_eq!(&bytes[0..8], MAGIC);
//! assert_eq!(&bytes[8..12], &4u32.to_le_bytes());
//! assert_eq!(&bytes[16..24], &7u64.to_le_bytes());
//! assert_eq!(Header::parse(&bytes).unwrap(), h);
//! ```

use crate::error::FormatErrorKind;

/// First eight bytes of every `.qbk` file.
pub const MAGIC: &[u8; 8] = b"QBRICKS\0";

/// The format version this build writes and reads.
pub const FORMAT_VERSION: u32 = 4;

/// Size of the header; also the payload's offset (a multiple of [`PAYLOAD_ALIGN`]).
pub const HEADER_LEN: usize = 48;

/// Alignment of the payload within the file and in memory.
pub(crate) const PAYLOAD_ALIGN: usize = 16;

/// Flag bit: archive primitives are little-endian (rkyv feature `little_endian`).
pub(crate) const FLAG_LITTLE_ENDIAN: u32 = 1 << 0;
/// Flag bit: archive primitives are naturally aligned (rkyv default, not `unaligned`).
pub(crate) const FLAG_ALIGNED: u32 = 1 << 1;
/// Flag bit: relative pointers are 32-bit (rkyv feature `pointer_width_32`; formats 1–3).
#[cfg(test)]
pub(crate) const FLAG_POINTER_WIDTH_32: u32 = 1 << 2;
/// Flag bit: relative pointers (and archived sizes) are 64-bit (rkyv feature
/// `pointer_width_64`; format 4 on).
pub(crate) const FLAG_POINTER_WIDTH_64: u32 = 1 << 3;

/// The flags of archives written by this build (rkyv 0.8, little-endian, aligned, 64-bit
/// relative pointers).
pub(crate) const FLAGS: u32 = FLAG_LITTLE_ENDIAN | FLAG_ALIGNED | FLAG_POINTER_WIDTH_64;

const _: () = assert!(HEADER_LEN & (PAYLOAD_ALIGN - 1) == 0);

/// The decoded header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    pub format_version: u32,
    pub flags: u32,
    pub payload_len: u64,
    pub checksum: u64,
}

/// Chunk size of [`checksum`].
pub const CHECKSUM_CHUNK: usize = 1 << 20;

/// The payload checksum: xxh3-64 (seed 0) of the little-endian xxh3-64s of the
/// [`CHECKSUM_CHUNK`]-byte chunks of `bytes` (the last one shorter; no chunk for empty
/// bytes). The chunks are hashed on up to as many threads as the machine has cores.
pub fn checksum(bytes: &[u8]) -> u64 {
    checksum_on(
        bytes,
        std::thread::available_parallelism().map_or(1, |n| n.get()),
    )
}

/// [`checksum`] on at most `threads` threads (the calling one when 1): a hash that runs
/// beside other work takes one core, not all.
pub fn checksum_on(bytes: &[u8], threads: usize) -> u64 {
    let chunks = bytes.len().div_ceil(CHECKSUM_CHUNK);
    let mut hashes = vec![0u64; chunks];
    let threads = threads.min(chunks / 4).max(1);
    let per_thread = chunks.div_ceil(threads).max(1);
    let hash_run = |first: usize, out: &mut [u64]| {
        for (k, h) in out.iter_mut().enumerate() {
            let at = (first + k) * CHECKSUM_CHUNK;
            let end = (at + CHECKSUM_CHUNK).min(bytes.len());
            *h = xxhash_rust::xxh3::xxh3_64(&bytes[at..end]);
        }
    };
    if threads == 1 {
        hash_run(0, &mut hashes);
    } else {
        std::thread::scope(|scope| {
            for (t, out) in hashes.chunks_mut(per_thread).enumerate() {
                let hash_run = &hash_run;
                scope.spawn(move || hash_run(t * per_thread, out));
            }
        });
    }
    let mut joined = Vec::with_capacity(hashes.len() * 8);
    for h in hashes {
        joined.extend_from_slice(&h.to_le_bytes());
    }
    xxhash_rust::xxh3::xxh3_64(&joined)
}

/// [`checksum`] computed over bytes that arrive in pieces (the writer streams the
/// archive): one xxh3 stream per chunk, whose digests are kept in order.
#[derive(Clone)]
pub struct ChunkedChecksum {
    chunk: xxhash_rust::xxh3::Xxh3,
    in_chunk: usize,
    hashes: Vec<u8>,
}

impl Default for ChunkedChecksum {
    fn default() -> Self {
        Self {
            chunk: xxhash_rust::xxh3::Xxh3::new(),
            in_chunk: 0,
            hashes: Vec::new(),
        }
    }
}

impl ChunkedChecksum {
    pub fn update(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            let take = (CHECKSUM_CHUNK - self.in_chunk).min(bytes.len());
            self.chunk.update(&bytes[..take]);
            self.in_chunk += take;
            bytes = &bytes[take..];
            if self.in_chunk == CHECKSUM_CHUNK {
                self.finish_chunk();
            }
        }
    }

    fn finish_chunk(&mut self) {
        self.hashes
            .extend_from_slice(&self.chunk.digest().to_le_bytes());
        self.chunk.reset();
        self.in_chunk = 0;
    }

    /// The checksum of everything passed to [`ChunkedChecksum::update`].
    pub fn digest(mut self) -> u64 {
        if self.in_chunk > 0 {
            self.finish_chunk();
        }
        xxhash_rust::xxh3::xxh3_64(&self.hashes)
    }
}

fn u32_at(bytes: &[u8; HEADER_LEN], at: usize) -> u32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(&bytes[at..at + 4]);
    u32::from_le_bytes(b)
}

fn u64_at(bytes: &[u8; HEADER_LEN], at: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(b)
}

impl Header {
    /// Header of the current version for `payload`.
    pub fn for_payload(payload: &[u8]) -> Self {
        Self {
            format_version: FORMAT_VERSION,
            flags: FLAGS,
            payload_len: payload.len() as u64,
            checksum: checksum(payload),
        }
    }

    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let mut out = [0u8; HEADER_LEN];
        out[0..8].copy_from_slice(MAGIC);
        out[8..12].copy_from_slice(&self.format_version.to_le_bytes());
        out[12..16].copy_from_slice(&self.flags.to_le_bytes());
        out[16..24].copy_from_slice(&self.payload_len.to_le_bytes());
        out[24..32].copy_from_slice(&self.checksum.to_le_bytes());
        out
    }

    /// Decodes and checks the header at the start of `file`: magic, version, flags and
    /// reserved bytes. Length and checksum are checked by [`Header::payload`].
    pub fn parse(file: &[u8]) -> Result<Self, FormatErrorKind> {
        let Some(bytes) = file.get(..HEADER_LEN) else {
            return Err(FormatErrorKind::TooShort {
                expected: HEADER_LEN as u64,
                found: file.len() as u64,
            });
        };
        let mut h = [0u8; HEADER_LEN];
        h.copy_from_slice(bytes);
        if &h[0..8] != MAGIC {
            let mut found = [0u8; 8];
            found.copy_from_slice(&h[0..8]);
            return Err(FormatErrorKind::BadMagic { found });
        }
        let format_version = u32_at(&h, 8);
        if format_version != FORMAT_VERSION {
            return Err(FormatErrorKind::UnsupportedVersion {
                found: format_version,
                supported: FORMAT_VERSION,
            });
        }
        let flags = u32_at(&h, 12);
        if flags != FLAGS {
            return Err(FormatErrorKind::UnsupportedFlags {
                found: flags,
                expected: FLAGS,
            });
        }
        if let Some(i) = h[32..].iter().position(|&b| b != 0) {
            return Err(FormatErrorKind::ReservedNotZero { offset: 32 + i });
        }
        Ok(Self {
            format_version,
            flags,
            payload_len: u64_at(&h, 16),
            checksum: u64_at(&h, 24),
        })
    }

    /// The payload of `file` after checking its length against the header (and, when
    /// `verify_checksum`, its checksum).
    pub(crate) fn payload<'a>(
        &self,
        file: &'a [u8],
        verify_checksum: bool,
    ) -> Result<&'a [u8], FormatErrorKind> {
        let found = file.len() as u64;
        let expected = (HEADER_LEN as u64).saturating_add(self.payload_len);
        if found != expected {
            return Err(FormatErrorKind::LengthMismatch { expected, found });
        }
        let payload = file.get(HEADER_LEN..).unwrap_or_default();
        if verify_checksum {
            let found = checksum(payload);
            if found != self.checksum {
                return Err(FormatErrorKind::ChecksumMismatch {
                    expected: self.checksum,
                    found,
                });
            }
        }
        Ok(payload)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The threaded checksum, the streamed one in odd pieces and the definition (xxh3 of
    /// the chunks' xxh3s) agree, at chunk edges too; and any changed byte changes it.
    #[test]
    fn chunked_checksum_agrees_however_it_is_computed() {
        let n = 10 * CHECKSUM_CHUNK + 5;
        let bytes: Vec<u8> = (0..n as u64)
            .map(|i| (i.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 56) as u8)
            .collect();
        for len in [
            0,
            1,
            CHECKSUM_CHUNK - 1,
            CHECKSUM_CHUNK,
            CHECKSUM_CHUNK + 1,
            9 * CHECKSUM_CHUNK,
            n,
        ] {
            let b = &bytes[..len];
            let mut joined = Vec::new();
            for c in b.chunks(CHECKSUM_CHUNK) {
                joined.extend_from_slice(&xxhash_rust::xxh3::xxh3_64(c).to_le_bytes());
            }
            let want = xxhash_rust::xxh3::xxh3_64(&joined);
            assert_eq!(checksum(b), want, "threaded, {len} bytes");
            for threads in [1, 2, 3, 64] {
                assert_eq!(
                    checksum_on(b, threads),
                    want,
                    "{threads} threads, {len} bytes"
                );
            }
            let mut streamed = ChunkedChecksum::default();
            let mut rest = b;
            let mut step = 1;
            while !rest.is_empty() {
                let k = step.min(rest.len());
                streamed.update(&rest[..k]);
                rest = &rest[k..];
                step = step * 7 + 3;
            }
            assert_eq!(streamed.digest(), want, "streamed, {len} bytes");
        }
        let mut changed = bytes.clone();
        for at in [0, CHECKSUM_CHUNK - 1, 5 * CHECKSUM_CHUNK + 17, n - 1] {
            changed[at] ^= 1;
            assert_ne!(checksum(&changed), checksum(&bytes), "byte {at}");
            changed[at] ^= 1;
        }
    }

    #[test]
    fn round_trip_and_field_offsets() {
        let h = Header {
            format_version: FORMAT_VERSION,
            flags: FLAGS,
            payload_len: 0x0102_0304_0506_0708,
            checksum: 0x1122_3344_5566_7788,
        };
        let b = h.to_bytes();
        assert_eq!(&b[0..8], b"QBRICKS\0");
        assert_eq!(b[16], 0x08);
        assert_eq!(b[24], 0x88);
        assert!(b[32..].iter().all(|&x| x == 0));
        assert_eq!(Header::parse(&b).map_err(|e| e.to_string()), Ok(h));
    }

    #[test]
    fn every_header_field_is_checked() {
        let good = Header::for_payload(b"abc").to_bytes();
        let mut file = good.to_vec();
        file.extend_from_slice(b"abc");
        let h = Header::parse(&file).expect("good header");
        assert!(h.payload(&file, true).is_ok());

        let mut bad = file.clone();
        bad[3] = b'x';
        assert!(matches!(
            Header::parse(&bad),
            Err(FormatErrorKind::BadMagic { .. })
        ));

        let mut bad = file.clone();
        bad[8] = 2;
        let e = Header::parse(&bad).expect_err("version 2");
        assert!(matches!(
            e,
            FormatErrorKind::UnsupportedVersion {
                found: 2,
                supported: 4
            }
        ));

        let mut bad = file.clone();
        // A version-3 file's flags: 32-bit pointers.
        bad[12] ^= (FLAG_POINTER_WIDTH_32 | FLAG_POINTER_WIDTH_64) as u8;
        assert!(matches!(
            Header::parse(&bad),
            Err(FormatErrorKind::UnsupportedFlags { .. })
        ));

        let mut bad = file.clone();
        bad[47] = 1;
        assert!(matches!(
            Header::parse(&bad),
            Err(FormatErrorKind::ReservedNotZero { offset: 47 })
        ));

        assert!(matches!(
            h.payload(&file[..file.len() - 1], true),
            Err(FormatErrorKind::LengthMismatch {
                expected: 51,
                found: 50
            })
        ));

        let mut bad = file.clone();
        bad[49] ^= 1;
        assert!(matches!(
            h.payload(&bad, true),
            Err(FormatErrorKind::ChecksumMismatch { .. })
        ));
        assert!(h.payload(&bad, false).is_ok());

        assert!(matches!(
            Header::parse(&file[..47]),
            Err(FormatErrorKind::TooShort {
                expected: 48,
                found: 47
            })
        ));
    }
}
