//! An 8-bit RGB image to draw overlays into: blended pixels, anti-aliased lines and
//! rectangles, and text.
//!
//! Overlays are drawn into the finished image, so everything here works on the bytes that
//! go into the PNG: a pixel is blended as `c·a + old·(1 − a)` with the coverage of the
//! shape as `a`. Text is rasterised with `ab_glyph` from a font bundled with egui (Hack,
//! a monospace face with unambiguous digits, MIT/Bitstream Vera licence), so no system
//! fonts are needed and the result is the same on every machine.

use ab_glyph::{Font, FontRef, PxScale, ScaleFont};

/// The bundled face every overlay writes with.
fn font() -> Option<FontRef<'static>> {
    FontRef::try_from_slice(epaint_default_fonts::HACK_REGULAR).ok()
}

/// A `width`×`height` RGB image, row-major from the top-left, 3 bytes per pixel.
pub struct Canvas<'a> {
    pub width: u32,
    pub height: u32,
    px: &'a mut [u8],
}

impl<'a> Canvas<'a> {
    /// `None` when `px` is not `3·width·height` bytes.
    pub fn new(px: &'a mut [u8], width: u32, height: u32) -> Option<Canvas<'a>> {
        (px.len() == 3 * width as usize * height as usize).then_some(Canvas { width, height, px })
    }

    /// Blends `rgb` (0..=1) over pixel (`x`, `y`) with opacity `a`; outside: nothing.
    pub fn blend(&mut self, x: i64, y: i64, rgb: [f32; 3], a: f32) {
        if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
            return;
        }
        let a = a.clamp(0.0, 1.0);
        if a <= 0.0 {
            return;
        }
        let i = 3 * (y as usize * self.width as usize + x as usize);
        for c in 0..3 {
            let old = f32::from(self.px[i + c]);
            let new = rgb[c].clamp(0.0, 1.0) * 255.0;
            self.px[i + c] = (new * a + old * (1.0 - a) + 0.5) as u8;
        }
    }

