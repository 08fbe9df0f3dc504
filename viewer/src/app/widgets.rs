//! Panel widgets for values of a field: the iso value picker over the field's histogram,
//! the iso value slider, and the colour-map editor over its histogram. Counts are drawn
//! on a log scale (a few cells near the extremes would vanish on a linear one).

use eframe::egui::{self, Color32, Pos2, Rect, Sense, Stroke, Vec2};

use crate::colormap::{ColorMap, ControlPoint};

const HEIGHT: f32 = 64.0;

/// The low end of the opacity sliders (surfaces, slices): at 1 % a surface is all but
/// invisible, and an opacity of 0 is none (the view state refuses it).
pub(crate) const MIN_OPACITY: f64 = 0.01;

fn to_color32(c: [f32; 3]) -> Color32 {
    let [r, g, b] = c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
    Color32::from_rgb(r, g, b)
}

/// Value at horizontal position `x` of `rect` for the range `lo..=hi`.
fn value_at(rect: Rect, x: f32, lo: f32, hi: f32) -> f32 {
    let u = ((x - rect.left()) / rect.width()).clamp(0.0, 1.0);
    lo + u * (hi - lo)
}

fn x_of(rect: Rect, v: f32, lo: f32, hi: f32) -> f32 {
    let span = hi - lo;
    let u = if span > 0.0 { (v - lo) / span } else { 0.5 };
    rect.left() + u.clamp(0.0, 1.0) * rect.width()
}

/// Log-scale histogram bars, grey, in `rect`.
fn bars(painter: &egui::Painter, rect: Rect, histogram: &[u64]) {
    let top = histogram.iter().copied().max().unwrap_or(0);
    if top == 0 || histogram.is_empty() {
        return;
    }
    let log_top = (top as f32 + 1.0).ln();
    let bw = rect.width() / histogram.len() as f32;
    for (i, &c) in histogram.iter().enumerate() {
        if c == 0 {
            continue;
        }
        let h = rect.height() * (c as f32 + 1.0).ln() / log_top;
        let x0 = rect.left() + i as f32 * bw;
        painter.rect_filled(
            Rect::from_min_max(
                Pos2::new(x0, rect.bottom() - h),
                Pos2::new(x0 + bw, rect.bottom()),
            ),
            0.0,
            Color32::from_gray(95),
        );
    }
}

/// Histogram of the iso field with the iso value marked (and the other surfaces' values
/// `others`, fainter); a click or drag sets the value. Returns whether the value changed.
pub(crate) fn iso_histogram(
    ui: &mut egui::Ui,
    histogram: &[u64],
    lo: f32,
    hi: f32,
    iso: &mut f64,
    others: &[f64],
) -> bool {
    let width = ui.available_width().max(60.0);
    let (rect, response) =
        ui.allocate_exact_size(Vec2::new(width, HEIGHT), Sense::click_and_drag());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, Color32::from_gray(30));
    bars(&painter, rect, histogram);
    for &v in others {
        let x = x_of(rect, v as f32, lo, hi);
        painter.line_segment(
            [Pos2::new(x, rect.top()), Pos2::new(x, rect.bottom())],
            Stroke::new(1.0, Color32::from_rgba_unmultiplied(255, 200, 60, 140)),
        );
    }
    let x = x_of(rect, *iso as f32, lo, hi);
    painter.line_segment(
        [Pos2::new(x, rect.top()), Pos2::new(x, rect.bottom())],
        Stroke::new(2.0, Color32::from_rgb(255, 200, 60)),
    );
    let mut changed = false;
    if response.clicked() || response.dragged() {
        if let Some(p) = response.interact_pointer_pos() {
            *iso = f64::from(value_at(rect, p.x, lo, hi));
            changed = true;
        }
    }
    changed
}

