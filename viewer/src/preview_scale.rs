//! The divisor of the window's previews, chosen from what recent previews cost.
//!
//! A preview renders at `1/scale` of the view's resolution on each axis, and should take
//! about a time budget, so that previews keep up with the user's drag. The first
//! controller stepped the divisor by one whenever a single preview was slower than 1.3×
//! the budget: one preview slowed by the UI's own frame or a page fault sent every later
//! preview coarser, and getting finer again needed one faster than half the budget. On
//! the benchmark views that showed a quarter of the resolution now and then although a
//! third kept within the budget.
//!
//! This one predicts instead. A preview's cost per pixel is about constant from one
//! divisor to the next (the same rays, fewer of them), so the median cost per pixel of
//! the last few previews, times the pixels of a candidate divisor, predicts its time.
//! The finest divisor predicted within [`SLACK`] × the budget is taken. The median lets
//! one slow preview pass; a view that really got slower (zoomed into the surface, a
//! larger file) moves the divisor after three previews, straight to the one that fits,
//! rather than one step per preview. The costs of another file's previews start over;
//! its first preview moves the divisor only when far off the budget (see
//! [`LONE_FACTOR`]).

use std::collections::VecDeque;

/// How many recent previews the prediction takes the median of.
const HISTORY: usize = 5;

/// A predicted preview time up to this multiple of the budget is accepted.
const SLACK: f64 = 1.3;

/// A lone timing (a file's first preview) moves the divisor only when it is off the
/// accepted time by more than this factor: the first preview of a file also pays for
/// its first page faults (44 ms against 20–35 ms for the next ones on the benchmark
/// views), while a file too large for the divisor (seconds a preview) should not wait
/// for a second slow one.
const LONE_FACTOR: f64 = 4.0;

/// The preview divisor and the costs it is chosen from.
#[derive(Debug, Clone)]
pub struct PreviewScale {
    scale: u32,
    min: u32,
    max: u32,
    budget_ms: f64,
    /// Milliseconds per rendered pixel of the last previews, newest last.
    costs: VecDeque<f64>,
}

impl PreviewScale {
    /// Starts at the finest divisor allowed; `min` and `max` are clamped to at least 1.
    pub fn new(min: u32, max: u32, budget_ms: f64) -> PreviewScale {
        let min = min.max(1);
        PreviewScale {
            scale: min,
            min,
            max: max.max(min),
            budget_ms,
            costs: VecDeque::with_capacity(HISTORY),
        }
    }

    /// The divisor the next preview should use.
    pub fn scale(&self) -> u32 {
        self.scale
    }

    /// Takes in a finished preview of a `width`×`height` view, rendered at `pixels`
    /// pixels in `ms`, and picks the divisor of the next one.
    pub fn record(&mut self, width: u32, height: u32, pixels: u64, ms: f64) {
        if pixels == 0 || !ms.is_finite() || ms < 0.0 {
            return;
        }
        if self.costs.len() == HISTORY {
            self.costs.pop_front();
        }
        self.costs.push_back(ms / pixels as f64);
        let mut sorted: Vec<f64> = self.costs.iter().copied().collect();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        let cost = (sorted[(n - 1) / 2] + sorted[n / 2]) / 2.0;
        let limit = SLACK * self.budget_ms;
        let now = cost * preview_pixels(width, height, self.scale) as f64;
        if sorted.len() == 1 && now <= LONE_FACTOR * limit {
            return;
        }
        self.scale = (self.min..=self.max)
            .find(|&s| cost * preview_pixels(width, height, s) as f64 <= limit)
            .unwrap_or(self.max);
    }

    /// Forgets the costs seen (another file: they say nothing about its previews); the
    /// divisor stays until the new file's previews are timed.
    pub fn forget(&mut self) {
        self.costs.clear();
    }
}

