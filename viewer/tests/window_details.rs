//! The window's menus, keys and details driven through egui_kittest: undo and redo of the
//! view, the keys-and-mouse overlay, the save dialog's proposed name, the extension a save
//! gets, the message for a VDB file, tooltips, the iso slider. (Picks cleared on Load view:
//! `app/tests.rs`, which can plant a pick.)
#![cfg(feature = "gui")]

use std::path::{Path, PathBuf};

use eframe::egui::accesskit::Role;
use eframe::egui::{Key, Modifiers, Pos2};
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use qbricks_viewer::app::ViewerApp;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data")
        .join(name)
}

fn harness() -> Harness<'static, ViewerApp> {
    let app = ViewerApp::for_tests(&data("wake_small.qbk"), Some(1)).expect("app");
    let mut h = Harness::builder()
        .with_size(eframe::egui::Vec2::new(1100.0, 900.0))
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app);
    h.run_steps(3);
    h
}

/// Whether some widget on screen shows `text` (a label's text is its accessibility
/// value, not its label).
fn shows(h: &Harness<'static, ViewerApp>, text: &str) -> bool {
    format!("{:#?}", h.root()).contains(text)
}

fn iso(h: &Harness<'static, ViewerApp>) -> f64 {
    h.state().state.iso
}

/// Drags the iso slider's handle from its middle to its right end in several moves.
fn drag_iso_slider(h: &mut Harness<'static, ViewerApp>) {
    let rect = h.get_by_role_and_label(Role::Slider, "iso value").rect();
    let y = rect.center().y;
    h.hover_at(Pos2::new(rect.center().x, y));
    h.run_steps(1);
    h.drag_at(Pos2::new(rect.center().x, y));
    h.run_steps(1);
    for i in 1..=6 {
        let x = rect.center().x + (rect.right() - 2.0 - rect.center().x) * i as f32 / 6.0;
        h.hover_at(Pos2::new(x, y));
        h.run_steps(1);
    }
    h.drop_at(Pos2::new(rect.right() - 2.0, y));
    h.run_steps(2);
    h.remove_cursor();
    h.run_steps(1);
}

#[test]
fn a_slider_drag_is_one_undo_step_and_redo_brings_it_back() {
    let mut h = harness();
    let start = iso(&h);
    drag_iso_slider(&mut h);
    let dragged = iso(&h);
    assert!(dragged > start, "the drag did not move the iso value");
    // The whole drag is one step: one undo goes back to where it started.
    h.key_press_modifiers(Modifiers::COMMAND, Key::Z);
    h.run_steps(2);
    assert_eq!(iso(&h), start);
    h.key_press_modifiers(Modifiers::COMMAND | Modifiers::SHIFT, Key::Z);
    h.run_steps(2);
    assert_eq!(iso(&h), dragged);
    // Ctrl+Y redoes too; the Edit menu undoes.
    h.key_press_modifiers(Modifiers::COMMAND, Key::Z);
    h.run_steps(2);
    assert_eq!(iso(&h), start);
    h.key_press_modifiers(Modifiers::COMMAND, Key::Y);
    h.run_steps(2);
    assert_eq!(iso(&h), dragged);
    h.get_by_label("Edit").click();
    h.run_steps(2);
    h.get_by_label_contains("Undo").click();
    h.run_steps(2);
    assert_eq!(iso(&h), start);
    // The image size follows the window, not the history.
    let size = [h.state().state.width, h.state().state.height];
    assert!(size[0] > 100 && size[1] > 100, "{size:?}");
}

#[test]
fn undo_restores_the_camera_and_the_panel_settings() {
    let mut h = harness();
    let before = h.state().state.clone();
    // A camera turned (as a drag on the image does) and one of the keys (F frames the
    // data).
    {
        let app = h.state_mut();
        qbricks_viewer::app::orbit(&mut app.state.camera, app.pivot, 0.5, 0.1);
    }
    h.run_steps(1);
    let turned = h.state().state.camera;
    h.key_press(Key::F);
    h.run_steps(2);
    assert_ne!(h.state().state.camera, turned);
    h.key_press_modifiers(Modifiers::COMMAND, Key::Z);
    h.run_steps(2);
    assert_eq!(h.state().state.camera, turned);
    h.key_press_modifiers(Modifiers::COMMAND, Key::Z);
    h.run_steps(2);
    assert_eq!(h.state().state.camera, before.camera);
    assert_eq!(h.state().state.lights, before.lights);
    // Nothing older: undo does nothing more.
    h.key_press_modifiers(Modifiers::COMMAND, Key::Z);
    h.run_steps(2);
    assert_eq!(h.state().state.camera, before.camera);
}

