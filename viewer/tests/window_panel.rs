//! The window's side panel driven through egui_kittest: no display, no GPU. Each test
//! builds the real `ViewerApp` on the bundled sample and acts on it as a user would.
#![cfg(feature = "gui")]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use qbricks_viewer::app::ViewerApp;
use qbricks_viewer::view_state::ViewState;

fn sample() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/wake_small.qbk")
}

fn harness(app: ViewerApp) -> Harness<'static, ViewerApp> {
    let mut h = Harness::builder()
        .with_size(eframe::egui::Vec2::new(1100.0, 900.0))
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app);
    h.run_steps(3);
    h
}

/// Steps the UI until the renderer has finished the current view.
fn refine(h: &mut Harness<'static, ViewerApp>) {
    let end = Instant::now() + Duration::from_secs(120);
    loop {
        h.step();
        let app = h.state();
        if app.renderer().idle() && app.renderer().wait_complete(app.generation, Duration::ZERO) {
            h.step(); // take the last image
            return;
        }
        assert!(Instant::now() < end, "the view never finished rendering");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn moving_the_iso_slider_changes_the_state_and_starts_a_new_frame() {
    let app = ViewerApp::for_tests(&sample(), Some(2)).expect("app");
    let mut h = harness(app);
    let iso0 = h.state().state.iso;
    let sigma0 = h.state().state.transfer.sigma;
    let gen0 = h.state().generation;
    assert!(gen0 > 0, "the first view was never submitted");
    h.get_by_role_and_label(eframe::egui::accesskit::Role::Slider, "iso value")
        .focus();
    h.run_steps(1);
    for _ in 0..5 {
        h.key_press(eframe::egui::Key::ArrowRight);
        h.run_steps(1);
    }
    let st = &h.state().state;
    assert!(st.iso > iso0, "iso {} did not grow from {iso0}", st.iso);
    // The dvr band follows the iso value, as on the command line.
    assert!((st.transfer.sigma - 0.08 * st.iso.abs()).abs() < 1e-12);
    assert_ne!(st.transfer.sigma, sigma0);
    assert!(h.state().generation > gen0, "no new frame was started");
}

#[test]
fn an_idle_window_does_not_start_new_frames() {
    let app = ViewerApp::for_tests(&sample(), Some(1)).expect("app");
    let mut h = harness(app);
    refine(&mut h);
    let generation = h.state().generation;
    h.run_steps(30);
    assert_eq!(
        h.state().generation,
        generation,
        "the view changed without input"
    );
}

#[test]
fn a_colour_point_added_shows_in_the_map() {
    let app = ViewerApp::for_tests(&sample(), Some(1)).expect("app");
    let mut h = harness(app);
    let before = h.state().state.colormap.points.clone();
    let gen0 = h.state().generation;
    h.get_by_label("Add point").click();
    h.run_steps(2);
    let map = &h.state().state.colormap;
    assert_eq!(map.points.len(), before.len() + 1);
    // The new point halves the widest gap, with the colour the map had there, so the
    // picture does not jump.
    let (gap, i) = before
        .windows(2)
        .enumerate()
        .map(|(i, w)| (w[1].value - w[0].value, i))
        .fold((f32::MIN, 0), |a, b| if b.0 > a.0 { b } else { a });
    let mid = before[i].value + 0.5 * gap;
    let added = map
        .points
        .iter()
        .find(|p| (p.value - mid).abs() < 1e-6)
        .expect("a point in the middle of the widest gap");
    let old_map = qbricks_viewer::colormap::ColorMap {
        points: before.clone(),
        ..map.clone()
    };
    let want = old_map.colour(mid);
    for a in 0..3 {
        assert!(
            (added.colour[a] - want[a]).abs() < 1e-5,
            "{:?} vs {want:?}",
            added.colour
        );
    }
    assert!(map.points.windows(2).all(|w| w[0].value <= w[1].value));
    assert!(h.state().generation > gen0);
    map.validate().expect("still a valid map");
}

#[test]
fn a_saved_and_loaded_state_is_equal() {
    let dir = tempfile::tempdir().expect("tempdir");
    let app = ViewerApp::for_tests(&sample(), Some(1)).expect("app");
    let mut h = harness(app);
    let path = dir.path().join("view.json");
    h.state_mut().save_state(&path);
    let saved = h.state().state.clone();
    assert_eq!(ViewState::load(&path).expect("load"), saved);
    // Change the view, then load the file back.
    h.state_mut().state.iso *= 0.5;
    h.state_mut().state.camera.eye[0] += 1.0;
    h.run_steps(1);
    h.state_mut().load_state(&path);
    h.run_steps(1);
    let mut loaded = h.state().state.clone();
    // The window renders at its own size; everything else is the file's.
    loaded.width = saved.width;
    loaded.height = saved.height;
    assert_eq!(loaded, saved);
    assert!(h.state().error.is_none(), "{:?}", h.state().error);
}

#[test]
fn a_bad_file_shows_its_error_and_keeps_the_old_file_open() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bad = dir.path().join("broken.qbk");
    std::fs::write(&bad, b"this is not a brick file").expect("write");
    let app = ViewerApp::for_tests(&sample(), Some(1)).expect("app");
    let mut h = harness(app);
    let open_before = h.state().file().map(Path::to_path_buf);
    h.state_mut().open_any(&bad);
    h.run_steps(2);
    let err = h.state().error.clone().expect("an error message");
    assert!(err.contains("broken.qbk"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    // The message is on screen, and the sample is still the open file.
    assert!(h.query_by_label_contains("broken.qbk").is_some());
    assert_eq!(h.state().file().map(Path::to_path_buf), open_before);
    // A state naming a field the file lacks is refused the same way.
    let st = dir.path().join("other.json");
    let mut s = h.state().state.clone();
    s.iso_field = "vorticity".into();
    s.save(&st).expect("save");
    h.state_mut().load_state(&st);
    h.run_steps(1);
    assert!(h
        .state()
        .error
        .as_deref()
        .unwrap_or("")
        .contains("vorticity"));
    assert_ne!(h.state().state.iso_field, "vorticity");
}

#[test]
fn a_view_saved_in_the_window_renders_headless_to_the_same_pixels() {
    let dir = tempfile::tempdir().expect("tempdir");
    let app = ViewerApp::for_tests(&sample(), Some(2)).expect("app");
    let mut h = harness(app);
    // A view of its own: orbit a little, dvr mode, 2 samples per pixel.
    {
        let app = h.state_mut();
        qbricks_viewer::app::orbit(&mut app.state.camera, app.pivot, 0.4, 0.2);
        app.state.mode = qbricks_viewer::transfer::Mode::Dvr;
        app.state.strategy = qbricks_viewer::sampling::Strategy::Bisect;
        app.state.spp = 2;
        app.resolution_scale = 0.25;
    }
    h.run_steps(2);
    refine(&mut h);
    let state_path = dir.path().join("view.json");
    h.state_mut().save_state(&state_path);
    let png = dir.path().join("window.png");
    h.state_mut().save_png(&png);
    assert!(h.state().error.is_none(), "{:?}", h.state().error);

    let headless = dir.path().join("headless.png");
    let out = Command::new(env!("CARGO_BIN_EXE_qbricks-view"))
        .arg("render")
        .arg(sample())
        .arg("--state")
        .arg(&state_path)
        .arg("-o")
        .arg(&headless)
        .output()
        .expect("run qbricks-view");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let a = image::open(&png).expect("window png").to_rgb8();
    let b = image::open(&headless).expect("headless png").to_rgb8();
    assert_eq!(a.dimensions(), b.dimensions());
    assert!(
        a == b,
        "the window's image differs from the headless render"
    );
    // And the window really rendered something.
    let distinct: std::collections::HashSet<_> = a.pixels().map(|p| p.0).collect();
    assert!(distinct.len() > 20, "{} colours", distinct.len());
}

/// Choosing another iso field in the window starts it where `render --iso-field` starts
/// it, whatever iso value the view held (the window used to keep Q's value, and speed at
/// Q's 0.25 showed nothing): the same iso value and band width. Choosing a colour field
/// gives the map `--colour-field` gives.
#[test]
fn choosing_fields_in_the_window_gives_the_state_the_command_line_gives() {
    use eframe::egui::accesskit::Role;
    let dir = tempfile::tempdir().expect("tempdir");
    let saved = dir.path().join("cli.json");
    let out = Command::new(env!("CARGO_BIN_EXE_qbricks-view"))
        .arg("render")
        .arg(sample())
        .args(["--iso-field", "speed", "--colour-field", "q"])
        .args(["--width", "8", "--height", "6", "-o"])
        .arg(dir.path().join("cli.png"))
        .arg("--save-state")
        .arg(&saved)
        .output()
        .expect("run qbricks-view");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cli = ViewState::load(&saved).expect("the saved state");

    let app = ViewerApp::for_tests(&sample(), Some(1)).expect("app");
    let mut h = harness(app);
    h.state_mut().state.set_iso(0.25);
    h.run_steps(1);
    h.get_by_role_and_label(Role::ComboBox, "iso field").click();
    h.run_steps(2);
    h.get_by_role_and_label(Role::Button, "speed").click();
    h.run_steps(2);
    let st = &h.state().state;
    assert_eq!(st.iso_field, "speed");
    assert_eq!(
        (st.iso, st.transfer.sigma),
        (cli.iso, cli.transfer.sigma),
        "the window's iso value and band for speed, then the command line's"
    );
    h.get_by_role_and_label(Role::ComboBox, "colour field")
        .click();
    h.run_steps(2);
    h.get_by_role_and_label(Role::Button, "q").click();
    h.run_steps(2);
    let (map, want) = (&h.state().state.colormap, &cli.colormap);
    assert_eq!(
        (map.field.as_str(), map.band),
        (want.field.as_str(), want.band)
    );
    assert_eq!(map.points.len(), want.points.len());
    for (p, q) in map.points.iter().zip(&want.points) {
        assert_eq!(p.value, q.value);
        // Drawing the panel's colour buttons rounds the colours through egui's colour
        // type (by a few 1e-8); the map is otherwise the command line's.
        let close = p
            .colour
            .iter()
            .zip(q.colour)
            .all(|(a, b)| (a - b).abs() < 1e-6);
        assert!(close, "{:?} vs {:?}", p.colour, q.colour);
    }
    assert!(h.state().error.is_none(), "{:?}", h.state().error);
}
