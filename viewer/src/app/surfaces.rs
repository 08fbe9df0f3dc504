//! The panel's iso-surfaces: the iso field's histogram with every surface's value marked,
//! and per surface its value (the symmetric-log slider), opacity and colour (the colour
//! map's or a fixed one), a button that removes it, and one that adds a surface. The first
//! surface's value goes through the rule the command line's `--iso` follows (the dvr
//! band's width follows it); the rest are plain settings, edited in place.

use eframe::egui::{self, RichText};

use super::command::AppCommand;
use super::document::FieldSummary;
use super::view::ViewControls;
use super::widgets::{self, MIN_OPACITY};
use crate::transfer::Mode;
use crate::view_state::{ViewCommand, ViewState, MAX_ISO_SURFACES};

pub(crate) const OPACITY_TIP: &str = "1 hides what lies behind the surface; less shows the \
    surfaces inside it.";
pub(crate) const COLOUR_TIP: &str = "Off: the surface takes the colour map's colours. On: one \
    colour of its own (the button beside it).";
pub(crate) const VALUE_TIP: &str = "Where the surface lies: the iso field's value on it (the \
    first surface's is also the middle of the dvr band).";
pub(crate) const ADD_TIP: &str = "Another surface of the iso field at half the last one's \
    value, translucent, so it shows as a shell around the ones inside it.";

/// The slider labels of surface `i` (0: the first, which keeps the names it always had).
pub(crate) fn value_label(i: usize) -> String {
    if i == 0 {
        "iso value".to_string()
    } else {
        format!("iso value {}", i + 1)
    }
}

pub(crate) fn opacity_label(i: usize) -> String {
    if i == 0 {
        "opacity".to_string()
    } else {
        format!("opacity {}", i + 1)
    }
}

/// Draws the surfaces of `st` (of field `f`); what the window is asked to do goes to `out`.
pub(crate) fn show(
    f: &FieldSummary,
    st: &mut ViewState,
    controls: &mut ViewControls,
    out: &mut Vec<AppCommand>,
    ui: &mut egui::Ui,
) {
    // Dvr draws the band around the first value only.
    let iso_mode = st.mode == Mode::Iso;
    let others: Vec<f64> = if iso_mode {
        st.more_isos.iter().map(|s| s.value).collect()
    } else {
        Vec::new()
    };
    let mut iso = st.iso;
    let mut changed = widgets::iso_histogram(ui, &f.histogram, f.min, f.max, &mut iso, &others);
    let n = if iso_mode { 1 + st.more_isos.len() } else { 1 };
    let mut remove = None;
    for i in 0..n {
        if i > 0 {
            ui.add_space(2.0);
        }
        ui.horizontal(|ui| {
            if i == 0 {
                let slider = widgets::iso_slider(&mut iso, f.min, f.max, controls.iso_log);
                changed |= ui
                    .add(slider.text(value_label(0)))
                    .on_hover_text(VALUE_TIP)
                    .changed();
            } else {
                let v = &mut st.more_isos[i - 1].value;
                let slider = widgets::iso_slider(v, f.min, f.max, controls.iso_log);
                ui.add(slider.text(value_label(i))).on_hover_text(VALUE_TIP);
            }
            if n > 1
                && ui
                    .small_button("remove")
                    .on_hover_text(format!("remove surface {}", i + 1))
                    .clicked()
            {
                remove = Some(i);
            }
        });
        if iso_mode {
            style_row(st, i, ui);
        }
    }
    ui.horizontal(|ui| {
        ui.checkbox(&mut controls.iso_log, "log scale")
            .on_hover_text(
                "iso sliders in decades on both sides of zero, so small values are in reach",
            );
        if iso_mode {
            let room = n < MAX_ISO_SURFACES;
            let add = ui
                .add_enabled(room, egui::Button::new("Add surface"))
                .on_hover_text(ADD_TIP)
                .on_disabled_hover_text(format!("at most {MAX_ISO_SURFACES} surfaces"));
            if add.clicked() {
                out.push(AppCommand::AddSurface);
            }
        }
    });
    if !iso_mode && !st.more_isos.is_empty() {
        ui.label(
            RichText::new("dvr shows the band around the first value; iso mode draws the others")
                .weak(),
        );
    }
    if changed {
        // The dvr band follows the iso value, as for a new view on the command line.
        out.push(AppCommand::View(ViewCommand::Iso {
            value: iso,
            band_follows: true,
        }));
    }
    if let Some(i) = remove {
        out.push(AppCommand::RemoveSurface(i));
    }
}

/// Opacity and colour of surface `i`.
fn style_row(st: &mut ViewState, i: usize, ui: &mut egui::Ui) {
    // A colour of its own starts from the middle of the colour map.
    let (lo, hi) = st.colormap.range();
    let start = st.colormap.colour(0.5 * (lo + hi));
    let (opacity, colour) = if i == 0 {
        (&mut st.iso_opacity, &mut st.iso_colour)
    } else {
        let s = &mut st.more_isos[i - 1];
        (&mut s.opacity, &mut s.colour)
    };
    ui.horizontal(|ui| {
        ui.add(egui::Slider::new(opacity, MIN_OPACITY..=1.0).text(opacity_label(i)))
            .on_hover_text(OPACITY_TIP);
        let mut fixed = colour.is_some();
        if ui
            .checkbox(&mut fixed, "colour")
            .on_hover_text(COLOUR_TIP)
            .changed()
        {
            *colour = fixed.then_some(start);
        }
        if let Some(c) = colour {
            // Through a copy: drawing the button rounds the colour through egui's type,
            // which must not count as a change.
            let mut picked = *c;
            if ui.color_edit_button_rgb(&mut picked).changed() {
                *c = picked;
            }
        }
    });
}