#[test]
fn f1_and_the_help_menu_show_every_key_and_mouse_binding() {
    let mut h = harness();
    assert!(h.query_by_label("Keys and mouse").is_none());
    h.key_press(Key::F1);
    h.run_steps(2);
    assert!(
        h.query_by_label("Keys and mouse").is_some(),
        "F1 shows no help"
    );
    for text in [
        "Ctrl+Z",
        "Ctrl+Shift+Z",
        "Ctrl+Y",
        "F",
        "Home",
        "F1",
        "?",
        "Escape",
        "undo the last view change",
        "drag",
        "orbit around the pivot",
        "wheel",
        "zoom towards the cursor",
        "double-click",
    ] {
        let shown = h.query_all_by_value(text).next().is_some();
        assert!(shown, "the help lacks {text}");
    }
    h.key_press(Key::Escape);
    h.run_steps(2);
    assert!(
        h.query_by_label("Keys and mouse").is_none(),
        "Escape keeps it"
    );
    h.get_by_label("Help").click();
    h.run_steps(2);
    h.get_by_label_contains("Keys and mouse…").click();
    h.run_steps(2);
    assert!(
        h.query_by_label("Keys and mouse").is_some(),
        "the menu shows no help"
    );
    // `?` (typed with shift) hides it again.
    h.key_press_modifiers(Modifiers::SHIFT, Key::Questionmark);
    h.run_steps(2);
    assert!(h.query_by_label("Keys and mouse").is_none(), "? keeps it");
}

#[test]
fn save_image_proposes_the_files_name_and_saves_add_their_extension() {
    let mut h = harness();
    // The panel's button (the File menu's entry asks for the same).
    h.get_by_label("Save image…").click();
    h.run_steps(3);
    let proposed = h
        .query_all_by_role(Role::TextInput)
        .any(|n| n.value().as_deref() == Some("wake_small.png"));
    assert!(proposed, "the save dialog does not propose wake_small.png");

    let dir = tempfile::tempdir().expect("tempdir");
    h.state_mut().save_state(&dir.path().join("view"));
    assert!(h.state().error.is_none(), "{:?}", h.state().error);
    assert!(dir.path().join("view.json").is_file(), "no view.json");
    assert!(!dir.path().join("view").exists());
}

#[test]
fn opening_a_vdb_file_says_how_to_bake_it() {
    let mut h = harness();
    let vdb = data("wake_small.vdb");
    h.state_mut().open_any(&vdb);
    h.run_steps(2);
    let err = h.state().error.clone().expect("a message");
    let want = format!(
        "qbricks-bake bake {} -o {}",
        vdb.display(),
        vdb.with_extension("qbk").display()
    );
    assert!(err.contains(&want), "{err}");
    assert!(
        shows(&h, "qbricks-bake bake"),
        "the message is not on screen"
    );
    // The sample stays open.
    assert!(h
        .state()
        .file()
        .is_some_and(|f| f.ends_with("wake_small.qbk")));
}

#[test]
fn strategy_step_and_band_have_tooltips() {
    let mut h = harness();
    let strategy = h.get_by_role_and_label(Role::ComboBox, "strategy").rect();
    let step = h.get_by_role_and_label(Role::Slider, "step (cells)").rect();
    let band = h
        .query_all_by_role(Role::SpinButton)
        .find(|n| n.value().is_some_and(|v| v.starts_with("band ±")))
        .expect("the band field")
        .rect();
    for (label, rect, words) in [
        ("strategy", strategy, "trilinear cubic"),
        ("step", step, "Distance between samples"),
        ("band", band, "take its colour"),
    ] {
        assert!(!shows(&h, words));
        h.hover_at(rect.center());
        h.run_steps(40);
        assert!(shows(&h, words), "no tooltip on {label}");
        h.remove_cursor();
        h.run_steps(2);
    }
}

#[test]
fn the_iso_slider_reaches_small_positive_values() {
    let mut h = harness();
    h.state_mut().state.iso = 0.0;
    h.run_steps(1);
    h.get_by_role_and_label(Role::Slider, "iso value").focus();
    h.run_steps(1);
    h.key_press(Key::ArrowRight);
    h.run_steps(1);
    // Q of the sample spans -0.92 … 0.363; a linear slider 100 points wide moves 0.013
    // (3.5 % of the top) per point, the symmetric-log one a hundred times less.
    let v = iso(&h);
    assert!(v > 0.0 && v < 1e-3, "one step right of 0 gives {v}");
}
