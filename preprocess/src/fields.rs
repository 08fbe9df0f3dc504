//! Baked fields: which ones, their per-cell values brick after brick, global range and
//! histogram, and per-region value bounds.

use format::Aabb;
use rayon::prelude::*;
use serde::Serialize;

use crate::bricks::BrickBox;
use std::sync::Arc;

use crate::kdtree::Regions;
use crate::spilled::{SpillTo, Store};

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
/// Two passes front to back, `chunk` values at a time, each chunk's range handed to
/// `release` once read (a reader of mapped values lets those pages go).
pub(crate) fn range_and_histogram(
    values: &[f32],
    chunk: usize,
    release: &dyn Fn(std::ops::Range<usize>),
) -> (f32, f32, Vec<u64>) {
    let chunk = chunk.max(1);
    let chunks = || {
        values
            .chunks(chunk)
            .enumerate()
            .map(move |(k, c)| (k * chunk..k * chunk + c.len(), c))
    };
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for (range, c) in chunks() {
        for &v in c.iter().filter(|v| v.is_finite()) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        release(range);
    }
    if lo > hi {
        return (0.0, 0.0, vec![0; HISTOGRAM_BINS]);
    }
    let mut hist = vec![0u64; HISTOGRAM_BINS];
    let span = hi as f64 - lo as f64;
    for (range, c) in chunks() {
        for &v in c.iter().filter(|v| v.is_finite()) {
            let b = if span > 0.0 {
                (((v as f64 - lo as f64) / span) * HISTOGRAM_BINS as f64) as usize
            } else {
                0
            };
            hist[b.min(HISTOGRAM_BINS - 1)] += 1;
        }
        release(range);
    }
    (lo, hi, hist)
}

/// The bricks' layout in the field arrays [`region_ranges`] reads: `first[b]` is brick
/// `b`'s first value; `origins[b]`, `widths[b]` its first cell centre and cell width.
pub(crate) struct RangeInput<'a> {
    pub bricks: &'a [BrickBox],
    pub origins: &'a [[f64; 3]],
    pub widths: &'a [f64],
    pub first: &'a [u64],
}

/// Where [`region_ranges`] reads the values (field `f` brick after brick in `values[f]`).
pub(crate) enum BrickValues<'a> {
    /// Resident (in memory): read in place.
    Resident(&'a [&'a [f32]]),
    /// Mapped from scratch files: each batch's bricks are copied out first, and
    /// `release(f, range)` lets the pages of what was copied go.
    Mapped {
        values: &'a [&'a [f32]],
        release: &'a (dyn Fn(usize, std::ops::Range<usize>) + Sync),
    },
}

/// Per-region, per-field `(min, max)` over every cell of the region's bricks whose tent
/// `(c − w, c + w)` reaches into the region box (`boxes` gives them in region order, see
/// [`crate::kdtree::leaf_boxes`]; a region without one gets no cells); conservative by a
/// hair at the edges.
///
/// Regions are taken [`REGION_BATCH`] at a time, in parallel within a batch, and fewer
/// when their bricks hold more than `window` values (all fields). Mapped values are read a
/// batch at a time: a batch's regions lie together, but their bricks' values are spread
/// over the arrays (a slab of space crosses every row of bricks), and every page fault
/// maps the pages around it too, so reading them in place would make most of the arrays
/// resident for every batch. Copied out, only the batch's bricks are held, and let go
/// behind every `window` values.
///
/// The ranges are kept as `store.0` says (in memory, or in a scratch file past a size), and
/// `store.1` is called behind every batch planned and every batch done (to let the pages of
/// the regions and tree go, when they are kept on disk).
pub(crate) fn region_ranges(
    input: &RangeInput,
    regions: &Regions,
    boxes: impl Iterator<Item = Aabb>,
    values: &BrickValues,
    window: usize,
    store: (Option<Arc<SpillTo>>, &dyn Fn()),
) -> Store<[f32; 2]> {
    ranges_in_batches(input, regions, boxes, values, REGION_BATCH, window, store)
}

