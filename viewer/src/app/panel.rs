//! The side panel. Every control edits the window's `ViewState`, so what the panel shows
//! is what `render --state` renders: plain settings in place, and the changes that follow
//! a rule (a new iso or colour field, an iso value, framing the data, the lights, files
//! and meshes, adding and removing surfaces and planes) as [`AppCommand`]s, which the
//! window handles in one place, with the rules the command line uses. The surfaces and
//! the planes have files of their own (`surfaces`, `cuts`).

use eframe::egui::{self, Color32, RichText};

use super::command::AppCommand;
use super::cuts;
use super::dialogs::DialogPurpose;
use super::document::Doc;
use super::navigation;
use super::player::Player;
use super::surfaces;
use super::view::ViewControls;
use super::widgets;
use crate::camera::Projection;
use crate::palette::Palette;
use crate::sampling::Strategy;
use crate::transfer::Mode;
use crate::view_state::{ViewCommand, ViewState, MAX_SPP};

/// Tooltips of the settings whose names do not say what they do.
pub(crate) const STRATEGY_TIP: &str = "How a ray samples the field. uniform: fixed steps \
    (fastest, can step over thin features); paper: ExaBricks' adaptive steps at interval \
    midpoints; bisect: adaptive steps, then bisection into the band; exact: the root of \
    each cell's trilinear cubic, no surface missed (iso mode; dvr samples it as uniform \
    or bisect).";
pub(crate) const STEP_TIP: &str = "Distance between samples along a ray, in cells of the \
    finest level there. Smaller: thin sheets are not stepped over, slower.";
pub(crate) const SIGMA_TIP: &str = "Width σ of the dvr shell's opacity, a Gaussian around \
    the iso value, in field units: wider shows more of the field around the surface.";
pub(crate) const HALF_WIDTH_TIP: &str = "Where the shell ends, in σ from the iso value: \
    beyond iso ± this·σ the field is transparent.";
pub(crate) const BAND_TIP: &str = "Values within ± this of a control point take its colour \
    flat; between the bands the colours blend (0: a smooth ramp between points).";

/// What the panel shows and edits: the view state and the window's own settings.
pub(crate) struct Panel<'a> {
    /// The message at the top (bad file, failed save, …).
    pub error: Option<&'a str>,
    pub doc: Option<&'a Doc>,
    pub player: Option<&'a mut Player>,
    pub state: &'a mut ViewState,
    pub controls: &'a mut ViewControls,
    /// Pick values under the cursor.
    pub picking: &'a mut bool,
    pub resolution_scale: &'a mut f32,
}

/// Draws the panel; what it asks the window to do, in order.
pub(crate) fn show(p: Panel<'_>, ui: &mut egui::Ui) -> Vec<AppCommand> {
    let mut out = Vec::new();
    ui.add_space(4.0);
    files(&mut out, ui);
    if let Some(msg) = p.error {
        ui.label(RichText::new(msg).color(Color32::from_rgb(255, 110, 100)));
    }
    if let Some(player) = p.player {
        ui.separator();
        sequence(player, &mut out, ui);
    }
    let Some(doc) = p.doc else {
        return out;
    };
    ui.separator();
    summary(doc, ui);
    ui.separator();
    volume(doc, p.state, p.controls, &mut out, ui);
    ui.separator();
    colours(doc, p.state, p.controls, &mut out, ui);
    ui.separator();
    overlays(p.state, ui);
    ui.separator();
    cuts::show(
        crate::overlay::data_bounds(doc.dataset.volume()),
        p.state,
        &mut out,
        ui,
    );
    ui.separator();
    scene(p.state, p.controls, &mut out, ui);
    ui.separator();
    camera(p.state, p.picking, p.resolution_scale, &mut out, ui);
    ui.add_space(8.0);
    out
}

fn files(out: &mut Vec<AppCommand>, ui: &mut egui::Ui) {
    ui.horizontal_wrapped(|ui| {
        for (label, purpose) in [
            ("Open…", DialogPurpose::OpenFile),
            ("Save image…", DialogPurpose::SavePng),
            ("Save view…", DialogPurpose::SaveState),
            ("Load view…", DialogPurpose::LoadState),
        ] {
            if ui.button(label).clicked() {
                out.push(AppCommand::Dialog(purpose));
            }
        }
    });
}

