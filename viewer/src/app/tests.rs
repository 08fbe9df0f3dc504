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
