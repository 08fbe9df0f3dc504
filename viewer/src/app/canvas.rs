//! The central image: the picture, and the mouse navigation and picking on it.

use eframe::egui::{self, Color32, Sense};
use glam::DVec3;

use super::document::Doc;
use super::frames::Shown;
use super::navigation;
use super::picking::Picking;
use crate::mesh::Meshes;
use crate::view_state::{ViewState, MAX_IMAGE_SIDE};

/// What the central image shows and moves.
pub(crate) struct Canvas<'a> {
    pub state: &'a mut ViewState,
    pub pivot: &'a mut [f64; 3],
    /// Image size in pixels the central area asks for.
    pub viewport_px: &'a mut [u32; 2],
    pub resolution_scale: f32,
    pub shown: Option<&'a Shown>,
    pub doc: Option<&'a Doc>,
    pub meshes: &'a Meshes,
    pub picking: &'a mut Picking,
}

/// Draws the image and applies the mouse to the camera; whether the camera moved (the
/// caller puts the lights back).
pub(crate) fn show(c: Canvas<'_>, ui: &mut egui::Ui) -> bool {
    let Canvas {
        state,
        pivot,
        viewport_px,
        resolution_scale,
        shown,
        doc,
        meshes,
        picking,
    } = c;
    let rect = ui.available_rect_before_wrap();
    let ppp = ui.ctx().pixels_per_point();
    let want = [rect.width(), rect.height()]
        .map(|s| ((s * ppp * resolution_scale).round() as u32).clamp(1, MAX_IMAGE_SIDE));
    if want != *viewport_px || [state.width, state.height] != want {
        *viewport_px = want;
        state.width = want[0];
        state.height = want[1];
    }
    let response = ui.allocate_rect(rect, Sense::click_and_drag());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 0.0, Color32::from_rgb(20, 22, 26));
    if let Some(s) = shown {
        painter.image(
            s.texture.id(),
            rect,
            egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
            Color32::WHITE,
        );
    } else if doc.is_none() {
        painter.text(
            rect.center(),
            egui::Align2::CENTER_CENTER,
            format!(
                "Open a .qbk file (File > {}, or drop it here)",
                super::menu::OPEN
            ),
            egui::FontId::proportional(18.0),
            Color32::LIGHT_GRAY,
        );
    }
    let (w, h) = (f64::from(state.width), f64::from(state.height));
    let to_px = |p: egui::Pos2| -> (f64, f64) {
        let u = (p - rect.min) / rect.size();
        (f64::from(u.x) * w, f64::from(u.y) * h)
    };
    let px_per_point = w / f64::from(rect.width().max(1.0));
    let shift = ui.input(|i| i.modifiers.shift);
    let mut moved = false;
    if response.dragged_by(egui::PointerButton::Primary) && !shift {
        let d = response.drag_delta();
        navigation::orbit(
            &mut state.camera,
            *pivot,
            -f64::from(d.x) * navigation::ORBIT_PER_PIXEL,
            f64::from(d.y) * navigation::ORBIT_PER_PIXEL,
        );
        moved = true;
    } else if response.dragged_by(egui::PointerButton::Secondary)
        || response.dragged_by(egui::PointerButton::Middle)
        || (response.dragged_by(egui::PointerButton::Primary) && shift)
    {
        let d = response.drag_delta();
        *pivot = navigation::pan(
            &mut state.camera,
            *pivot,
            f64::from(d.x) * px_per_point,
            f64::from(d.y) * px_per_point,
            w,
            h,
        );
        moved = true;
    }
    if response.hovered() {
        let scroll = ui.input(|i| i.smooth_scroll_delta.y);
        if scroll != 0.0 {
            let at = response
                .hover_pos()
                .map(to_px)
                .unwrap_or((0.5 * w, 0.5 * h));
            navigation::zoom(
                &mut state.camera,
                *pivot,
                (-f64::from(scroll) * 0.002).exp(),
                at.0,
                at.1,
                state.width,
                state.height,
            );
            moved = true;
        }
    }
    let pick = |picking: &mut Picking, state: &ViewState, (x, y): (f64, f64)| {
        let doc = doc?;
        picking.pick_at(&doc.dataset, state, meshes, x, y)
    };
    if response.double_clicked() {
        if let Some(p) = response.interact_pointer_pos() {
            if let Some(hit) = pick(picking, state, to_px(p)) {
                *pivot = hit.world;
                picking.pick = Some(hit);
            }
        }
    }
    if picking.on {
        if let Some(p) = response.hover_pos() {
            if ui.input(|i| i.pointer.delta() != egui::Vec2::ZERO) || picking.pick.is_none() {
                picking.pick = pick(picking, state, to_px(p));
            }
        }
    }
    // Mark the pivot while navigating.
    if response.dragged() {
        let rays = state.camera.basis();
        let eye = DVec3::from_array(state.camera.eye);
        if (DVec3::from_array(*pivot) - eye).dot(rays.forward) > 0.0 {
            painter.circle_stroke(rect.center(), 3.0, (1.0, Color32::from_white_alpha(120)));
        }
    }
    moved
}
