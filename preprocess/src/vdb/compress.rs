//! Per-buffer compression as OpenVDB writes it: optional zip (zlib) or blosc, each chunk
//! prefixed by a signed 64-bit size (negative = stored uncompressed).
//!
//! Blosc is decoded here over `lz4_flex` instead of linking the C library (`blosc-src`):
//! OpenVDB only ever writes blosc1 frames with the LZ4 codec and byte shuffle (see
//! `io/Compression.cc`, `bloscCompress`), which takes ~100 lines to decode, and a pure-Rust
//! decoder keeps the build free of a C toolchain and is fuzzable like the rest of the reader.

use std::io::Read;

use super::codec::CompressionFlags;
use super::cursor::Cursor;
use super::error::{DecompressError, ErrorKind, Invalid, RawError, RawResult};

/// One data chunk located in the file but not decoded yet, so that decoding can run in
/// parallel once the sequential walk over the file has found every chunk.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Chunk<'a> {
    Raw(&'a [u8]),
    Zip(&'a [u8], usize),
    Blosc(&'a [u8], usize),
}

/// A located chunk with where it starts, for error messages.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LocatedChunk<'a> {
    pub chunk: Chunk<'a>,
    pub start: usize,
    pub what: &'static str,
}

/// Decoding state one decoding thread keeps across chunks: a zlib decoder (setting one up,
/// with its state, window and 32 KiB input buffer, costs about as much as inflating a
/// leaf's few KiB) and the buffer the decoded bytes go to.
#[derive(Default)]
pub(crate) struct Inflater<'a> {
    zlib: Option<flate2::read::ZlibDecoder<&'a [u8]>>,
    buf: Vec<u8>,
}

impl<'a> LocatedChunk<'a> {
    /// The chunk's `nbytes` decoded bytes: the chunk itself when stored raw, otherwise
    /// `inflater`'s buffer.
    pub(crate) fn decode<'s>(&self, inflater: &'s mut Inflater<'a>) -> RawResult<&'s [u8]>
    where
        'a: 's,
    {
        let decoded = match self.chunk {
            Chunk::Raw(b) => return Ok(b),
            Chunk::Zip(src, n) => zlib_decode(src, n, &mut inflater.zlib, &mut inflater.buf),
            Chunk::Blosc(src, n) => blosc_decode(src, n).map(|b| inflater.buf = b),
        };
        decoded
            .map(|()| &inflater.buf[..])
            .map_err(|error| RawError::new(self.start, self.what, ErrorKind::Decompress(error)))
    }
}

/// Finds one data chunk of `nbytes` decoded bytes (OpenVDB `readData`) and moves past it.
pub(crate) fn locate_chunk<'a>(
    cur: &mut Cursor<'a>,
    flags: CompressionFlags,
    nbytes: usize,
    what: &'static str,
    count: usize,
) -> RawResult<LocatedChunk<'a>> {
    let expected = || format!("{count} values");
    let start = cur.pos();
    let located = |chunk| LocatedChunk { chunk, start, what };
    if !flags.contains(CompressionFlags::BLOSC) && !flags.contains(CompressionFlags::ZIP) {
        return Ok(located(Chunk::Raw(cur.take_as(nbytes, what, expected)?)));
    }
    let size = cur.i64(what)?;
    if size <= 0 {
        // Stored uncompressed.
        if size.unsigned_abs() != nbytes as u64 {
            return Err(RawError::invalid(
                start,
                what,
                Invalid::ChunkSize {
                    expected: nbytes,
                    found: size.unsigned_abs(),
                },
            ));
        }
        return Ok(located(Chunk::Raw(cur.take_as(nbytes, what, expected)?)));
    }
    let len = usize::try_from(size).unwrap_or(usize::MAX);
    if len > cur.left() {
        return Err(RawError::new(
            start,
            what,
            ErrorKind::Truncated {
                expected: format!("{len} compressed bytes"),
                left: cur.left() as u64,
            },
        ));
    }
    let src = cur.take(len, what)?;
    Ok(located(if flags.contains(CompressionFlags::BLOSC) {
        Chunk::Blosc(src, nbytes)
    } else {
        Chunk::Zip(src, nbytes)
    }))
}

