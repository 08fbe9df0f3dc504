//! The side panel. Every control edits a field of the window's `ViewState` (or, for
//! the few window-only settings, a field of the app), so what the panel shows is what
//! `render --state` renders.

use eframe::egui::{self, Color32, RichText};

use super::navigation;
use super::viewer::{DialogPurpose, ViewerApp};
use super::widgets;
use crate::camera::Projection;
use crate::colormap::ColorMap;
use crate::sampling::Strategy;
use crate::transfer::Mode;
use crate::view_state::MAX_SPP;

pub(crate) fn show(app: &mut ViewerApp, ui: &mut egui::Ui) {
    ui.add_space(4.0);
    files(app, ui);
    if let Some(msg) = &app.error {
        ui.label(RichText::new(msg).color(Color32::from_rgb(255, 110, 100)));
    }
    if app.sequence.is_some() {
        ui.separator();
        sequence(app, ui);
    }
    if app.doc.is_none() {
        return;
    }
    ui.separator();
    summary(app, ui);
    ui.separator();
    volume(app, ui);
    ui.separator();
    colours(app, ui);
    ui.separator();
    scene(app, ui);
    ui.separator();
    camera(app, ui);
    ui.add_space(8.0);
}

fn files(app: &mut ViewerApp, ui: &mut egui::Ui) {
    ui.horizontal_wrapped(|ui| {
        if ui.button("Open…").clicked() {
            app.open_dialog(DialogPurpose::OpenFile);
        }
        if ui.button("Save image…").clicked() {
            app.open_dialog(DialogPurpose::SavePng);
        }
        if ui.button("Save view…").clicked() {
            app.open_dialog(DialogPurpose::SaveState);
        }
        if ui.button("Load view…").clicked() {
            app.open_dialog(DialogPurpose::LoadState);
        }
    });
}

/// The frame slider and play/pause of a sequence.
fn sequence(app: &mut ViewerApp, ui: &mut egui::Ui) {
    let Some(player) = &mut app.sequence else {
        return;
    };
    let n = player.frames.len();
    ui.label(RichText::new(&player.pattern).strong());
    let numbers: Vec<u64> = player.frames.iter().map(|f| f.0).collect();
    let mut index = player.index;
    let mut changed = false;
    ui.add(
        egui::Slider::new(&mut index, 0..=n.saturating_sub(1))
            .text("frame")
            .custom_formatter(|v, _| {
                let i = (v.round().max(0.0) as usize).min(numbers.len().saturating_sub(1));
                numbers.get(i).map_or_else(String::new, u64::to_string)
            })
            .custom_parser(|s| {
                let f: u64 = s.trim().parse().ok()?;
                numbers.iter().position(|&x| x == f).map(|i| i as f64)
            }),
    );
    if index != player.index {
        changed |= player.seek(index);
    }
    ui.horizontal(|ui| {
        if ui.button("◀").on_hover_text("previous frame").clicked() {
            changed |= player.step_back();
        }
        let label = if player.playing { "Pause" } else { "Play" };
        if ui.button(label).clicked() {
            player.toggle();
        }
        if ui.button("▶").on_hover_text("next frame").clicked() {
            changed |= player.step_forward();
        }
        ui.add(
            egui::DragValue::new(&mut player.fps)
                .range(super::player::FPS_RANGE)
                .speed(0.1)
                .suffix(" fps"),
        );
    });
    ui.label(format!("{} of {n} frames", player.index + 1));
    if changed {
        app.show_frame();
    }
}

fn summary(app: &ViewerApp, ui: &mut egui::Ui) {
    let Some(doc) = &app.doc else {
        return;
    };
    let name = doc
        .path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    ui.label(RichText::new(name).strong())
        .on_hover_text(doc.path.display().to_string());
    let file = doc.dataset.view().file();
    ui.label(format!(
        "{} levels · {} leaf cells · {} bricks · {} regions",
        file.levels.len(),
        doc.cells,
        doc.bricks,
        doc.regions
    ));
    for f in &doc.fields {
        ui.label(format!("{}: {:.4} … {:.4}", f.name, f.min, f.max));
    }
}

