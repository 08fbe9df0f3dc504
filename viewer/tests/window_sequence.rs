//! The window opened on a frame sequence (`qbricks-view 'out/frame_####.qbk'`), driven
//! through egui_kittest with no display: the frame slider, stepping, play/pause, one view
//! state and one colour map over every frame, a corrupt frame in the middle.
#![cfg(feature = "gui")]

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use qbricks_viewer::app::ViewerApp;
use qbricks_viewer::testvol::{self, GridSpec};

/// A frame over the unit cube: `q` a cone around the centre, `speed` = x plus, scaled by
/// `hot`, a narrow bump at the corner (1, 1, 1) that widens the frame's speed range.
fn write_frame(path: &Path, hot: f64) {
    let q = |p: [f64; 3]| 1.0 - 2.0 * p.iter().map(|x| (x - 0.5).powi(2)).sum::<f64>().sqrt();
    let speed = move |p: [f64; 3]| {
        p[0] + hot * (-p.iter().map(|x| (x - 1.0).powi(2)).sum::<f64>() / 0.01).exp()
    };
    let grid = GridSpec::covering([0.0; 3], [1.0; 3], 1.0 / 8.0);
    let file = testvol::build(&[grid], &[("q", &q), ("speed", &speed)], 8);
    format::writer::write(path, &file).expect("write frame");
}

fn harness(app: ViewerApp) -> Harness<'static, ViewerApp> {
    let mut h = Harness::builder()
        .with_size(eframe::egui::Vec2::new(900.0, 700.0))
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app);
    h.run_steps(3);
    h
}

fn file_name(h: &Harness<'static, ViewerApp>) -> String {
    h.state()
        .file()
        .and_then(Path::file_name)
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Steps the UI (with real time passing) until `done`, at most 60 s.
fn step_until(h: &mut Harness<'static, ViewerApp>, what: &str, done: impl Fn(&ViewerApp) -> bool) {
    let end = Instant::now() + Duration::from_secs(60);
    while !done(h.state()) {
        assert!(Instant::now() < end, "timed out waiting for {what}");
        h.step();
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn frames(dir: &Path) -> PathBuf {
    write_frame(&dir.join("f_0001.qbk"), 0.0);
    write_frame(&dir.join("f_0002.qbk"), 3.0);
    write_frame(&dir.join("f_0003.qbk"), 0.0);
    dir.join("f_####.qbk")
}

#[test]
fn the_slider_and_buttons_step_through_frames_with_one_view() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pattern = frames(dir.path());
    let app = ViewerApp::for_tests(&pattern, Some(1)).expect("app");
    let mut h = harness(app);
    assert!(h.state().error.is_none(), "{:?}", h.state().error);
    assert_eq!(h.state().sequence.as_ref().map(|p| p.frames.len()), Some(3));
    assert_eq!(file_name(&h), "f_0001.qbk");
    // The colour map spans the whole sequence's speed range (frame 2's hot corner), not
    // frame 1's own.
    let top = h
        .state()
        .state
        .colormap
        .points
        .last()
        .map_or(0.0, |p| p.value);
    assert!(top > 1.5, "colour map ends at {top} (frame 1 alone: 0.94)");
    let view = h.state().state.clone();

    let gen0 = h.state().generation;
    h.get_by_label("▶").click();
    h.run_steps(2);
    assert_eq!(file_name(&h), "f_0002.qbk");
    assert_eq!(h.state().state, view, "a frame change keeps the view");
    assert!(
        h.state().generation > gen0,
        "the new frame was not rendered"
    );
    h.get_by_label("◀").click();
    h.run_steps(1);
    h.get_by_label("◀").click();
    h.run_steps(1);
    assert_eq!(file_name(&h), "f_0003.qbk", "stepping back wraps");

    // The slider: focus it and move with the arrow keys.
    h.get_by_role_and_label(eframe::egui::accesskit::Role::Slider, "frame")
        .focus();
    h.run_steps(1);
    h.key_press(eframe::egui::Key::ArrowLeft);
    h.run_steps(2);
    assert_eq!(file_name(&h), "f_0002.qbk");
    assert!(h.query_by_label_contains("2 of 3 frames").is_some());
}

#[test]
fn play_loops_over_the_frames_and_skips_a_corrupt_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pattern = frames(dir.path());
    std::fs::write(dir.path().join("f_0002.qbk"), b"not a brick file").expect("corrupt");
    let app = ViewerApp::for_tests(&pattern, Some(1)).expect("app");
    let mut h = harness(app);
    if let Some(p) = &mut h.state_mut().sequence {
        p.fps = 30.0;
    }
    h.get_by_label("Play").click();
    h.run_steps(1);
    assert!(h.state().sequence.as_ref().is_some_and(|p| p.playing));
    // Frame 2 does not open: its error shows, frame 1 stays on screen, playback goes on.
    step_until(&mut h, "frame 2", |a| {
        a.sequence.as_ref().is_some_and(|p| p.frame() == 2)
    });
    h.step();
    let err = h.state().error.clone().unwrap_or_default();
    assert!(err.contains("f_0002.qbk"), "{err}");
    step_until(&mut h, "frame 3", |a| {
        a.file().is_some_and(|f| f.ends_with("f_0003.qbk"))
    });
    assert!(h.state().error.is_none(), "a good frame clears the error");
    step_until(&mut h, "the loop back to frame 1", |a| {
        a.file().is_some_and(|f| f.ends_with("f_0001.qbk"))
    });
    h.get_by_label("Pause").click();
    h.run_steps(1);
    let at = h.state().sequence.as_ref().map(|p| p.index);
    for _ in 0..20 {
        h.step();
        std::thread::sleep(Duration::from_millis(10));
    }
    assert_eq!(h.state().sequence.as_ref().map(|p| p.index), at, "paused");
}

#[test]
fn a_pattern_without_frames_is_an_error_in_the_window() {
    let dir = tempfile::tempdir().expect("tempdir");
    let app = ViewerApp::for_tests(&dir.path().join("g_####.qbk"), Some(1)).expect("app");
    let h = harness(app);
    let err = h.state().error.clone().unwrap_or_default();
    assert!(
        err.contains("g_####.qbk") && err.contains("no file matches"),
        "{err}"
    );
    assert!(h.state().sequence.is_none());
}
