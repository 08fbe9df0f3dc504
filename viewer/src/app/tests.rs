//! Window behaviour that needs the window's private parts to set up (a picked point).

use std::path::Path;

use super::picking::PickInfo;
use super::ViewerApp;

#[test]
fn load_view_clears_the_values_picked() {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/wake_small.qbk");
    let mut app = ViewerApp::for_tests(&sample, Some(1)).expect("app");
    let dir = tempfile::tempdir().expect("tempdir");
    let saved = dir.path().join("view.json");
    app.save_state(&saved);
    app.picking.pick = Some(PickInfo {
        world: [1.0, 0.0, 0.0],
        values: vec![("q".into(), 0.1)],
    });
    app.load_state(&saved);
    assert!(app.error.is_none(), "{:?}", app.error);
    // The values belonged to the old view's surface: they must not stay on screen.
    assert!(app.picking.pick.is_none());
}

/// Polls the window's camera fit until it is taken (or 60 s pass).
fn finish_framing(app: &mut ViewerApp) {
    let ctx = eframe::egui::Context::default();
    let t = std::time::Instant::now();
    while app.background_pending() {
        assert!(t.elapsed().as_secs() < 60, "the fit never arrived");
        std::thread::sleep(std::time::Duration::from_millis(2));
        app.poll_background(&ctx);
    }
}

fn sample() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/wake_small.qbk")
}

/// The camera the library fits to the surface of `state`'s view of the sample.
fn framed(state: &crate::view_state::ViewState) -> crate::camera::Camera {
    let dataset = crate::dataset::Dataset::open(&sample()).expect("open");
    let mut s = state.clone();
    s.frame_surface(dataset.volume());
    s.camera
}

/// F on data whose fit takes longer than the window waits: `handle` returns with the
/// camera where it was (the UI thread does not wait on the fit), the status line says
/// so, and the camera moves to the library's fit, with the pivot and the lights, when
/// the fit arrives.
#[test]
fn a_late_fit_to_the_surface_moves_the_camera_when_it_arrives() {
    let mut app = ViewerApp::for_tests(&sample(), Some(1)).expect("app");
    app.background_wait = std::time::Duration::ZERO;
    crate::app::orbit(&mut app.state.camera, app.pivot, 0.7, 0.2);
    let turned = app.state.camera;
    let want = framed(&app.state);
    assert_ne!(want, turned);
    app.handle(super::command::AppCommand::FrameSurface);
    assert!(app.background_pending());
    assert_eq!(app.state.camera, turned, "the window waited for the fit");
    let status = super::status::status_text(None, None, None, app.busy().as_deref());
    assert!(status.contains("framing the surface"), "{status}");
    finish_framing(&mut app);
    assert_eq!(app.state.camera, want);
    assert_eq!(app.pivot, want.look_at);
    let mut lit = app.state.clone();
    lit.lights_follow_camera();
    app.controls.relight(&mut lit);
    assert_eq!(app.state.lights, lit.lights);
}

/// A fit made for a view that is no longer shown (another iso value, a view from the
/// history, a loaded state) leaves the camera alone when it arrives.
#[test]
fn a_fit_for_a_view_no_longer_shown_is_dropped() {
    for change in 0..3 {
        let mut app = ViewerApp::for_tests(&sample(), Some(1)).expect("app");
        let dir = tempfile::tempdir().expect("tempdir");
        let saved = dir.path().join("view.json");
        crate::app::orbit(&mut app.state.camera, app.pivot, 0.7, 0.2);
        app.save_state(&saved);
        app.background_wait = std::time::Duration::ZERO;
        if change == 1 {
            // Back to the opening (framed) view, so that the view redone is the turned one.
            app.handle(super::command::AppCommand::Undo);
        }
        app.handle(super::command::AppCommand::FrameSurface);
        assert!(app.background_pending());
        match change {
            0 => app.state.iso *= 1.5,
            1 => app.handle(super::command::AppCommand::Redo),
            _ => app.load_state(&saved),
        }
        assert_ne!(app.state.camera, framed(&app.state), "change {change}");
        let before = app.state.camera;
        std::thread::sleep(std::time::Duration::from_millis(50));
        finish_framing(&mut app);
        assert_eq!(app.state.camera, before, "change {change}");
    }
}