    /// The colour of pixel (`x`, `y`) in 0..=1 (black outside).
    pub fn get(&self, x: i64, y: i64) -> [f32; 3] {
        if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
            return [0.0; 3];
        }
        let i = 3 * (y as usize * self.width as usize + x as usize);
        std::array::from_fn(|c| f32::from(self.px[i + c]) / 255.0)
    }

    /// Fills the rectangle `[x0, x1) × [y0, y1)` (pixel edges, fractional edges blended by
    /// the covered share).
    pub fn fill_rect(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, rgb: [f32; 3], a: f32) {
        let (xa, xb) = (x0.floor() as i64, x1.ceil() as i64);
        let (ya, yb) = (y0.floor() as i64, y1.ceil() as i64);
        for y in ya..yb {
            let cy = overlap(y as f64, y0, y1);
            for x in xa..xb {
                let cover = overlap(x as f64, x0, x1) * cy;
                self.blend(x, y, rgb, a * cover as f32);
            }
        }
    }

    /// A line from (`x0`, `y0`) to (`x1`, `y1`) of `width` pixels with round ends,
    /// anti-aliased by the distance of each pixel centre to the segment. Only the pixels
    /// within reach of the segment are visited (a strip along its longer axis), so a long
    /// diagonal costs its length, not its bounding box.
    #[allow(clippy::too_many_arguments)]
    pub fn line(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, width: f64, rgb: [f32; 3], a: f32) {
        if !(x0.is_finite() && y0.is_finite() && x1.is_finite() && y1.is_finite()) {
            return;
        }
        let r = 0.5 * width.max(0.5);
        let reach = r + 1.0;
        let (dx, dy) = (x1 - x0, y1 - y0);
        let len2 = dx * dx + dy * dy;
        let coverage = |px: f64, py: f64| {
            let t = if len2 > 0.0 {
                (((px - x0) * dx + (py - y0) * dy) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let (qx, qy) = (x0 + t * dx - px, y0 + t * dy - py);
            (r + 0.5 - (qx * qx + qy * qy).sqrt()).clamp(0.0, 1.0)
        };
        // Walk the longer axis; across it, the pixels within `reach` of the line (wider
        // where the line is steep relative to the walked axis).
        let steep = dy.abs() > dx.abs();
        let (a0, a1, b0, slope) = if steep {
            (
                y0.min(y1),
                y0.max(y1),
                if y0 <= y1 { x0 } else { x1 },
                if dy != 0.0 { dx / dy } else { 0.0 },
            )
        } else {
            (
                x0.min(x1),
                x0.max(x1),
                if x0 <= x1 { y0 } else { y1 },
                if dx != 0.0 { dy / dx } else { 0.0 },
            )
        };
        let (limit_a, limit_b) = if steep {
            (i64::from(self.height), i64::from(self.width))
        } else {
            (i64::from(self.width), i64::from(self.height))
        };
        let spread = reach * (1.0 + slope * slope).sqrt();
        let start = ((a0 - reach).floor() as i64).max(0);
        let end = ((a1 + reach).ceil() as i64).min(limit_a);
        for i in start..end {
            let ac = (i as f64 + 0.5).clamp(a0, a1);
            let bc = b0 + (ac - a0) * slope;
            let lo = ((bc - spread).floor() as i64).max(0);
            let hi = ((bc + spread).ceil() as i64).min(limit_b);
            for j in lo..hi {
                let (x, y) = if steep { (j, i) } else { (i, j) };
                let cover = coverage(x as f64 + 0.5, y as f64 + 0.5);
                self.blend(x, y, rgb, a * cover as f32);
            }
        }
    }

    /// Writes `text` with its baseline starting at (`x`, `y`), `size` pixels high (the
    /// font's em); returns the pen position after it.
    pub fn text(&mut self, x: f64, y: f64, size: f64, text: &str, rgb: [f32; 3], a: f32) -> f64 {
        let Some(font) = font() else {
            return x;
        };
        let scale = PxScale::from(size as f32);
        let scaled = font.as_scaled(scale);
        let mut caret = x as f32;
        for c in text.chars() {
            let id = font.glyph_id(c);
            let glyph = id.with_scale_and_position(scale, ab_glyph::point(caret, y as f32));
            caret += scaled.h_advance(id);
            if let Some(outlined) = font.outline_glyph(glyph) {
                let b = outlined.px_bounds();
                let (ox, oy) = (b.min.x as i64, b.min.y as i64);
                outlined.draw(|gx, gy, cover| {
                    self.blend(ox + i64::from(gx), oy + i64::from(gy), rgb, a * cover);
                });
            }
        }
        f64::from(caret)
    }

    /// [`Canvas::text`] over a one-pixel halo of `halo` (every offset of ±`spread`
    /// pixels), legible on any picture.
    #[allow(clippy::too_many_arguments)]
    pub fn text_with_halo(
        &mut self,
        x: f64,
        y: f64,
        size: f64,
        text: &str,
        rgb: [f32; 3],
        halo: [f32; 3],
        spread: f64,
    ) -> f64 {
        for (dx, dy) in [(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)] {
            self.text(x + dx * spread, y + dy * spread, size, text, halo, 0.8);
        }
        self.text(x, y, size, text, rgb, 1.0)
    }
}

/// Width in pixels of `text` at `size`.
pub fn text_width(size: f64, text: &str) -> f64 {
    let Some(font) = font() else {
        return 0.0;
    };
    let scaled = font.as_scaled(PxScale::from(size as f32));
    text.chars()
        .map(|c| f64::from(scaled.h_advance(font.glyph_id(c))))
        .sum()
}

/// Height of a capital letter at `size` (for centring text on a point).
pub fn cap_height(size: f64) -> f64 {
    // Hack's capitals are 0.73 em high.
    0.73 * size
}

/// How much of the pixel `[p, p + 1)` lies inside `[a, b)`.
fn overlap(p: f64, a: f64, b: f64) -> f64 {
    ((p + 1.0).min(b) - p.max(a)).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_stay_inside_and_blend() {
        let mut px = vec![0u8; 3 * 20 * 10];
        let mut c = Canvas::new(&mut px, 20, 10).expect("size");
        c.fill_rect(-5.0, -5.0, 2.0, 2.0, [1.0, 1.0, 1.0], 1.0);
        c.line(0.0, 9.5, 100.0, 9.5, 1.0, [1.0, 0.0, 0.0], 0.5);
        c.blend(100, 100, [1.0; 3], 1.0);
        assert_eq!(c.get(0, 0), [1.0; 3]);
        assert_eq!(c.get(2, 2), [0.0; 3]);
        let r = c.get(10, 9);
        assert!(r[0] > 0.45 && r[0] < 0.55 && r[1] == 0.0, "{r:?}");
        assert!(Canvas::new(&mut px, 21, 10).is_none());
    }

    #[test]
    fn text_is_drawn_where_its_width_says() {
        let (w, h) = (200u32, 40u32);
        let mut px = vec![0u8; 3 * (w * h) as usize];
        let mut c = Canvas::new(&mut px, w, h).expect("size");
        let end = c.text(10.0, 30.0, 20.0, "0.125", [1.0; 3], 1.0);
        assert!((end - 10.0 - text_width(20.0, "0.125")).abs() < 1e-3);
        let lit: Vec<u32> = (0..w)
            .filter(|&x| (0..h).any(|y| c.get(i64::from(x), i64::from(y))[0] > 0.5))
            .collect();
        let (first, last) = (lit[0], lit[lit.len() - 1]);
        assert!(
            first >= 10 && f64::from(last) <= end + 1.0,
            "{first}..{last}, end {end}"
        );
        // Nothing above the capitals or below the baseline's descent.
        assert!((0..w).all(|x| c.get(i64::from(x), 5)[0] < 0.5));
    }
}
