//! Node values: OpenVDB's node-value compression, used by internal nodes (one value per
//! entry) and leaf buffers alike. A metadata byte ([`NodeMeta`]) says which inactive values
//! the node stores and whether a selection mask follows; then come the values themselves,
//! all of them or (with [`CompressionFlags::ACTIVE_MASK`]) only the active ones, as one
//! chunk (see [`super::compress`]).
//!
//! Reading is split in two so that leaf buffers can be decoded in parallel: [`locate_values`]
//! walks the file, [`decode_values`] needs only what it located.

use super::codec::{mask_is_on, CompressionFlags, NodeMeta, VdbValue};
use super::compress::{locate_chunk, Inflater, LocatedChunk};
use super::cursor::Cursor;
use super::error::{Invalid, RawError, RawResult};

/// Decoding settings shared by every node of one grid.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Codec {
    pub flags: CompressionFlags,
    pub half: bool,
}

/// One node's stored values, located but not decoded (see [`locate_values`]).
#[derive(Debug, Clone)]
pub(crate) struct ValuesFrame<'a, V> {
    inactive0: V,
    inactive1: V,
    selection: Option<Vec<u64>>,
    /// Number of values stored (all, or only the active ones).
    stored: usize,
    chunk: Option<LocatedChunk<'a>>,
}

/// OpenVDB `readCompressedValues`, first half: a metadata byte saying how inactive values
/// are encoded, up to two inactive values and a selection mask, then the (possibly only
/// active) values as one data chunk, which is located but not decoded.
pub(crate) fn locate_values<'a, V: VdbValue>(
    cur: &mut Cursor<'a>,
    codec: Codec,
    background: V,
    value_mask: &[u64],
    count: usize,
    what: &'static str,
) -> RawResult<ValuesFrame<'a, V>> {
    let start = cur.pos();
    let byte = cur.u8(what)?;
    let meta = NodeMeta::from_byte(byte)
        .ok_or_else(|| RawError::invalid(start, what, Invalid::MaskCompression { code: byte }))?;
    // Inactive values not stored are −background, or +background when selected (or when
    // the node says they all are).
    let mut inactive0 = if meta == NodeMeta::NoMaskOrInactiveVals {
        background
    } else {
        background.negate()
    };
    let mut inactive1 = background;
    match meta {
        NodeMeta::NoMaskAndOneInactiveVal | NodeMeta::MaskAndOneInactiveVal => {
            inactive0 = V::from_bytes(cur.take(V::SIZE, what)?);
        }
        NodeMeta::MaskAndTwoInactiveVals => {
            inactive0 = V::from_bytes(cur.take(V::SIZE, what)?);
            inactive1 = V::from_bytes(cur.take(V::SIZE, what)?);
        }
        _ => {}
    }
    let selection = if meta.has_selection_mask() {
        Some(cur.mask(count, what)?)
    } else {
        None
    };
    let mask_compressed =
        codec.flags.contains(CompressionFlags::ACTIVE_MASK) && meta != NodeMeta::NoMaskAndAllVals;
    let stored = if mask_compressed {
        value_mask.iter().map(|w| w.count_ones() as usize).sum()
    } else {
        count
    };
    let value_size = if codec.half { V::HALF_SIZE } else { V::SIZE };
    // Half-float writers write nothing at all for an empty buffer.
    let chunk = if codec.half && stored == 0 {
        None
    } else {
        Some(locate_chunk(
            cur,
            codec.flags,
            stored * value_size,
            what,
            stored,
        )?)
    };
    Ok(ValuesFrame {
        inactive0,
        inactive1,
        selection,
        stored,
        chunk,
    })
}

/// Second half: decodes a located frame into `out` (one value per node entry), with the
/// decoding state `inflater` (see [`Inflater`]).
pub(crate) fn decode_values<'a, V: VdbValue>(
    frame: &ValuesFrame<'a, V>,
    codec: Codec,
    value_mask: &[u64],
    out: &mut [V],
    inflater: &mut Inflater<'a>,
) -> RawResult<()> {
    let bytes = match &frame.chunk {
        Some(c) => c.decode(inflater)?,
        None => &[][..],
    };
    let value_size = if codec.half { V::HALF_SIZE } else { V::SIZE };
    let decode = |i: usize| -> V {
        let b = &bytes[i * value_size..(i + 1) * value_size];
        if codec.half {
            V::from_half_bytes(b)
        } else {
            V::from_bytes(b)
        }
    };
    if frame.stored == out.len() {
        for (i, v) in out.iter_mut().enumerate() {
            *v = decode(i);
        }
    } else {
        let mut next = 0;
        for (n, v) in out.iter_mut().enumerate() {
            if mask_is_on(value_mask, n) {
                *v = decode(next);
                next += 1;
            } else if frame.selection.as_deref().is_some_and(|s| mask_is_on(s, n)) {
                *v = frame.inactive1;
            } else {
                *v = frame.inactive0;
            }
        }
    }
    Ok(())
}

/// Both halves at once.
pub(crate) fn read_values<V: VdbValue>(
    cur: &mut Cursor<'_>,
    codec: Codec,
    background: V,
    value_mask: &[u64],
    out: &mut [V],
    what: &'static str,
) -> RawResult<()> {
    let frame = locate_values(cur, codec, background, value_mask, out.len(), what)?;
    decode_values(&frame, codec, value_mask, out, &mut Inflater::default())
}
