//! The panel's clip planes and slices: per plane its axis (x, y, z, or the normal it has),
//! a slider that moves it along its normal over the data's extent that way, flip (clip
//! planes: keep the other side) and remove; slices also their opacity, contour lines and
//! whether they clip what lies in front of them. Adding one asks the window (it goes
//! through the pivot); the rest are plain settings, edited in place. The limits are the
//! library's ([`MAX_CLIP_PLANES`], [`MAX_SLICES`]).

use eframe::egui::{self, RichText};

use super::command::{AppCommand, Cut};
use super::widgets::MIN_OPACITY;
use crate::planes::{Plane, MAX_CLIP_PLANES, MAX_SLICES};
use crate::view_state::ViewState;

pub(crate) const ADD_CLIP_TIP: &str = "A clip plane through the pivot, across the axis the \
    view looks along most; it keeps the far side, so the data opens up towards you.";
pub(crate) const ADD_SLICE_TIP: &str = "A slice through the pivot, across the axis the view \
    looks along most, coloured by the colour field.";
const OFFSET_TIP: &str = "Move the plane along its normal, across the data's extent that way.";
const FLIP_TIP: &str = "Keep the other side of the plane (its normal turned round).";
const CONTOURS_TIP: &str = "Draw the iso values' contour lines on the slice.";
const CLIP_IN_FRONT_TIP: &str = "Also remove what lies between the camera and the slice.";
const SLICE_OPACITY_TIP: &str = "1 hides what lies behind the slice; less lets it show through.";

/// The names of plane `i` of a kind, as the panel labels its controls.
pub(crate) fn name(cut: Cut, i: usize) -> String {
    match cut {
        Cut::Clip => format!("clip {}", i + 1),
        Cut::Slice => format!("slice {}", i + 1),
    }
}

/// Draws the clip planes and slices of `st` over the data's box `bounds` (world).
pub(crate) fn show(
    bounds: ([f64; 3], [f64; 3]),
    st: &mut ViewState,
    out: &mut Vec<AppCommand>,
    ui: &mut egui::Ui,
) {
    ui.horizontal(|ui| {
        ui.label(RichText::new("Clip planes").strong());
        ui.label(RichText::new("keep the side the normal points to").weak());
    });
    let mut remove = None;
    for (i, plane) in st.clip.iter_mut().enumerate() {
        if controls(ui, &name(Cut::Clip, i), plane, bounds, true) {
            remove = Some(i);
        }
    }
    if let Some(i) = remove {
        out.push(AppCommand::RemovePlane(Cut::Clip, i));
    }
    if add_button(
        ui,
        "Add clip plane",
        st.clip.len(),
        MAX_CLIP_PLANES,
        ADD_CLIP_TIP,
    ) {
        out.push(AppCommand::AddPlane(Cut::Clip));
    }

    ui.separator();
    ui.label(RichText::new("Slices").strong());
    let mut remove = None;
    for (i, slice) in st.slices.iter_mut().enumerate() {
        let name = name(Cut::Slice, i);
        if controls(ui, &name, &mut slice.plane, bounds, false) {
            remove = Some(i);
        }
        ui.add(
            egui::Slider::new(&mut slice.opacity, MIN_OPACITY..=1.0)
                .text(format!("{name} opacity")),
        )
        .on_hover_text(SLICE_OPACITY_TIP);
        ui.horizontal(|ui| {
            ui.checkbox(&mut slice.contours, "contours")
                .on_hover_text(CONTOURS_TIP);
            ui.checkbox(&mut slice.clip, "clip in front")
                .on_hover_text(CLIP_IN_FRONT_TIP);
        });
    }
    if let Some(i) = remove {
        out.push(AppCommand::RemovePlane(Cut::Slice, i));
    }
    if add_button(ui, "Add slice", st.slices.len(), MAX_SLICES, ADD_SLICE_TIP) {
        out.push(AppCommand::AddPlane(Cut::Slice));
    }
}

/// An add button, enabled while there are fewer than `max`; whether it was clicked.
fn add_button(ui: &mut egui::Ui, label: &str, n: usize, max: usize, tip: &str) -> bool {
    ui.add_enabled(n < max, egui::Button::new(label))
        .on_hover_text(tip)
        .on_disabled_hover_text(format!("at most {max}"))
        .clicked()
}

/// The controls of one plane called `name`; whether its remove button was clicked.
fn controls(
    ui: &mut egui::Ui,
    name: &str,
    plane: &mut Plane,
    (lo, hi): ([f64; 3], [f64; 3]),
    flip: bool,
) -> bool {
    let mut remove = false;
    ui.horizontal(|ui| {
        ui.label(name);
        let axis = plane.axis();
        for (a, label) in ["x", "y", "z"].into_iter().enumerate() {
            let r = ui
                .selectable_label(axis == Some(a), label)
                .on_hover_text(format!("across the {label} axis, through the same point"));
            if r.clicked() && axis != Some(a) {
                *plane = plane.across_axis(a);
            }
        }
        if flip && ui.small_button("flip").on_hover_text(FLIP_TIP).clicked() {
            *plane = plane.flipped();
        }
        remove = ui
            .small_button("remove")
            .on_hover_text(format!("remove {name}"))
            .clicked();
    });
    // A plane that fails the check is refused with the view state; nothing to move.
    if plane.check().is_err() {
        return remove;
    }
    if plane.axis().is_none() {
        let [x, y, z] = plane.unit_normal();
        ui.label(
            RichText::new(format!(
                "normal {x:.3}, {y:.3}, {z:.3} (x, y, z replace it)"
            ))
            .weak(),
        );
    }
    let (a, b) = plane.offset_range(lo, hi);
    let mut at = plane.offset();
    let range = a.min(at)..=b.max(at);
    let slider = egui::Slider::new(&mut at, range).text(format!("{name} offset"));
    if ui.add(slider).on_hover_text(OFFSET_TIP).changed() {
        *plane = plane.with_offset(at);
    }
    remove
}