/// Polls until the file being opened is taken (the fit it starts is not looked at yet).
fn finish_opening(app: &mut ViewerApp) {
    let ctx = eframe::egui::Context::default();
    let t = std::time::Instant::now();
    while app.opening_pending() {
        assert!(t.elapsed().as_secs() < 60, "the open never finished");
        std::thread::sleep(std::time::Duration::from_millis(2));
        app.poll_background(&ctx);
    }
}

/// A file whose open takes longer than the window waits: `open_file` returns at once with
/// the file shown before still open and the status line saying what is being opened;
/// the new file (or its error, naming it) comes when the open is done.
#[test]
fn a_late_open_keeps_the_window_drawing_and_arrives() {
    let mut app = ViewerApp::for_tests(&sample(), Some(1)).expect("app");
    let before = app
        .document
        .doc
        .as_ref()
        .map(|d| std::sync::Arc::clone(&d.dataset));
    let dir = tempfile::tempdir().expect("tempdir");
    let copy = dir.path().join("copy.qbk");
    std::fs::copy(sample(), &copy).expect("copy");
    let broken = dir.path().join("broken.qbk");
    std::fs::write(&broken, b"not a brick file at all, too short").expect("write");
    app.background_wait = std::time::Duration::ZERO;
    app.open_file(&copy);
    assert!(app.opening_pending());
    let busy = app.busy().unwrap_or_default();
    assert!(
        busy.contains("opening") && busy.contains("copy.qbk"),
        "{busy}"
    );
    let now = app
        .document
        .doc
        .as_ref()
        .map(|d| std::sync::Arc::clone(&d.dataset));
    assert!(matches!((&before, &now), (Some(a), Some(b)) if std::sync::Arc::ptr_eq(a, b)));
    finish_opening(&mut app);
    assert_eq!(app.file(), Some(copy.as_path()));
    assert!(app.error.is_none(), "{:?}", app.error);
    app.open_file(&broken);
    assert!(app.opening_pending() && app.error.is_none());
    finish_opening(&mut app);
    let e = app.error.clone().unwrap_or_default();
    assert!(e.contains("broken.qbk"), "{e}");
    assert_eq!(
        app.file(),
        Some(copy.as_path()),
        "a failed open keeps the file open"
    );
}

/// A file opened with a fit that arrives late: its first view is the whole data, and
/// becomes the framed default view (`ViewState::default_for_volume`, as `render` frames
/// it) when the fit arrives, as the first step of the history; unless the user moved
/// the camera meanwhile.
#[test]
fn a_file_opened_with_a_late_fit_is_framed_when_it_arrives_unless_moved() {
    for moved in [false, true] {
        let mut app = ViewerApp::for_tests(&sample(), Some(1)).expect("app");
        app.background_wait = std::time::Duration::ZERO;
        app.open_file(&sample());
        finish_opening(&mut app);
        assert!(app.background_pending());
        let dataset = crate::dataset::Dataset::open(&sample()).expect("open");
        let whole = crate::view_state::ViewState::default_unframed(dataset.volume()).camera;
        let want = crate::view_state::ViewState::default_for_volume(dataset.volume()).camera;
        assert_eq!(app.state.camera, whole);
        if moved {
            crate::app::orbit(&mut app.state.camera, app.pivot, 0.3, 0.0);
        }
        let before = app.state.camera;
        finish_framing(&mut app);
        if moved {
            assert_eq!(app.state.camera, before);
        } else {
            assert_eq!(app.state.camera, want);
            assert!(!app.history.can_undo(), "the framing became an undo step");
        }
    }
}