/// [`region_ranges`], at most `batch` regions at a time.
fn ranges_in_batches(
    input: &RangeInput,
    regions: &Regions,
    mut boxes: impl Iterator<Item = Aabb>,
    values: &BrickValues,
    batch_regions: usize,
    window: usize,
    (to, behind_batch): (Option<Arc<SpillTo>>, &dyn Fn()),
) -> Store<[f32; 2]> {
    let batch_regions = batch_regions.max(1);
    let nf = match values {
        BrickValues::Resident(v) | BrickValues::Mapped { values: v, .. } => v.len(),
    };
    // Region-major, as the file stores them; written in place (no list per region).
    let mut ranges = Store::new(to);
    ranges.resize(regions.len() * nf, [f32::INFINITY, f32::NEG_INFINITY]);
    if nf == 0 || ranges.failed().is_some() {
        return ranges;
    }
    let cells = |b: usize| input.bricks[b].cells() as usize;
    // Mapped values: where each brick of the batch is in the copies (`NONE`: not copied).
    const NONE: u32 = u32::MAX;
    let mut slot = match values {
        BrickValues::Resident(_) => Vec::new(),
        BrickValues::Mapped { .. } => vec![NONE; input.bricks.len()],
    };
    // Batches: consecutive regions, as many as `batch_regions` and their bricks' values
    // (counted once per region that names them: an upper bound) within the window.
    let mut batches = Vec::new();
    let mut start = 0;
    while start < regions.len() {
        let (mut end, mut held) = (start, 0usize);
        while end < regions.len() && end - start < batch_regions {
            let more: usize = regions
                .bricks_of(end)
                .iter()
                .map(|&b| cells(b as usize))
                .sum();
            if end > start && held + more * nf > window {
                break;
            }
            held += more * nf;
            end += 1;
        }
        batches.push(start..end);
        start = end;
        // Planning reads every region's list: kept on disk, its pages go behind.
        behind_batch();
    }
    for regs in batches {
        let first = regs.start;
        let batch = &mut ranges[first * nf..regs.end * nf];
        let batch_boxes: Vec<Aabb> = boxes.by_ref().take(regs.len()).collect();
        match values {
            BrickValues::Resident(v) => {
                let get = |f: usize, b: usize| {
                    let at = input.first[b] as usize;
                    &v[f][at..at + cells(b)]
                };
                ranges_of_batch(input, regions, first, &batch_boxes, nf, batch, &get);
            }
            BrickValues::Mapped { values, release } => {
                let regs = first..first + batch.len() / nf;
                let mut ids: Vec<u32> = regs.flat_map(|r| regions.bricks_of(r)).copied().collect();
                ids.sort_unstable();
                ids.dedup();
                let mut at = Vec::with_capacity(ids.len() + 1);
                at.push(0usize);
                for (i, &b) in ids.iter().enumerate() {
                    at.push(at[i] + cells(b as usize));
                    slot[b as usize] = i as u32;
                }
                // Front to back (the ids are sorted, and bricks lie in id order), letting
                // go of what lies behind every window of values, and of the rest
                // (with the pages mapped around the last reads) at the end.
                let copied: Vec<Vec<f32>> = (0..nf)
                    .map(|f| {
                        let mut out = Vec::with_capacity(at[ids.len()]);
                        let mut behind = 0;
                        for &b in &ids {
                            let start = input.first[b as usize] as usize;
                            out.extend_from_slice(&values[f][start..start + cells(b as usize)]);
                            if start - behind >= window {
                                release(f, behind..start);
                                behind = start;
                            }
                        }
                        release(f, 0..values[f].len());
                        out
                    })
                    .collect();
                let get = |f: usize, b: usize| {
                    let i = slot[b] as usize;
                    &copied[f][at[i]..at[i + 1]]
                };
                ranges_of_batch(input, regions, first, &batch_boxes, nf, batch, &get);
                for &b in &ids {
                    slot[b as usize] = NONE;
                }
            }
        }
        ranges.release(first * nf..regs.end * nf);
        behind_batch();
    }
    ranges
}

/// Regions whose ranges [`region_ranges`] finds at once: their bricks' values are a few
/// tens of megabytes.
pub(crate) const REGION_BATCH: usize = 1 << 16;

