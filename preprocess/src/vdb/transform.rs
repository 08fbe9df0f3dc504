//! Grid transforms: the map type name followed by the map's vectors. Only maps without
//! rotation or shear are accepted, since qbricks treats grids as axis-aligned boxes.

use super::cursor::Cursor;
use super::error::{ErrorKind, RawError, RawResult};
use crate::grid::Transform;

/// Reads a transform. Unsupported map types give [`ErrorKind::UnsupportedTransform`].
pub(crate) fn read_transform(cur: &mut Cursor<'_>) -> RawResult<(String, Transform)> {
    let start = cur.pos();
    let map = cur.string("transform type")?;
    let what = "transform";
    // ScaleMap and its subclasses store scale, voxel size and three derived vectors.
    let (translation, scale) = match map.as_str() {
        "UniformScaleTranslateMap" | "ScaleTranslateMap" => {
            let t = cur.vec3d(what)?;
            let s = cur.vec3d(what)?;
            cur.skip(4 * 24, what)?;
            (t, s)
        }
        "UniformScaleMap" | "ScaleMap" => {
            let s = cur.vec3d(what)?;
            cur.skip(4 * 24, what)?;
            ([0.0; 3], s)
        }
        "TranslationMap" => (cur.vec3d(what)?, [1.0; 3]),
        _ => {
            return Err(RawError::new(
                start,
                what,
                ErrorKind::UnsupportedTransform(map),
            ))
        }
    };
    if scale.iter().any(|s| !s.is_finite() || *s <= 0.0)
        || translation.iter().any(|t| !t.is_finite())
    {
        return Err(RawError::invalid(
            start,
            what,
            format!(
                "voxel size {scale:?} / translation {translation:?} must be finite and positive"
            ),
        ));
    }
    Ok((
        map,
        Transform {
            voxel_size: scale,
            translation,
        },
    ))
}