fn volume(app: &mut ViewerApp, ui: &mut egui::Ui) {
    let Some(doc) = &app.doc else {
        return;
    };
    let names: Vec<String> = doc.fields.iter().map(|f| f.name.clone()).collect();
    let st = &mut app.state;
    ui.horizontal(|ui| {
        ui.label("Mode");
        ui.radio_value(&mut st.mode, Mode::Iso, "iso-surface");
        ui.radio_value(&mut st.mode, Mode::Dvr, "shell (dvr)");
    });
    egui::ComboBox::from_label("iso field")
        .selected_text(st.iso_field.clone())
        .show_ui(ui, |ui| {
            for n in &names {
                ui.selectable_value(&mut st.iso_field, n.clone(), n);
            }
        });
    if let Some(f) = doc.field(&st.iso_field) {
        let mut iso = st.iso;
        let mut changed = widgets::iso_histogram(ui, &f.histogram, f.min, f.max, &mut iso);
        let (lo, hi) = (f64::from(f.min), f64::from(f.max));
        changed |= ui
            .add(egui::Slider::new(&mut iso, lo.min(hi)..=hi.max(lo)).text("iso value"))
            .changed();
        if changed {
            st.set_iso(iso);
        }
    }
    egui::ComboBox::from_label("strategy")
        .selected_text(st.strategy.as_str())
        .show_ui(ui, |ui| {
            for s in Strategy::ALL {
                ui.selectable_value(&mut st.strategy, s, s.as_str());
            }
        });
    if st.effective_strategy() != st.strategy {
        let used = st.effective_strategy();
        ui.label(RichText::new(format!("dvr samples `exact` as `{used}`")).weak());
    }
    ui.add(
        egui::Slider::new(&mut st.step, 0.01..=4.0)
            .logarithmic(true)
            .text("step (cells)"),
    );
    ui.add(
        egui::Slider::new(&mut st.spp, 1..=MAX_SPP.min(256))
            .logarithmic(true)
            .text("samples / pixel"),
    );
    if st.mode == Mode::Dvr {
        let sigma_max = (st.iso.abs() * 2.0).max(st.transfer.sigma * 4.0).max(1e-6);
        ui.add(
            egui::Slider::new(&mut st.transfer.sigma, 1e-6..=sigma_max)
                .logarithmic(true)
                .text("band σ"),
        );
        ui.add(egui::Slider::new(&mut st.transfer.peak, 0.01..=4.0).text("peak opacity"));
        ui.add(egui::Slider::new(&mut st.transfer.k, 0.5..=4.0).text("band half-width (σ)"));
    }
}

fn colours(app: &mut ViewerApp, ui: &mut egui::Ui) {
    let Some(doc) = &app.doc else {
        return;
    };
    let st = &mut app.state;
    ui.label(RichText::new("Colour map").strong());
    let before = st.colormap.field.clone();
    egui::ComboBox::from_label("colour field")
        .selected_text(st.colormap.field.clone())
        .show_ui(ui, |ui| {
            for f in &doc.fields {
                ui.selectable_value(&mut st.colormap.field, f.name.clone(), &f.name);
            }
        });
    if st.colormap.field != before {
        // A new field gets a map over its own range.
        if let Some(f) = doc.field(&st.colormap.field) {
            st.colormap = ColorMap::default_for_range(&f.name, f.min, f.max);
        }
    }
    if let Some(f) = doc.field(&st.colormap.field) {
        widgets::colormap_editor(ui, &mut st.colormap, &f.histogram, f.min, f.max);
        ui.label(RichText::new("click: add · drag: move · right-click: remove").weak());
    }
    let mut remove = None;
    let n = st.colormap.points.len();
    for (i, p) in st.colormap.points.iter_mut().enumerate() {
        ui.horizontal(|ui| {
            ui.color_edit_button_rgb(&mut p.colour);
            ui.add(egui::DragValue::new(&mut p.value).speed(1e-3));
            if n > 1 && ui.small_button("x").on_hover_text("remove").clicked() {
                remove = Some(i);
            }
        });
    }
    if let Some(i) = remove {
        st.colormap.points.remove(i);
    }
    st.colormap
        .points
        .sort_by(|a, b| a.value.total_cmp(&b.value));
    if ui.button("Add point").clicked() {
        // Halve the widest gap between neighbouring points.
        let v = st
            .colormap
            .points
            .windows(2)
            .map(|w| (w[1].value - w[0].value, w[0].value))
            .fold(None, |best: Option<(f32, f32)>, g| match best {
                Some(b) if b.0 >= g.0 => Some(b),
                _ => Some(g),
            })
            .map_or_else(
                || st.colormap.points.first().map_or(0.0, |p| p.value + 1.0),
                |(gap, lo)| lo + 0.5 * gap,
            );
        widgets::add_point(&mut st.colormap, v);
    }
    ui.add(
        egui::DragValue::new(&mut st.colormap.band)
            .speed(1e-4)
            .range(0.0..=f32::MAX)
            .prefix("band ±"),
    );
}

