//! Front-to-back region traversal along a ray: the file's own KD walk
//! ([`format::kd::segments`]) in the volume's local frame.

pub use format::kd::{inverse, ray_box, Segment, Skip, SKIPPED};

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
        let skip = format::kd::keep_all();
        self.segments_skipping(o, d, t_min, t_max, stack, &skip, f)
    }

    /// As [`Volume::segments`], but a KD subtree whose value range `skip.keep` rejects is
    /// reported as one [`SKIPPED`] segment over the ray's part of the subtree's cell.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn segments_skipping<K: Fn(f32, f32) -> bool, F: FnMut(Segment) -> bool>(
        &self,
        o: [f64; 3],
        d: [f64; 3],
        t_min: f64,
        t_max: f64,
        stack: &mut Vec<(u32, f64, f64)>,
        skip: &Skip<K>,
        f: F,
    ) {
        format::kd::segments(self.file, self.frame, o, d, t_min, t_max, stack, skip, f)
    }
}