/// Inflates `src` into `out`, which must come to exactly `nbytes` bytes, with `decoder`
/// (reset to `src`, or made on first use).
fn zlib_decode<'a>(
    src: &'a [u8],
    nbytes: usize,
    decoder: &mut Option<flate2::read::ZlibDecoder<&'a [u8]>>,
    out: &mut Vec<u8>,
) -> Result<(), DecompressError> {
    out.clear();
    out.reserve(nbytes);
    let decoder = match decoder {
        Some(d) => {
            d.reset(src);
            d
        }
        None => decoder.insert(flate2::read::ZlibDecoder::new(src)),
    };
    // Read at most one byte more than expected so a zip bomb cannot grow the buffer.
    decoder
        .take(nbytes as u64 + 1)
        .read_to_end(out)
        .map_err(|e| DecompressError::Zip {
            message: e.to_string(),
        })?;
    if out.len() != nbytes {
        return Err(DecompressError::ZipSize {
            found: out.len(),
            expected: nbytes,
        });
    }
    Ok(())
}

const BLOSC_HEADER: usize = 16;
const BLOSC_DOSHUFFLE: u8 = 0x1;
const BLOSC_MEMCPYED: u8 = 0x2;
const BLOSC_DOBITSHUFFLE: u8 = 0x4;
const BLOSC_DONT_SPLIT: u8 = 0x10;
const BLOSC_LZ4: u8 = 1;
const MAX_SPLITS: usize = 16;
const MIN_BUFFERSIZE: usize = 128;

fn le32(b: &[u8], at: usize) -> Result<usize, DecompressError> {
    b.get(at..at.saturating_add(4))
        .and_then(|s| s.try_into().ok())
        .map(|s: [u8; 4]| u32::from_le_bytes(s) as usize)
        .ok_or(DecompressError::BloscEnds { at, len: b.len() })
}

/// Decodes a blosc1 frame (LZ4 codec, optional byte shuffle, optional split blocks) into
/// exactly `nbytes` bytes. Layout: 16-byte header (version, codec version, flags, type size,
/// uncompressed size, block size, frame size), block start offsets, then per block one or
/// `typesize` streams each prefixed by its i32 compressed length.
pub(crate) fn blosc_decode(src: &[u8], nbytes: usize) -> Result<Vec<u8>, DecompressError> {
    if src.len() < BLOSC_HEADER {
        return Err(DecompressError::BloscShort { len: src.len() });
    }
    let flags = src[2];
    let typesize = src[3] as usize;
    let total = le32(src, 4)?;
    let blocksize = le32(src, 8)?;
    let cbytes = le32(src, 12)?;
    if total != nbytes {
        return Err(DecompressError::BloscTotal {
            total,
            expected: nbytes,
        });
    }
    if cbytes > src.len() {
        return Err(DecompressError::BloscClaims {
            claimed: cbytes,
            len: src.len(),
        });
    }
    // The frame size counts the header: a smaller one is corrupt, and the block-count
    // check below subtracts the header from it.
    if cbytes < BLOSC_HEADER {
        return Err(DecompressError::BloscClaimsBelowHeader { claimed: cbytes });
    }
    let src = &src[..cbytes];
    if flags & BLOSC_MEMCPYED != 0 {
        return src
            .get(BLOSC_HEADER..BLOSC_HEADER + nbytes)
            .map(<[u8]>::to_vec)
            .ok_or(DecompressError::BloscCopyShort);
    }
    if nbytes == 0 {
        return Ok(Vec::new());
    }
    let codec = flags >> 5;
    if codec != BLOSC_LZ4 {
        return Err(DecompressError::BloscCodec { codec });
    }
    if flags & BLOSC_DOBITSHUFFLE != 0 && blocksize >= typesize {
        return Err(DecompressError::BloscBitShuffle);
    }
    if blocksize == 0 || typesize == 0 {
        return Err(DecompressError::BloscZeroSize {
            blocksize,
            typesize,
        });
    }
    let nblocks = nbytes.div_ceil(blocksize);
    if nblocks > (src.len() - BLOSC_HEADER) / 4 {
        return Err(DecompressError::BloscBlocks {
            blocks: nblocks,
            len: src.len(),
        });
    }
    let shuffle = flags & BLOSC_DOSHUFFLE != 0 && typesize > 1;
    let dont_split = flags & BLOSC_DONT_SPLIT != 0;
    let mut out = vec![0u8; nbytes];
    // `blocksize` comes from the frame: never allocate more than the expected output.
    let mut tmp = if shuffle {
        vec![0u8; blocksize.min(nbytes)]
    } else {
        Vec::new()
    };
    for (b, dest) in out.chunks_mut(blocksize).enumerate() {
        let bsize = dest.len();
        let leftover = bsize < blocksize;
        let nsplits = if !dont_split
            && typesize <= MAX_SPLITS
            && bsize / typesize >= MIN_BUFFERSIZE
            && !leftover
        {
            typesize
        } else {
            1
        };
        let neblock = bsize / nsplits;
        let mut at = le32(src, BLOSC_HEADER + 4 * b)?;
        let target: &mut [u8] = if shuffle { &mut tmp[..bsize] } else { dest };
        for split in target.chunks_mut(neblock).take(nsplits) {
            let n = le32(src, at)?;
            let past_end = DecompressError::BloscPastEnd { block: b };
            at = at.checked_add(4).ok_or(past_end.clone())?;
            let stream = src
                .get(at..at.checked_add(n).ok_or(past_end.clone())?)
                .ok_or(past_end)?;
            if n == neblock {
                split.copy_from_slice(stream);
            } else {
                let got = lz4_flex::block::decompress_into(stream, split).map_err(|e| {
                    DecompressError::Lz4 {
                        block: b,
                        message: e.to_string(),
                    }
                })?;
                if got != neblock {
                    return Err(DecompressError::Lz4Size {
                        block: b,
                        found: got,
                        expected: neblock,
                    });
                }
            }
            at += n;
        }
        if shuffle {
            unshuffle(&tmp[..bsize], dest, typesize);
        }
    }
    Ok(out)
}