/// A sequence frame whose open takes longer than the window waits: the frame shown before
/// stays open, the frame does not count as shown (playback waits for it), and it comes
/// with the view kept; a broken frame's error names it and counts as shown, so playback
/// goes on past it.
#[test]
fn a_late_sequence_frame_keeps_the_view_and_playback_waits_for_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    for i in 0..2 {
        std::fs::copy(sample(), dir.path().join(format!("f_{i:04}.qbk"))).expect("copy");
    }
    std::fs::write(dir.path().join("f_0002.qbk"), b"broken").expect("write");
    let pattern = dir.path().join("f_####.qbk");
    let mut app = ViewerApp::for_tests(&pattern, Some(1)).expect("app");
    assert!(
        app.sequence.is_some() && app.error.is_none(),
        "{:?}",
        app.error
    );
    crate::app::orbit(&mut app.state.camera, app.pivot, 0.4, 0.1);
    let view = app.state.camera;
    let first = app
        .document
        .doc
        .as_ref()
        .map(|d| std::sync::Arc::clone(&d.dataset));
    app.background_wait = std::time::Duration::ZERO;
    app.sequence.as_mut().map(|p| p.seek(1));
    app.show_frame();
    assert!(app.opening_pending() && !app.frame_shown());
    let still = app
        .document
        .doc
        .as_ref()
        .map(|d| std::sync::Arc::clone(&d.dataset));
    assert!(matches!((&first, &still), (Some(a), Some(b)) if std::sync::Arc::ptr_eq(a, b)));
    finish_opening(&mut app);
    assert!(app.file().is_some_and(|f| f.ends_with("f_0001.qbk")));
    assert!(app.error.is_none(), "{:?}", app.error);
    assert_eq!(app.state.camera, view, "a frame keeps the view");
    assert!(!app.background_pending(), "a frame is not framed again");
    app.sequence.as_mut().map(|p| p.seek(2));
    app.show_frame();
    assert!(!app.frame_shown());
    finish_opening(&mut app);
    let e = app.error.clone().unwrap_or_default();
    assert!(e.contains("f_0002.qbk"), "{e}");
    assert!(app.frame_shown(), "a broken frame counts as shown");
    assert_eq!(app.state.camera, view);
}

/// The window interactively (no script) on a file whose payload checksum fails (one
/// value's lowest bit flipped, the archive valid): it opens and frames without waiting
/// for the checksum, which runs once framed; when its failure is known the file is
/// refused: the error names the file and the checksum, and saving the picture is refused
/// and writes nothing.
#[test]
fn a_file_whose_checksum_fails_is_refused_once_known() {
    let dir = tempfile::tempdir().expect("tempdir");
    let good = std::fs::read(sample()).expect("read");
    let flipped = crate::testvol::with_one_value_flipped(&good);
    let path = dir.path().join("flipped.qbk");
    std::fs::write(&path, &flipped).expect("write");

    let mut app = ViewerApp::for_tests(&path, Some(1)).expect("app");
    finish_framing(&mut app);
    assert!(app.document.doc.is_some(), "opened without the checksum");
    let ctx = eframe::egui::Context::default();
    let t = std::time::Instant::now();
    while app
        .document
        .doc
        .as_ref()
        .is_some_and(super::document::Doc::checksum_pending)
    {
        assert!(t.elapsed().as_secs() < 60, "the checksum never came");
        std::thread::sleep(std::time::Duration::from_millis(2));
        app.poll_background(&ctx);
    }
    assert!(
        !app.take_file_error(&ctx),
        "an interactive window stays open"
    );
    let error = app.error.clone().unwrap_or_default();
    assert!(
        error.contains("flipped.qbk") && error.contains("checksum"),
        "{error}"
    );
    let png = dir.path().join("shot.png");
    app.save_png(&png);
    assert!(!png.exists(), "a picture of a refused file was saved");
    assert!(app.error.as_deref().is_some_and(|e| e.contains("checksum")));
}