/// The ranges of the regions from `first` on, into `out` (`nf` entries a region);
/// `get(f, b)` is brick `b`'s values of field `f`.
fn ranges_of_batch<'v>(
    input: &RangeInput,
    regions: &Regions,
    first: usize,
    boxes: &[Aabb],
    nf: usize,
    out: &mut [[f32; 2]],
    get: &(dyn Fn(usize, usize) -> &'v [f32] + Sync),
) {
    const NO_BOX: Aabb = Aabb {
        min: [0.0; 3],
        max: [0.0; 3],
    };
    out.par_chunks_mut(nf).enumerate().for_each(|(k, out)| {
        let r = first + k;
        // Without a box (a tree with fewer region leaves than regions) no cell counts.
        let (rb, bricks) = match boxes.get(k) {
            Some(rb) => (rb, regions.bricks_of(r)),
            None => (&NO_BOX, &[][..]),
        };
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
            for (f, r) in out.iter_mut().enumerate() {
                let vals = get(f, b);
                for z in lo[2]..=hi[2] {
                    for y in lo[1]..=hi[1] {
                        let row = nx * (y + ny * z);
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use format::Region;

    /// Mapped values, copied out a batch at a time, give the ranges read in place, for
    /// batches of one region to all of them; every value's pages are let go after each
    /// batch. Bricks of two widths, regions listing up to three bricks (one of them in
    /// every batch), non-finite values among the cells.
    #[test]
    fn ranges_of_mapped_values_in_batches_are_those_read_in_place() {
        let bricks: Vec<BrickBox> = (0..6)
            .map(|b| BrickBox {
                set: b % 2,
                level: (b % 2) as u32,
                lo: [0; 3],
                dims: [2 + (b as u32 % 3), 2, 1 + (b as u32 % 2)],
            })
            .collect();
        let widths: Vec<f64> = (0..6).map(|b| [0.5, 1.0][b % 2]).collect();
        let origins: Vec<[f64; 3]> = (0..6).map(|b| [b as f64 * 0.7, 0.25, -0.5]).collect();
        let mut first = Vec::new();
        let mut total = 0u64;
        for b in &bricks {
            first.push(total);
            total += b.cells();
        }
        let field = |k: usize| -> Vec<f32> {
            (0..total as usize)
                .map(|i| match (i * 7 + k) % 11 {
                    3 => f32::NAN,
                    5 => f32::INFINITY,
                    r => (r as f32 - 4.5) * (k as f32 + 1.0) + i as f32 * 0.01,
                })
                .collect()
        };
        let values = [field(0), field(1)];
        let slices: Vec<&[f32]> = values.iter().map(Vec::as_slice).collect();
        let mut regions = Regions::default();
        let mut boxes = Vec::new();
        for r in 0..9 {
            let lo = r as f64 * 0.45 - 0.3;
            let ids: Vec<u32> = [0, (r % 5 + 1) as u32, ((r * 2) % 6) as u32]
                .into_iter()
                .collect::<std::collections::BTreeSet<_>>()
                .into_iter()
                .collect();
            boxes.push(Aabb {
                min: [lo, 0.0, -0.6],
                max: [lo + 0.9, 1.4, 0.4],
            });
            regions.runs.push(Region {
                bricks_start: regions.bricks.len() as u32,
                bricks_len: ids.len() as u32,
            });
            regions.bricks.extend(ids);
        }
        let input = RangeInput {
            bricks: &bricks,
            origins: &origins,
            widths: &widths,
            first: &first,
        };
        let in_place = region_ranges(
            &input,
            &regions,
            boxes.iter().copied(),
            &BrickValues::Resident(&slices),
            1 << 20,
            (None, &|| {}),
        );
        assert!(!in_place.on_disk());
        assert_eq!(in_place.len(), 9 * 2);
        assert!(in_place.iter().all(|r| r[0].is_finite() && r[0] <= r[1]));
        for batch in [1, 2, 4, 9, 100] {
            let released = std::sync::Mutex::new(Vec::new());
            let release = |f: usize, r: std::ops::Range<usize>| {
                released.lock().expect("lock").push((f, r));
            };
            let mapped = BrickValues::Mapped {
                values: &slices,
                release: &release,
            };
            let in_batches = |window: usize| {
                let boxes = boxes.iter().copied();
                ranges_in_batches(
                    &input,
                    &regions,
                    boxes,
                    &mapped,
                    batch,
                    window,
                    (None, &|| {}),
                )
            };
            let ranges = in_batches(usize::MAX);
            let bits = |v: &[[f32; 2]]| -> Vec<[u32; 2]> {
                v.iter().map(|r| r.map(f32::to_bits)).collect()
            };
            assert_eq!(bits(&ranges), bits(&in_place), "batch {batch}");
            // Kept in a scratch file, with a call behind every batch: the same ranges.
            let dir = tempfile::tempdir().expect("tempdir");
            let to = Arc::new(SpillTo {
                dir: dir.path().to_path_buf(),
                above: 0,
                window: 64,
            });
            let calls = std::sync::atomic::AtomicUsize::new(0);
            let behind = || {
                calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            };
            let on_disk = ranges_in_batches(
                &input,
                &regions,
                boxes.iter().copied(),
                &BrickValues::Resident(&slices),
                batch,
                usize::MAX,
                (Some(to), &behind),
            );
            assert!(on_disk.on_disk());
            assert_eq!(bits(&on_disk), bits(&in_place), "batch {batch} on disk");
            // Behind every batch planned, and every batch done.
            assert_eq!(
                calls.into_inner(),
                2 * 9usize.div_ceil(batch),
                "batch {batch}"
            );
            let whole = released
                .lock()
                .expect("lock")
                .iter()
                .filter(|(_, r)| *r == (0..total as usize))
                .count();
            assert_eq!(whole, 2 * 9usize.div_ceil(batch), "batch {batch}");
            // Batches cut by the values their bricks hold give the same ranges.
            for window in [1, 40, 700] {
                let ranges = in_batches(window);
                assert_eq!(
                    bits(&ranges),
                    bits(&in_place),
                    "batch {batch} window {window}"
                );
            }
        }
    }
}
