//! Image and window sizes given as `WxH`, read the same way by every command.

use super::MAX_IMAGE_SIDE;

/// Why a `WxH` size argument is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{flag}: expected WxH with sides {min}..={MAX_IMAGE_SIDE}, found `{text}`")]
pub struct SizeError {
    pub flag: String,
    pub min: u32,
    pub text: String,
}

/// `WxH` (or `WXH`) with both sides in `min..=`[`MAX_IMAGE_SIDE`]: the one reading of an
/// image or window size every command uses.
pub fn parse_size(flag: &str, text: &str, min: u32) -> Result<(u32, u32), SizeError> {
    let bad = || SizeError {
        flag: flag.to_string(),
        min,
        text: text.to_string(),
    };
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(bad)?;
    let w: u32 = w.trim().parse().map_err(|_| bad())?;
    let h: u32 = h.trim().parse().map_err(|_| bad())?;
    let side = min..=MAX_IMAGE_SIDE;
    if !side.contains(&w) || !side.contains(&h) {
        return Err(bad());
    }
    Ok((w, h))
}