/// Pixels of a `width`×`height` view's preview at divisor `scale`.
pub fn preview_pixels(width: u32, height: u32, scale: u32) -> u64 {
    let s = scale.max(1);
    u64::from(width.max(1).div_ceil(s)) * u64::from(height.max(1).div_ceil(s))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A preview of a 1200×900 view at `scale` that cost `per_px` ms per pixel.
    fn preview(p: &mut PreviewScale, scale: u32, per_px: f64) {
        let px = preview_pixels(1200, 900, scale);
        p.record(1200, 900, px, per_px * px as f64);
    }

    /// The cost per pixel at which a preview at `scale` takes exactly `ms`.
    fn cost_for(scale: u32, ms: f64) -> f64 {
        ms / preview_pixels(1200, 900, scale) as f64
    }

    #[test]
    fn a_first_preview_a_little_slow_does_not_coarsen() {
        let mut p = PreviewScale::new(3, 16, 30.0);
        preview(&mut p, 3, cost_for(3, 45.0));
        assert_eq!(p.scale(), 3);
        preview(&mut p, 3, cost_for(3, 25.0));
        assert_eq!(p.scale(), 3);
        // Two slow ones in a row do.
        let mut q = PreviewScale::new(3, 16, 30.0);
        preview(&mut q, 3, cost_for(3, 45.0));
        preview(&mut q, 3, cost_for(3, 45.0));
        assert_eq!(q.scale(), 4);
    }

    #[test]
    fn one_slow_preview_does_not_coarsen() {
        let mut p = PreviewScale::new(3, 16, 30.0);
        let usual = cost_for(3, 28.0);
        for _ in 0..5 {
            preview(&mut p, 3, usual);
        }
        // A preview twice as slow (the UI's frame beside it): the median is still usual.
        preview(&mut p, 3, 2.0 * usual);
        assert_eq!(p.scale(), 3);
        preview(&mut p, 3, usual);
        assert_eq!(p.scale(), 3);
    }

    #[test]
    fn a_lasting_slowdown_goes_straight_to_the_divisor_that_fits() {
        let mut p = PreviewScale::new(3, 16, 30.0);
        // Ten times the cost per pixel: 280 ms at a third.
        for _ in 0..3 {
            preview(&mut p, 3, cost_for(3, 28.0));
        }
        let slow = cost_for(3, 280.0);
        preview(&mut p, 3, slow);
        preview(&mut p, 3, slow);
        assert_eq!(p.scale(), 3, "two of five are not a trend");
        preview(&mut p, 3, slow);
        let s = p.scale();
        let predicted = |s: u32| slow * preview_pixels(1200, 900, s) as f64;
        assert!(predicted(s) <= SLACK * 30.0, "scale {s}");
        assert!(
            predicted(s - 1) > SLACK * 30.0,
            "scale {s} is not the finest that fits"
        );
        assert!(s >= 9, "one step per preview would give 4, got {s}");
    }

    #[test]
    fn faster_previews_come_back_to_the_finest_allowed() {
        let mut p = PreviewScale::new(3, 16, 30.0);
        for _ in 0..3 {
            preview(&mut p, 3, cost_for(3, 300.0));
        }
        assert!(p.scale() > 3);
        // The view got cheap again (turned away from the surface).
        for _ in 0..HISTORY / 2 + 1 {
            let s = p.scale();
            preview(&mut p, s, cost_for(3, 20.0));
        }
        assert_eq!(p.scale(), 3);
    }

    #[test]
    fn the_divisor_stays_within_its_bounds() {
        let mut p = PreviewScale::new(2, 5, 30.0);
        for _ in 0..3 {
            preview(&mut p, 2, 1.0);
        }
        assert_eq!(p.scale(), 5, "nothing fits: the coarsest allowed");
        for _ in 0..3 {
            preview(&mut p, 5, 0.0);
        }
        assert_eq!(p.scale(), 2);
        // Nonsense timings are ignored.
        p.record(1200, 900, 0, 10.0);
        p.record(1200, 900, 100, f64::NAN);
        p.record(1200, 900, 100, -1.0);
        assert_eq!(p.scale(), 2);
        let q = PreviewScale::new(0, 0, 30.0);
        assert_eq!((q.scale(), q.max), (1, 1));
    }

    #[test]
    fn another_file_starts_its_own_median() {
        let mut p = PreviewScale::new(3, 16, 30.0);
        for _ in 0..3 {
            preview(&mut p, 3, cost_for(3, 20.0));
        }
        p.forget();
        // The new file's first preview is far too slow: it sets the divisor at once,
        // where the old costs would have outvoted it.
        preview(&mut p, 3, cost_for(3, 400.0));
        assert!(p.scale() > 3);
        let mut kept = PreviewScale::new(3, 16, 30.0);
        for _ in 0..3 {
            preview(&mut kept, 3, cost_for(3, 20.0));
        }
        preview(&mut kept, 3, cost_for(3, 400.0));
        assert_eq!(kept.scale(), 3);
    }
}