/// Byte unshuffle: byte `j` of element `i` is stored at `j * n + i`; a tail shorter than one
/// element is stored as is.
fn unshuffle(src: &[u8], dest: &mut [u8], typesize: usize) {
    let n = src.len() / typesize;
    let tail = n * typesize;
    if typesize == 4 {
        // OpenVDB always shuffles with 4-byte elements: a branch-free fast path.
        let (p0, rest) = src.split_at(n);
        let (p1, rest) = rest.split_at(n);
        let (p2, p3) = rest.split_at(n);
        let planes = p0.iter().zip(p1).zip(p2.iter().zip(p3));
        for (out, ((a, b), (c, d))) in dest[..tail].chunks_exact_mut(4).zip(planes) {
            out.copy_from_slice(&[*a, *b, *c, *d]);
        }
    } else {
        for j in 0..typesize {
            let plane = &src[j * n..(j + 1) * n];
            for (i, &byte) in plane.iter().enumerate() {
                dest[i * typesize + j] = byte;
            }
        }
    }
    dest[tail..].copy_from_slice(&src[tail..]);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unshuffle_fast_path_matches_generic() {
        let src: Vec<u8> = (0..203u32).map(|v| (v * 7) as u8).collect();
        let mut fast = vec![0u8; src.len()];
        unshuffle(&src, &mut fast, 4);
        let n = src.len() / 4;
        let mut slow = src.clone();
        for i in 0..n {
            for j in 0..4 {
                slow[i * 4 + j] = src[j * n + i];
            }
        }
        assert_eq!(fast, slow);
        let mut three = vec![0u8; src.len()];
        unshuffle(&src, &mut three, 3);
        let n = src.len() / 3;
        assert_eq!(three[4], src[n + 1]);
    }

    #[test]
    fn unshuffle_restores_interleaving() {
        // Two 4-byte elements [1,2,3,4] and [5,6,7,8] plus a one-byte tail.
        let shuffled = [1, 5, 2, 6, 3, 7, 4, 8, 9];
        let mut out = [0u8; 9];
        unshuffle(&shuffled, &mut out, 4);
        assert_eq!(out, [1, 2, 3, 4, 5, 6, 7, 8, 9]);
    }

    #[test]
    fn blosc_memcpyed_frame() {
        let mut frame = vec![2, 1, BLOSC_MEMCPYED, 4];
        frame.extend(8u32.to_le_bytes());
        frame.extend(8u32.to_le_bytes());
        frame.extend(24u32.to_le_bytes());
        frame.extend([1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(
            blosc_decode(&frame, 8).unwrap(),
            vec![1, 2, 3, 4, 5, 6, 7, 8]
        );
        assert!(blosc_decode(&frame, 12).is_err());
    }

    #[test]
    fn blosc_lz4_shuffled_frame() {
        // Build a frame by hand: one block, no split, shuffle, typesize 4.
        let data: Vec<u8> = (0..64u32).flat_map(|v| (v * 3).to_le_bytes()).collect();
        let n = data.len() / 4;
        let mut shuffled = vec![0u8; data.len()];
        for i in 0..n {
            for j in 0..4 {
                shuffled[j * n + i] = data[i * 4 + j];
            }
        }
        let comp = lz4_flex::block::compress(&shuffled);
        let mut frame = vec![
            2,
            1,
            BLOSC_DOSHUFFLE | BLOSC_DONT_SPLIT | (BLOSC_LZ4 << 5),
            4,
        ];
        frame.extend((data.len() as u32).to_le_bytes());
        frame.extend((data.len() as u32).to_le_bytes());
        let total = 16 + 4 + 4 + comp.len();
        frame.extend((total as u32).to_le_bytes());
        frame.extend(20u32.to_le_bytes());
        frame.extend((comp.len() as u32).to_le_bytes());
        frame.extend(&comp);
        assert_eq!(blosc_decode(&frame, data.len()).unwrap(), data);
        // Every truncation fails cleanly.
        for cut in 0..frame.len() {
            assert!(blosc_decode(&frame[..cut], data.len()).is_err());
        }
    }

    #[test]
    fn huge_block_size_does_not_allocate() {
        let mut frame = vec![2, 1, BLOSC_DOSHUFFLE | (BLOSC_LZ4 << 5), 4];
        frame.extend(8u32.to_le_bytes());
        frame.extend(u32::MAX.to_le_bytes());
        frame.extend(32u32.to_le_bytes());
        frame.extend(20u32.to_le_bytes());
        frame.extend(8u32.to_le_bytes());
        frame.extend([1, 2, 3, 4, 5, 6, 7, 8]);
        // Stored split (cbytes == block size): decodes, with a block buffer of 8 bytes.
        assert_eq!(
            blosc_decode(&frame, 8).unwrap(),
            vec![1, 3, 5, 7, 2, 4, 6, 8]
        );
    }

    /// A frame whose own size field is below the 16-byte header (but within the chunk) is
    /// refused, not used to compute a negative block-table length (an overflow panic in
    /// builds with overflow checks, a huge bogus bound without).
    #[test]
    fn frame_size_below_header_is_refused() {
        for cbytes in 0..16u32 {
            let mut frame = vec![2, 1, BLOSC_DOSHUFFLE | (BLOSC_LZ4 << 5), 4];
            frame.extend(8u32.to_le_bytes());
            frame.extend(8u32.to_le_bytes());
            frame.extend(cbytes.to_le_bytes());
            frame.extend([0u8; 16]);
            let err = blosc_decode(&frame, 8).unwrap_err();
            assert_eq!(
                err,
                DecompressError::BloscClaimsBelowHeader {
                    claimed: cbytes as usize
                },
                "cbytes {cbytes}: {err}"
            );
        }
    }

    #[test]
    fn zlib_size_mismatch_is_an_error() {
        use std::io::Write;
        let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(&[7u8; 100]).unwrap();
        let z = enc.finish().unwrap();
        // One decoder for every call, as a decoding thread reuses it: a failed or
        // corrupt stream must not leak into the next one.
        let mut corrupt = z.clone();
        corrupt[3] ^= 0xff;
        let (mut decoder, mut out) = (None, Vec::new());
        let calls: [(&[u8], usize, bool); 6] = [
            (&z, 100, true),
            (&z, 99, false),
            (&z, 101, false),
            (&z[..z.len() / 2], 100, false),
            (&corrupt, 100, false),
            (&z, 100, true),
        ];
        for (src, n, ok) in calls {
            let r = zlib_decode(src, n, &mut decoder, &mut out);
            assert_eq!(r.is_ok(), ok, "{n} bytes from {} : {r:?}", src.len());
            if ok {
                assert_eq!(out, vec![7u8; 100]);
            }
        }
    }
}