/// The frame slider and play/pause of a sequence.
fn sequence(player: &mut Player, out: &mut Vec<AppCommand>, ui: &mut egui::Ui) {
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
        out.push(AppCommand::ShowFrame);
    }
}

fn summary(doc: &Doc, ui: &mut egui::Ui) {
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

fn volume(
    doc: &Doc,
    st: &mut ViewState,
    controls: &mut ViewControls,
    out: &mut Vec<AppCommand>,
    ui: &mut egui::Ui,
) {
    ui.horizontal(|ui| {
        ui.label("Mode");
        ui.radio_value(&mut st.mode, Mode::Iso, "iso-surface");
        ui.radio_value(&mut st.mode, Mode::Dvr, "shell (dvr)");
    });
    // A new iso field starts from its own range (the window's rule is the command line's).
    if let Some(name) = field_box(ui, "iso field", doc, &st.iso_field) {
        out.push(AppCommand::View(ViewCommand::IsoField {
            name,
            keep_iso: false,
        }));
    }
    if let Some(f) = doc.field(&st.iso_field) {
        surfaces::show(f, st, controls, out, ui);
    }
    // The same warning `render` prints: an empty picture should say why.
    if let Some(w) = st.iso_outside_range(&doc.dataset.volume().fields) {
        ui.label(RichText::new(w).color(Color32::from_rgb(255, 190, 90)));
    }
    egui::ComboBox::from_label("strategy")
        .selected_text(st.strategy.as_str())
        .show_ui(ui, |ui| {
            for s in Strategy::ALL {
                ui.selectable_value(&mut st.strategy, s, s.as_str());
            }
        })
        .response
        .on_hover_text(STRATEGY_TIP);
    if st.effective_strategy() != st.strategy {
        let used = st.effective_strategy();
        ui.label(RichText::new(format!("dvr samples `exact` as `{used}`")).weak());
    }
    ui.add(
        egui::Slider::new(&mut st.step, 0.01..=4.0)
            .logarithmic(true)
            .text("step (cells)"),
    )
    .on_hover_text(STEP_TIP);
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
        )
        .on_hover_text(SIGMA_TIP);
        ui.add(egui::Slider::new(&mut st.transfer.peak_opacity, 0.01..=4.0).text("peak opacity"));
        ui.add(egui::Slider::new(&mut st.transfer.k, 0.5..=4.0).text("band half-width (σ)"))
            .on_hover_text(HALF_WIDTH_TIP);
    }
}

/// A box choosing one of the file's fields, showing `current`; the field chosen in it
/// this frame, if another.
fn field_box(ui: &mut egui::Ui, label: &str, doc: &Doc, current: &str) -> Option<String> {
    let mut chosen = current.to_string();
    egui::ComboBox::from_label(label)
        .selected_text(current)
        .show_ui(ui, |ui| {
            for f in &doc.fields {
                ui.selectable_value(&mut chosen, f.name.clone(), &f.name);
            }
        });
    (chosen != current).then_some(chosen)
}

fn colours(
    doc: &Doc,
    st: &mut ViewState,
    controls: &mut ViewControls,
    out: &mut Vec<AppCommand>,
    ui: &mut egui::Ui,
) {
    ui.label(RichText::new("Colour map").strong());
    // A new field gets a map over its own range.
    if let Some(name) = field_box(ui, "colour field", doc, &st.colormap.field) {
        out.push(AppCommand::View(ViewCommand::ColourField { name }));
    }
    // A preset rebuilds the map over its current range, as `--colormap` does.
    let before = (controls.palette, controls.log);
    ui.horizontal(|ui| {
        egui::ComboBox::from_id_salt("palette")
            .selected_text(controls.palette.palette.name())
            .show_ui(ui, |ui| {
                for p in Palette::ALL {
                    ui.selectable_value(&mut controls.palette.palette, p, p.name());
                }
            });
        ui.checkbox(&mut controls.palette.reversed, "reverse");
        ui.checkbox(&mut controls.log, "log")
            .on_hover_text("colours spaced evenly in log10 of the value (positive ranges)");
    });
    if (controls.palette, controls.log) != before {
        out.push(AppCommand::View(ViewCommand::ColourScale {
            palette: controls.palette,
            range: None,
            centre: None,
            log: controls.log,
        }));
    }
    if ui
        .button("Fit to visible")
        .on_hover_text("spread the map over the colour field's values on the surfaces shown")
        .clicked()
    {
        out.push(AppCommand::FitColoursToVisible);
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
    )
    .on_hover_text(BAND_TIP);
}

