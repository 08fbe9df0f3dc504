//! Grid transforms: the map type name followed by the map's vectors. Only maps without
//! rotation or shear are accepted, since qbricks treats grids as axis-aligned boxes.

use super::cursor::Cursor;
use super::error::{ErrorKind, Invalid, RawError, RawResult};
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
            Invalid::Transform { scale, translation },
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

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes(map: &str, vectors: &[[f64; 3]]) -> Vec<u8> {
        let mut b = (map.len() as u32).to_le_bytes().to_vec();
        b.extend(map.as_bytes());
        for v in vectors {
            for c in v {
                b.extend(c.to_le_bytes());
            }
        }
        b
    }

    #[test]
    fn translation_map_has_unit_voxels() {
        let b = bytes("TranslationMap", &[[1.0, -2.0, 3.5]]);
        let (_, t) = read_transform(&mut Cursor::new(&b, 0)).unwrap();
        assert_eq!(t.voxel_size, [1.0; 3]);
        assert_eq!(t.translation, [1.0, -2.0, 3.5]);
    }

    #[test]
    fn scale_translate_map_reads_translation_then_scale() {
        let mut v = vec![[4.0, 5.0, 6.0], [0.5, 0.25, 2.0]];
        v.extend([[9.0; 3]; 4]);
        let b = bytes("ScaleTranslateMap", &v);
        let mut c = Cursor::new(&b, 0);
        let (_, t) = read_transform(&mut c).unwrap();
        assert_eq!(t.voxel_size, [0.5, 0.25, 2.0]);
        assert_eq!(t.translation, [4.0, 5.0, 6.0]);
        assert_eq!(c.left(), 0);
    }

    #[test]
    fn rotations_and_bad_scales_are_refused() {
        let b = bytes("AffineMap", &[[1.0; 3]; 6]);
        let e = read_transform(&mut Cursor::new(&b, 0)).unwrap_err();
        assert_eq!(e.kind, ErrorKind::UnsupportedTransform("AffineMap".into()));
        let mut v = vec![[0.0, 1.0, 1.0]];
        v.extend([[1.0; 3]; 4]);
        let b = bytes("ScaleMap", &v);
        let e = read_transform(&mut Cursor::new(&b, 0)).unwrap_err();
        assert!(
            matches!(&e.kind, ErrorKind::Invalid(i) if matches!(**i, Invalid::Transform { .. })),
            "{e:?}"
        );
    }
}
