//! The colour legend: the colour map's bar with round-numbered ticks, the colour field's
//! name above it and the iso values marked.

use super::canvas::{cap_height, text_width, Canvas};
use super::ticks::{format_tick, format_value, nice_ticks};
use super::{LegendInfo, Style};

pub(super) fn draw(c: &mut Canvas, s: &Style, info: &LegendInfo) {
    let map = info.colormap;
    let (Some(first), Some(last)) = (map.points.first(), map.points.last()) else {
        return;
    };
    let (lo, hi) = (f64::from(first.value), f64::from(last.value));
    if !(lo.is_finite() && hi.is_finite()) {
        return;
    }
    let ticks = nice_ticks(lo, hi);
    let step = match ticks.as_slice() {
        [a, b, ..] => b - a,
        _ => (hi - lo).abs().max(lo.abs() * 1e-3),
    };
    let labels: Vec<String> = ticks.iter().map(|&t| format_tick(t, step)).collect();
    let font = s.font;
    let gap = 0.45 * font;
    let label_w = labels
        .iter()
        .map(|l| text_width(font, l))
        .fold(0.0, f64::max);
    // The iso values: on the bar when they are values of the colour field, else a line
    // of text under it.
    let on_bar = info.iso_field == map.field;
    let marks: Vec<f64> = info
        .isos
        .iter()
        .copied()
        .filter(|v| v.is_finite() && (!on_bar || (*v >= lo.min(hi) && *v <= hi.max(lo))))
        .collect();
    let mark_w = if on_bar && !marks.is_empty() {
        text_width(font * 0.85, "iso") + gap
    } else {
        0.0
    };
    let iso_line = (!on_bar && !marks.is_empty()).then(|| {
        let values: Vec<String> = marks.iter().map(|&v| format_value(v)).collect();
        format!("iso {} = {}", info.iso_field, values.join(", "))
    });
    let title = map.field.as_str();
    let bar_w = 0.9 * font;
    let block_w = (mark_w + bar_w + gap + label_w)
        .max(text_width(font, title))
        .max(
            iso_line
                .as_ref()
                .map_or(0.0, |l| text_width(font * 0.85, l)),
        );
    let (w, h) = (f64::from(c.width), f64::from(c.height));
    let x0 = w - s.margin - block_w;
    let bar_x0 = x0 + mark_w;
    let bar_x1 = bar_x0 + bar_w;
    let bar_h = (0.42 * h).max(4.0 * font).min(h - 6.0 * font);
    let bar_y0 = 0.5 * (h - bar_h);
    let bar_y1 = bar_y0 + bar_h;
    // A panel behind the legend, so it reads on any picture.
    let pad = 0.5 * font;
    let title_y = bar_y0 - 0.6 * font;
    let panel_top = title_y - cap_height(font) - pad;
    let panel_bottom =
        bar_y1 + 0.5 * font + pad + if iso_line.is_some() { 1.3 * font } else { 0.0 };
    c.fill_rect(
        x0 - pad,
        panel_top,
        x0 + block_w + pad,
        panel_bottom,
        s.paper,
        0.75,
    );
    c.text(x0, title_y, font, title, s.ink, 1.0);

    // The bar: each row the map's colour at its value (top: the largest).
    let value_at = |y: f64| hi - (y - bar_y0) / bar_h * (hi - lo);
    let rows = bar_h.ceil() as i64;
    for r in 0..rows {
        let ya = bar_y0 + r as f64;
        let yb = (ya + 1.0).min(bar_y1);
        let colour = map.colour(value_at(0.5 * (ya + yb)) as f32);
        c.fill_rect(bar_x0, ya, bar_x1, yb, colour, 1.0);
    }
    let frame = 0.08 * font;
    for (xa, ya, xb, yb) in [
        (bar_x0, bar_y0, bar_x1, bar_y0),
        (bar_x0, bar_y1, bar_x1, bar_y1),
        (bar_x0, bar_y0, bar_x0, bar_y1),
        (bar_x1, bar_y0, bar_x1, bar_y1),
    ] {
        c.line(xa, ya, xb, yb, frame, s.ink, 0.8);
    }

    // Ticks and their numbers.
    let y_of = |v: f64| {
        if hi > lo {
            bar_y1 - (v - lo) / (hi - lo) * bar_h
        } else {
            0.5 * (bar_y0 + bar_y1)
        }
    };
    for (t, label) in ticks.iter().zip(&labels) {
        let y = y_of(*t);
        c.line(bar_x1, y, bar_x1 + 0.3 * font, y, frame, s.ink, 1.0);
        c.text(
            bar_x1 + gap,
            y + 0.5 * cap_height(font),
            font,
            label,
            s.ink,
            1.0,
        );
    }

    // Iso values.
    if on_bar {
        for v in &marks {
            let y = y_of(*v);
            c.line(
                bar_x0 - 0.2 * font,
                y,
                bar_x1 + 0.2 * font,
                y,
                0.18 * font,
                s.paper,
                1.0,
            );
            c.line(
                bar_x0 - 0.2 * font,
                y,
                bar_x1 + 0.2 * font,
                y,
                0.08 * font,
                s.ink,
                1.0,
            );
            let small = 0.85 * font;
            c.text(
                bar_x0 - gap - text_width(small, "iso"),
                y + 0.5 * cap_height(small),
                small,
                "iso",
                s.ink,
                1.0,
            );
        }
    } else if let Some(line) = &iso_line {
        c.text(x0, bar_y1 + 1.6 * font, 0.85 * font, line, s.ink, 1.0);
    }
}