/// What the picture carries besides the data (the view state's `overlays`).
fn overlays(st: &mut ViewState, ui: &mut egui::Ui) {
    ui.label(RichText::new("Overlays").strong());
    let o = &mut st.overlays;
    ui.horizontal_wrapped(|ui| {
        ui.checkbox(&mut o.legend, "legend");
        ui.checkbox(&mut o.axes, "axes");
        ui.checkbox(&mut o.outline, "box");
        ui.checkbox(&mut o.scale, "scale bar");
    });
}

fn scene(
    st: &mut ViewState,
    controls: &mut ViewControls,
    out: &mut Vec<AppCommand>,
    ui: &mut egui::Ui,
) {
    ui.label(RichText::new("Light and scene").strong());
    let mut follow_changed = ui
        .checkbox(&mut controls.lights_follow, "lights follow the camera")
        .changed();
    let dir = &mut controls.light_dir;
    ui.add_enabled_ui(controls.lights_follow, |ui| {
        follow_changed |= ui
            .add(egui::Slider::new(&mut dir[0], -180.0..=180.0).text("light azimuth °"))
            .changed();
        follow_changed |= ui
            .add(egui::Slider::new(&mut dir[1], -89.0..=89.0).text("light elevation °"))
            .changed();
    });
    if follow_changed {
        out.push(AppCommand::Relight);
    }
    ui.checkbox(&mut st.shadows, "shadows");
    ui.horizontal(|ui| {
        ui.label("background");
        ui.color_edit_button_rgb(&mut st.background);
    });
    ui.label("Meshes");
    let mut remove = None;
    let mut hide = None;
    for (i, m) in st.meshes.iter().enumerate() {
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
    for (i, m) in controls.hidden_meshes.iter().enumerate() {
        let mut on = false;
        if ui.checkbox(&mut on, m.path.display().to_string()).changed() {
            show = Some(i);
        }
    }
    if let Some(i) = remove {
        out.push(AppCommand::RemoveMesh(i));
    } else if let Some(i) = hide {
        out.push(AppCommand::HideMesh(i));
    } else if let Some(i) = show {
        out.push(AppCommand::ShowMesh(i));
    }
    ui.horizontal(|ui| {
        ui.add(
            egui::TextEdit::singleline(&mut controls.mesh_spec)
                .hint_text("PATH[@x,y,z,scale]")
                .desired_width(150.0),
        );
        if ui.button("Add").clicked() {
            out.push(AppCommand::AddMesh);
        }
        if ui.button("Browse…").clicked() {
            out.push(AppCommand::Dialog(DialogPurpose::AddMesh));
        }
    });
}

fn camera(
    st: &mut ViewState,
    picking: &mut bool,
    resolution_scale: &mut f32,
    out: &mut Vec<AppCommand>,
    ui: &mut egui::Ui,
) {
    ui.label(RichText::new("Camera and render").strong());
    let aspect = f64::from(st.width) / f64::from(st.height.max(1));
    let mut ortho = matches!(st.camera.projection, Projection::Orthographic { .. });
    ui.horizontal(|ui| {
        let before = ortho;
        ui.radio_value(&mut ortho, false, "perspective");
        ui.radio_value(&mut ortho, true, "orthographic");
        if ortho != before {
            navigation::set_orthographic(&mut st.camera, ortho, aspect);
        }
    });
    match &mut st.camera.projection {
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
        if ui
            .button("Frame surface (F)")
            .on_hover_text("fill the picture with the iso surface")
            .clicked()
        {
            out.push(AppCommand::FrameSurface);
        }
        if ui
            .button("Frame all data (Home)")
            .on_hover_text("show the whole data set")
            .clicked()
        {
            out.push(AppCommand::FrameData);
        }
    });
    ui.checkbox(picking, "pick values under the cursor");
    ui.add(egui::Slider::new(resolution_scale, 0.25..=2.0).text("resolution scale"));
    ui.label(RichText::new(super::keys::mouse_hint()).weak());
}
