//! Grid transforms, the writer's side of [`crate::vdb::transform`]: a scale + translation
//! map, the only kind qbricks grids have, stored with the derived vectors OpenVDB's
//! `ScaleTranslateMap` keeps so that OpenVDB reads it without recomputing them.

use super::{write_string, Unwritable};
use crate::grid::Transform;

/// Refuses a transform OpenVDB could not invert (zero, negative or non-finite scale) or
/// place (non-finite translation).
pub(super) fn check_transform(t: &Transform) -> Result<(), Unwritable> {
    if !(t.voxel_size.iter().all(|v| v.is_finite() && *v > 0.0)
        && t.translation.iter().all(|v| v.is_finite()))
    {
        return Err(Unwritable::Transform { transform: *t });
    }
    Ok(())
}

/// Map type name, then translation, scale, voxel size, 1/scale, 1/scale² and 1/(2 scale).
pub(super) fn write_transform(out: &mut Vec<u8>, t: &Transform) {
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
