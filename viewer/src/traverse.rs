//! Front-to-back region traversal along a ray: the file's KD walk
//! ([`format::kd::segments`]) in the volume's local frame, over the tree packed with the
//! walked field's ranges (`crate::packed`) so that a subtree whose values cannot matter
//! is stepped over as one segment.

pub use format::kd::{inverse, ray_box, Segment, Skip, SKIPPED};

use crate::packed::Packed;
use crate::volume::Volume;

impl Volume<'_> {
    /// Calls `f` for every region the ray `o + t d` (local frame) crosses within
    /// `[t_min, t_max]`, front to back; `f` returns `false` to stop.
    pub fn segments<F: FnMut(Segment) -> bool>(
        &self,
        o: [f64; 3],
        d: [f64; 3],
        t_min: f64,
        t_max: f64,
        stack: &mut Vec<(u32, f64, f64)>,
        f: F,
    ) {
        // Nothing is skipped, so any packing will do: the point-location tree's.
        let skip = format::kd::keep_all();
        segments_skipping(
            self,
            self.locate_tree(),
            o,
            d,
            t_min,
            t_max,
            stack,
            &skip,
            f,
        )
    }
}

/// As [`Volume::segments`], but a KD subtree whose value range of field `skip.field`
/// `skip.keep` rejects is reported as one [`SKIPPED`] segment over the ray's part of the
/// subtree's cell. `packed` is the tree packed with that field's ranges (a view's, see
/// [`crate::accel::Accel`]); without it the archived tree is walked, its ranges derived
/// node by node.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(crate) fn segments_skipping<K: Fn(f32, f32) -> bool, F: FnMut(Segment) -> bool>(
    vol: &Volume,
    packed: Option<&Packed>,
    o: [f64; 3],
    d: [f64; 3],
    t_min: f64,
    t_max: f64,
    stack: &mut Vec<(u32, f64, f64)>,
    skip: &Skip<K>,
    f: F,
) {
    match packed {
        Some(packed) => format::kd::segments(
            vol.file, packed, vol.frame, o, d, t_min, t_max, stack, skip, f,
        ),
        None => {
            let stored = format::kd::FileNodes::new(vol.file, skip.field);
            format::kd::segments(
                vol.file, &stored, vol.frame, o, d, t_min, t_max, stack, skip, f,
            )
        }
    }
}