fn scene(app: &mut ViewerApp, ui: &mut egui::Ui) {
    ui.label(RichText::new("Light and scene").strong());
    let mut follow_changed = ui
        .checkbox(&mut app.lights_follow, "lights follow the camera")
        .changed();
    ui.add_enabled_ui(app.lights_follow, |ui| {
        follow_changed |= ui
            .add(egui::Slider::new(&mut app.light_dir[0], -180.0..=180.0).text("light azimuth °"))
            .changed();
        follow_changed |= ui
            .add(egui::Slider::new(&mut app.light_dir[1], -89.0..=89.0).text("light elevation °"))
            .changed();
    });
    if follow_changed {
        app.relight();
    }
    ui.checkbox(&mut app.state.shadows, "shadows");
    ui.horizontal(|ui| {
        ui.label("background");
        ui.color_edit_button_rgb(&mut app.state.background);
    });
    ui.label("Meshes");
    let mut remove = None;
    let mut hide = None;
    for (i, m) in app.state.meshes.iter().enumerate() {
        ui.horizontal(|ui| {
            let mut on = true;
            if ui.checkbox(&mut on, m.path.display().to_string()).changed() {
                hide = Some(i);
            }
            if ui.small_button("x").on_hover_text("remove").clicked() {
                remove = Some(i);
            }
        });
    }
    let mut show = None;
    for (i, m) in app.hidden_meshes.iter().enumerate() {
        let mut on = false;
        if ui.checkbox(&mut on, m.path.display().to_string()).changed() {
            show = Some(i);
        }
    }
    if let Some(i) = remove {
        app.state.meshes.remove(i);
    } else if let Some(i) = hide {
        let m = app.state.meshes.remove(i);
        app.hidden_meshes.push(m);
    } else if let Some(i) = show {
        let m = app.hidden_meshes.remove(i);
        app.state.meshes.push(m);
    }
    ui.horizontal(|ui| {
        ui.add(
            egui::TextEdit::singleline(&mut app.mesh_spec)
                .hint_text("PATH[@x,y,z,scale]")
                .desired_width(150.0),
        );
        if ui.button("Add").clicked() {
            app.add_mesh_from_spec();
        }
        if ui.button("Browse…").clicked() {
            app.open_dialog(DialogPurpose::AddMesh);
        }
    });
}

fn camera(app: &mut ViewerApp, ui: &mut egui::Ui) {
    ui.label(RichText::new("Camera and render").strong());
    let aspect = f64::from(app.state.width) / f64::from(app.state.height.max(1));
    let mut ortho = matches!(app.state.camera.projection, Projection::Orthographic { .. });
    ui.horizontal(|ui| {
        let before = ortho;
        ui.radio_value(&mut ortho, false, "perspective");
        ui.radio_value(&mut ortho, true, "orthographic");
        if ortho != before {
            navigation::set_orthographic(&mut app.state.camera, ortho, aspect);
        }
    });
    match &mut app.state.camera.projection {
        Projection::Perspective { fov_deg } => {
            ui.add(egui::Slider::new(fov_deg, 5.0..=120.0).text("field of view °"));
        }
        Projection::Orthographic { width } => {
            ui.add(
                egui::DragValue::new(width)
                    .speed(0.01)
                    .range(1e-6..=f64::MAX)
                    .prefix("view width "),
            );
        }
    }
    ui.horizontal(|ui| {
        if ui.button("Frame data (F)").clicked() {
            app.frame_data();
            app.relight();
        }
        ui.checkbox(&mut app.pick_mode, "pick values under the cursor");
    });
    ui.add(egui::Slider::new(&mut app.resolution_scale, 0.25..=2.0).text("resolution scale"));
    ui.label(
        RichText::new(
            "drag: orbit · right/middle or shift-drag: pan · wheel: zoom · double-click: pivot",
        )
        .weak(),
    );
}
