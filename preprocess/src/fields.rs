//! Baked fields: which ones, their per-cell values brick after brick, global range and
//! histogram, and per-region value bounds.

use rayon::prelude::*;
use serde::Serialize;

use crate::bricks::BrickBox;
use crate::kdtree::Regions;

/// Bins of every field's histogram.
pub(crate) const HISTOGRAM_BINS: usize = 64;

/// A baked field: derived from the velocity, or a scalar grid of the file resampled onto
/// the velocity's leaf cells.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FieldKind {
    /// Q-criterion.
    Q,
    /// Velocity magnitude.
    Speed,
    /// Vorticity magnitude `|∇ × u|`.
    Vorticity,
    /// λ2 criterion: the middle eigenvalue of `S² + Ω²`, negative in vortex cores.
    Lambda2,
    /// Normalised helicity `u · ω / (|u| |ω|)`, in [−1, 1].
    Helicity,
    /// The three velocity components (three fields `velocity_x`, `velocity_y`, `velocity_z`).
    Velocity,
    /// The scalar grid(s) of this name, sampled trilinearly at the leaf-cell centres.
    Scalar(String),
}

impl FieldKind {
    /// `q`, `speed`, `vorticity`, `lambda2`, `helicity`, `velocity`, or `None` for any other
    /// name (a scalar grid's, for callers that take extra fields: see
    /// [`FieldKind::parse_or_grid`]).
    pub(crate) fn parse(s: &str) -> Option<FieldKind> {
        match s.trim().to_ascii_lowercase().as_str() {
            "q" => Some(FieldKind::Q),
            "speed" => Some(FieldKind::Speed),
            "vorticity" => Some(FieldKind::Vorticity),
            "lambda2" => Some(FieldKind::Lambda2),
            "helicity" => Some(FieldKind::Helicity),
            "velocity" => Some(FieldKind::Velocity),
            _ => None,
        }
    }

    /// As [`FieldKind::parse`], any other (non-empty) name being a scalar grid's.
    pub fn parse_or_grid(s: &str) -> Option<FieldKind> {
        let t = s.trim();
        match FieldKind::parse(t) {
            Some(k) => Some(k),
            None if !t.is_empty() => Some(FieldKind::Scalar(t.to_string())),
            None => None,
        }
    }

    /// Names of the file fields this kind produces.
    pub(crate) fn names(&self) -> Vec<String> {
        match self {
            FieldKind::Q => vec!["q".into()],
            FieldKind::Speed => vec!["speed".into()],
            FieldKind::Vorticity => vec!["vorticity".into()],
            FieldKind::Lambda2 => vec!["lambda2".into()],
            FieldKind::Helicity => vec!["helicity".into()],
            FieldKind::Velocity => ["velocity_x", "velocity_y", "velocity_z"]
                .map(String::from)
                .to_vec(),
            FieldKind::Scalar(name) => vec![name.clone()],
        }
    }

    /// Whether the field is made from the velocity gradient (one stencil for all of them,
    /// computed once per cell).
    pub(crate) fn needs_gradient(&self) -> bool {
        matches!(
            self,
            FieldKind::Q | FieldKind::Vorticity | FieldKind::Lambda2 | FieldKind::Helicity
        )
    }
}

/// Range over finite values (`(0, 0)` when there is none) and histogram over that range.
pub(crate) fn range_and_histogram(values: &[f32]) -> (f32, f32, Vec<u64>) {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for &v in values.iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return (0.0, 0.0, vec![0; HISTOGRAM_BINS]);
    }
    let mut hist = vec![0u64; HISTOGRAM_BINS];
    let span = hi as f64 - lo as f64;
    for &v in values.iter().filter(|v| v.is_finite()) {
        let b = if span > 0.0 {
            (((v as f64 - lo as f64) / span) * HISTOGRAM_BINS as f64) as usize
        } else {
            0
        };
        hist[b.min(HISTOGRAM_BINS - 1)] += 1;
    }
    (lo, hi, hist)
}

/// Per-region, per-field `(min, max)` over every cell of the region's bricks whose tent
/// `(c − w, c + w)` reaches into the region box; conservative by a hair at the edges.
/// `values[f]` is field `f` brick after brick; `first[b]` is brick `b`'s first value;
/// `origins[b]`, `widths[b]` its first cell centre and cell width.
pub(crate) struct RangeInput<'a> {
    pub bricks: &'a [BrickBox],
    pub origins: &'a [[f64; 3]],
    pub widths: &'a [f64],
    pub first: &'a [u64],
    pub values: &'a [Vec<f32>],
}

pub(crate) fn region_ranges(input: &RangeInput, regions: &Regions) -> Vec<[f32; 2]> {
    let nf = input.values.len();
    // Region-major, as the file stores them; written in place (no list per region).
    let mut ranges = vec![[f32::INFINITY, f32::NEG_INFINITY]; regions.len() * nf];
    if nf == 0 {
        return ranges;
    }
    ranges
        .par_chunks_mut(nf)
        .enumerate()
        .for_each(|(r, out)| {
            let rb = &regions.bounds[r];
            let bricks = regions.bricks_of(r);
            for &b in bricks {
                let b = b as usize;
                let bx = &input.bricks[b];
                let o = input.origins[b];
                let w = input.widths[b];
                let mut lo = [0usize; 3];
                let mut hi = [0usize; 3];
                for a in 0..3 {
                    let d = bx.dims[a] as f64;
                    let l = ((rb.min[a] - o[a]) / w - 1.0 - 1e-6)
                        .ceil()
                        .clamp(0.0, d - 1.0);
                    let h = ((rb.max[a] - o[a]) / w + 1.0 + 1e-6)
                        .floor()
                        .clamp(0.0, d - 1.0);
                    lo[a] = l as usize;
                    hi[a] = h as usize;
                }
                let (nx, ny) = (bx.dims[0] as usize, bx.dims[1] as usize);
                let base = input.first[b] as usize;
                for (f, r) in out.iter_mut().enumerate() {
                    let vals = &input.values[f];
                    for z in lo[2]..=hi[2] {
                        for y in lo[1]..=hi[1] {
                            let row = base + nx * (y + ny * z);
                            for &v in &vals[row + lo[0]..=row + hi[0]] {
                                if v.is_finite() {
                                    r[0] = r[0].min(v);
                                    r[1] = r[1].max(v);
                                }
                            }
                        }
                    }
                }
            }
            // A region whose cells are all non-finite gets an empty-but-valid range.
            for r in out.iter_mut() {
                if r[0] > r[1] {
                    *r = [0.0, 0.0];
                }
            }
        });
    ranges
}