/// A slider of an iso value over the field's range `lo..=hi`. Q spans decades: on a linear
/// slider the small positive values that show the vortex cores' edges sit within a pixel
/// of zero. With `log` the slider is symmetric-log: each decade down to 1e-4 of the range
/// gets the same room, on both sides of zero.
pub(crate) fn iso_slider(value: &mut f64, lo: f32, hi: f32, log: bool) -> egui::Slider<'_> {
    let (lo, hi) = (f64::from(lo), f64::from(hi));
    let slider = egui::Slider::new(value, lo.min(hi)..=hi.max(lo));
    if log {
        let smallest = 1e-4 * lo.abs().max(hi.abs());
        slider
            .logarithmic(true)
            .smallest_positive(if smallest > 0.0 { smallest } else { 1e-6 })
    } else {
        slider
    }
}

/// The colour map as a bar over the colour field's histogram. Click on the bar to add a
/// control point, drag a handle to move it, right-click a handle to remove it. Returns
/// whether the map changed.
pub(crate) fn colormap_editor(
    ui: &mut egui::Ui,
    map: &mut ColorMap,
    histogram: &[u64],
    lo: f32,
    hi: f32,
) -> bool {
    let width = ui.available_width().max(60.0);
    let (rect, response) = ui.allocate_exact_size(Vec2::new(width, HEIGHT), Sense::click());
    let painter = ui.painter_at(rect);
    let bar = Rect::from_min_max(Pos2::new(rect.left(), rect.bottom() - 14.0), rect.max);
    let hist_rect = Rect::from_min_max(rect.min, Pos2::new(rect.right(), bar.top() - 2.0));
    painter.rect_filled(hist_rect, 2.0, Color32::from_gray(30));
    bars(&painter, hist_rect, histogram);
    // The map itself, sampled per pixel column.
    let cols = bar.width().max(1.0) as usize;
    for i in 0..cols {
        let x = bar.left() + i as f32;
        let v = value_at(bar, x + 0.5, lo, hi);
        painter.rect_filled(
            Rect::from_min_max(Pos2::new(x, bar.top()), Pos2::new(x + 1.0, bar.bottom())),
            0.0,
            to_color32(map.colour(v)),
        );
    }
    let mut changed = false;
    let mut remove = None;
    let mut moved = None;
    for (i, p) in map.points.iter().enumerate() {
        let x = x_of(bar, p.value, lo, hi);
        let handle = Rect::from_center_size(Pos2::new(x, bar.center().y), Vec2::new(8.0, 18.0));
        let id = response.id.with(("point", i));
        let r = ui.interact(handle, id, Sense::click_and_drag());
        painter.rect_filled(handle, 2.0, to_color32(p.colour));
        painter.rect_stroke(
            handle,
            2.0,
            Stroke::new(
                1.5,
                if r.hovered() {
                    Color32::WHITE
                } else {
                    Color32::BLACK
                },
            ),
            egui::StrokeKind::Outside,
        );
        if r.secondary_clicked() && map.points.len() > 1 {
            remove = Some(i);
        }
        if r.dragged() {
            if let Some(pos) = r.interact_pointer_pos() {
                moved = Some((i, value_at(bar, pos.x, lo, hi)));
            }
        }
    }
    if let Some(i) = remove {
        map.points.remove(i);
        changed = true;
    } else if let Some((i, v)) = moved {
        map.points[i].value = v;
        map.points.sort_by(|a, b| a.value.total_cmp(&b.value));
        changed = true;
    } else if response.clicked() {
        if let Some(p) = response.interact_pointer_pos() {
            let v = value_at(bar, p.x, lo, hi);
            add_point(map, v);
            changed = true;
        }
    }
    changed
}

/// Adds a control point at `v` with the colour the map has there, keeping points sorted.
pub(crate) fn add_point(map: &mut ColorMap, v: f32) {
    let colour = map.colour(v);
    let at = map.points.partition_point(|p| p.value <= v);
    map.points.insert(at, ControlPoint { value: v, colour });
}
