//! The window's figure controls driven through egui_kittest: F frames the iso surface and
//! Home (or its button) the whole data, a checkbox per overlay, the colour-map preset's
//! reverse and log, and the warning for an iso value outside its field's range.
#![cfg(feature = "gui")]

use std::path::Path;

use eframe::egui::Key;
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use qbricks_viewer::app::ViewerApp;
use qbricks_viewer::overlay::Overlays;

fn harness() -> Harness<'static, ViewerApp> {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/wake_small.qbk");
    let app = ViewerApp::for_tests(&file, Some(1)).expect("app");
    let mut h = Harness::builder()
        .with_size(eframe::egui::Vec2::new(1100.0, 1400.0))
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app);
    h.run_steps(3);
    h
}

/// Turns the camera away from its framing (as a drag on the picture does).
fn turn(h: &mut Harness<'static, ViewerApp>) {
    let app = h.state_mut();
    qbricks_viewer::app::orbit(&mut app.state.camera, app.pivot, 0.7, 0.2);
    h.run_steps(1);
}

#[test]
fn f_frames_the_surface_and_home_the_whole_data() {
    let mut h = harness();
    turn(&mut h);
    h.key_press(Key::F);
    h.run_steps(2);
    let surface = h.state().state.camera;
    // The same camera the library frames a view's surface with, for this image size.
    let dataset = qbricks_viewer::dataset::Dataset::open(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/wake_small.qbk"),
    )
    .expect("open");
    let mut expected = h.state().state.clone();
    expected.frame_surface(dataset.volume());
    assert_eq!(surface, expected.camera);
    assert_eq!(h.state().pivot, surface.look_at);
    turn(&mut h);
    h.key_press(Key::Home);
    h.run_steps(2);
    let data = h.state().state.camera;
    assert_ne!(data, surface, "the whole data is framed like the surface");
    // The panel's buttons do the same.
    turn(&mut h);
    h.get_by_label("Frame surface (F)").click();
    h.run_steps(2);
    assert_eq!(h.state().state.camera, surface);
    h.get_by_label("Frame all data (Home)").click();
    h.run_steps(2);
    assert_eq!(h.state().state.camera, data);
}

#[test]
fn each_overlay_has_a_checkbox() {
    let mut h = harness();
    assert_eq!(h.state().state.overlays, Overlays::default());
    for (label, off) in [
        (
            "legend",
            Overlays {
                legend: false,
                ..Overlays::default()
            },
        ),
        (
            "axes",
            Overlays {
                legend: false,
                axes: false,
                ..Overlays::default()
            },
        ),
        (
            "box",
            Overlays {
                legend: false,
                axes: false,
                outline: false,
                ..Overlays::default()
            },
        ),
        ("scale bar", Overlays::NONE),
    ] {
        h.get_by_label(label).click();
        h.run_steps(2);
        assert_eq!(h.state().state.overlays, off, "after {label}");
    }
}

#[test]
fn the_preset_is_reversed_and_log_spaced_over_the_same_range() {
    let mut h = harness();
    let before = h.state().state.colormap.clone();
    let (lo, hi) = before.range();
    h.get_by_label("reverse").click();
    h.run_steps(2);
    let reversed = h.state().state.colormap.clone();
    assert_eq!(reversed.field, before.field);
    assert_eq!(reversed.range(), (lo, hi));
    assert_ne!(reversed.points, before.points);
    h.get_by_label("log").click();
    h.run_steps(2);
    let log = &h.state().state.colormap;
    // Log spacing: the middle point is the geometric mean of a positive range.
    if lo > 0.0 {
        let mid = log.points[log.points.len() / 2].value;
        let want = (lo * hi).sqrt();
        assert!((mid - want).abs() < 1e-3 * want, "{mid} vs {want}");
    }
}

#[test]
fn an_iso_value_outside_the_field_warns_in_the_panel() {
    let mut h = harness();
    let text = |h: &Harness<'static, ViewerApp>| format!("{:#?}", h.root());
    assert!(!text(&h).contains("outside the range"));
    h.state_mut().state.iso = 1e6;
    h.run_steps(2);
    assert!(
        text(&h).contains("is outside the range of q"),
        "no warning for an iso value of 1e6"
    );
}
