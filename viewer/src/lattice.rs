//! The cell lattices of a region: the grids its bricks' cells lie on. `exact` cuts a ray
//! at the planes of every lattice of a region (between them the reconstruction is a
//! cubic), and a region of one lattice can have a dual-cell mask ([`crate::dual_mask`]);
//! the active tree lists each leaf's lattices once ([`crate::active`]).

use crate::volume::Volume;

/// Most distinct cell lattices `exact` cuts planes for in one region.
pub(crate) const MAX_LATTICES: usize = 8;

/// One cell lattice of a region: cell width, its inverse and one cell centre (local).
pub(crate) type Lattice = (f64, f64, [f64; 3]);

/// The distinct cell lattices of a region's bricks (at most [`MAX_LATTICES`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Lattices {
    list: [Lattice; MAX_LATTICES],
    n: usize,
    /// The region has more lattices than are listed (see
    /// [`Stats::inexact_segments`](crate::sampling::Stats::inexact_segments)).
    pub(crate) inexact: bool,
}

impl Lattices {
    /// The lattices of region `r`: bricks whose cells are whole cells apart share one.
    pub(crate) fn of(vol: &Volume, r: usize) -> Lattices {
        let mut l = Lattices {
            list: [(0.0, 0.0, [0.0; 3]); MAX_LATTICES],
            n: 0,
            inexact: false,
        };
        for b in vol.region_brick_ids(r) {
            let br = vol.brick(b.to_native());
            let same = |&(w, _, origin): &Lattice| {
                w == br.w
                    && (origin == br.origin
                        || (0..3).all(|a| {
                            // Whole cells apart (a cast truncates in one instruction;
                            // `round` is a library call on the baseline target).
                            let q = (origin[a] - br.origin[a]) * br.inv_w;
                            let frac = (q - q as i64 as f64).abs();
                            !(1e-9..=1.0 - 1e-9).contains(&frac)
                        }))
            };
            if l.list[..l.n].iter().any(same) {
                continue;
            }
            if l.n == MAX_LATTICES {
                // More distinct lattices in one region than are cut (never produced by
                // nested grids of one refinement ratio): the remaining lattices' planes are
                // not cut, so intervals there are only approximately cubic. Counted in
                // `Stats::inexact_segments` and reported by `render --json`.
                l.inexact = true;
                break;
            }
            l.list[l.n] = (br.w, br.inv_w, br.origin);
            l.n += 1;
        }
        l
    }

    pub(crate) fn as_slice(&self) -> &[Lattice] {
        &self.list[..self.n]
    }
}
