//! The window's surfaces list, clip planes and slices driven through egui_kittest: adding
//! them, moving, flipping, turning and removing planes, changing a surface's opacity and
//! colour, undo; and a view with planes and two surfaces saved from the window renders
//! headless to the window's pixels.
#![cfg(feature = "gui")]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use eframe::egui::accesskit::Role;
use eframe::egui::{Key, Pos2};
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use qbricks_viewer::app::ViewerApp;
use qbricks_viewer::view_state::{ViewState, NEW_SURFACE_OPACITY};

fn sample() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/wake_small.qbk")
}

/// A window tall enough that the whole panel is on screen.
fn harness(threads: usize) -> Harness<'static, ViewerApp> {
    let app = ViewerApp::for_tests(&sample(), Some(threads)).expect("app");
    let mut h = Harness::builder()
        .with_size(eframe::egui::Vec2::new(1100.0, 1800.0))
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app);
    h.run_steps(3);
    h
}

fn state(h: &Harness<'static, ViewerApp>) -> ViewState {
    h.state().state.clone()
}

fn click(h: &mut Harness<'static, ViewerApp>, label: &str) {
    h.get_by_label(label).click();
    h.run_steps(2);
}

/// Clicks the `n`th (from 0, in panel order) control labelled `label`.
fn click_nth(h: &mut Harness<'static, ViewerApp>, label: &str, n: usize) {
    h.get_all_by_label(label)
        .nth(n)
        .unwrap_or_else(|| panic!("no control {n} labelled {label}"))
        .click();
    h.run_steps(2);
}

/// Undo through the Edit menu (keys go to a focused slider).
fn undo(h: &mut Harness<'static, ViewerApp>) {
    h.get_by_label("Edit").click();
    h.run_steps(2);
    h.get_by_label_contains("Undo").click();
    h.run_steps(2);
}

/// Presses an arrow key `times` on the slider labelled `label`.
fn nudge(h: &mut Harness<'static, ViewerApp>, label: &str, key: Key, times: usize) {
    h.get_by_role_and_label(Role::Slider, label).focus();
    h.run_steps(1);
    for _ in 0..times {
        h.key_press(key);
        h.run_steps(1);
    }
}

/// Drags the handle of the slider labelled `label` from its middle towards its right end.
fn drag_right(h: &mut Harness<'static, ViewerApp>, label: &str) {
    let rect = h.get_by_role_and_label(Role::Slider, label).rect();
    let y = rect.center().y;
    h.hover_at(Pos2::new(rect.center().x, y));
    h.run_steps(1);
    h.drag_at(Pos2::new(rect.center().x, y));
    h.run_steps(1);
    for i in 1..=4 {
        let x = rect.center().x + (rect.right() - 4.0 - rect.center().x) * i as f32 / 5.0;
        h.hover_at(Pos2::new(x, y));
        h.run_steps(1);
    }
    h.drop_at(Pos2::new(rect.right() - 4.0, y));
    h.run_steps(2);
    h.remove_cursor();
    h.run_steps(1);
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let l = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    v.map(|x| x / l)
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| a[k] * b[k]).sum()
}

#[test]
fn clip_planes_and_slices_are_added_moved_flipped_removed_and_undone() {
    let mut h = harness(1);
    assert!(state(&h).clip.is_empty() && state(&h).slices.is_empty());
    let pivot = h.state().pivot;

    // Added through the pivot, across the axis the view looks along most, keeping the
    // far side.
    click(&mut h, "Add clip plane");
    let st = state(&h);
    assert_eq!(st.clip.len(), 1, "no clip plane added");
    let added = st.clip[0];
    let forward: [f64; 3] = std::array::from_fn(|a| st.camera.look_at[a] - st.camera.eye[a]);
    let axis = added.axis().expect("across an axis");
    let most = (0..3)
        .max_by(|&i, &j| forward[i].abs().total_cmp(&forward[j].abs()))
        .expect("an axis");
    assert_eq!(axis, most);
    assert!(dot(added.normal, forward) > 0.0, "keeps the near side");
    assert_eq!(added.origin, pivot);
    let gen = h.state().generation;

    // Dragging its slider moves it along its normal, and renders again.
    drag_right(&mut h, "clip 1 offset");
    let moved = state(&h).clip[0];
    assert_eq!(moved.normal, added.normal);
    let shift: [f64; 3] = std::array::from_fn(|a| moved.origin[a] - added.origin[a]);
    let along = dot(shift, unit(added.normal)).abs();
    let length = dot(shift, shift).sqrt();
    assert!(length > 0.1, "the drag moved the plane by {length}");
    assert!(
        (along - length).abs() < 1e-9 * length,
        "moved off its normal: {shift:?}"
    );
    // To the right is further along the axis.
    assert!(shift[axis] > 0.0, "{shift:?}");
    assert!(
        h.state().generation > gen,
        "no new frame for the moved plane"
    );

    // Flip turns the normal round where the plane is.
    click(&mut h, "flip");
    let flipped = state(&h).clip[0];
    assert_eq!(flipped, moved.flipped());

    // Another axis, through the same point.
    let other = ["x", "y", "z"][(axis + 1) % 3];
    let other_axis = (axis + 1) % 3;
    // "x" also labels the colour points' remove buttons: the plane's is the last one.
    let n = h.get_all_by_label(other).count();
    click_nth(&mut h, other, n - 1);
    let turned = state(&h).clip[0];
    assert_eq!(turned.axis(), Some(other_axis));
    assert_eq!(turned.origin, flipped.origin);

    // A slice, with its opacity, contours and clip in front.
    click(&mut h, "Add slice");
    assert_eq!(state(&h).slices.len(), 1, "no slice added");
    let slice = state(&h).slices[0];
    assert_eq!(
        (slice.opacity, slice.contours, slice.clip),
        (1.0, false, false)
    );
    nudge(&mut h, "slice 1 opacity", Key::ArrowLeft, 3);
    click(&mut h, "contours");
    click(&mut h, "clip in front");
    let slice = state(&h).slices[0];
    assert!(
        slice.opacity < 1.0 && slice.opacity > 0.0,
        "{}",
        slice.opacity
    );
    assert!(slice.contours && slice.clip);
    assert!(h.state().error.is_none(), "{:?}", h.state().error);

    // Remove the clip plane (the first remove button), then undo brings it back.
    click_nth(&mut h, "remove", 0);
    assert!(state(&h).clip.is_empty(), "the clip plane was not removed");
    assert_eq!(state(&h).slices.len(), 1);
    undo(&mut h);
    assert_eq!(state(&h).clip, vec![turned]);
    // And further back, step by step: the slice's settings (each key press on its
    // opacity slider was one), the slice, the turn, the flip, the move, the plane.
    for step in 0..6 {
        assert_eq!(state(&h).slices.len(), 1, "undo {step}");
        undo(&mut h);
        assert_eq!(state(&h).clip, vec![turned]);
    }
    assert!(state(&h).slices.is_empty(), "{:?}", state(&h).slices);
    undo(&mut h);
    assert_eq!(state(&h).clip, vec![flipped]);
    undo(&mut h);
    assert_eq!(state(&h).clip, vec![moved]);
    undo(&mut h);
    assert_eq!(state(&h).clip, vec![added]);
    undo(&mut h);
    assert!(state(&h).clip.is_empty());
}

#[test]
fn a_surface_is_added_and_its_opacity_and_colour_changed() {
    let mut h = harness(1);
    let iso = state(&h).iso;
    assert!(state(&h).more_isos.is_empty());
    click(&mut h, "Add surface");
    let st = state(&h);
    assert_eq!(st.more_isos.len(), 1, "no surface added");
    assert_eq!(st.more_isos[0].value, 0.5 * iso);
    assert_eq!(st.more_isos[0].opacity, NEW_SURFACE_OPACITY);
    assert_eq!(st.iso, iso);

    nudge(&mut h, "opacity 2", Key::ArrowLeft, 3);
    let opacity = state(&h).more_isos[0].opacity;
    assert!(
        opacity < NEW_SURFACE_OPACITY && opacity > 0.0,
        "opacity {opacity}"
    );
    // Its value on its own slider; the first surface's stays.
    nudge(&mut h, "iso value 2", Key::ArrowRight, 2);
    let value = state(&h).more_isos[0].value;
    assert!(value > 0.5 * iso, "value {value}");
    assert_eq!(state(&h).iso, iso);
    // A colour of its own (the second surface's checkbox), and back to the map's.
    click_nth(&mut h, "colour", 1);
    assert!(state(&h).more_isos[0].colour.is_some());
    assert!(state(&h).iso_colour.is_none());
    click_nth(&mut h, "colour", 1);
    assert!(state(&h).more_isos[0].colour.is_none());
    // The first surface's opacity is its own slider.
    nudge(&mut h, "opacity", Key::ArrowLeft, 2);
    assert!(state(&h).iso_opacity < 1.0);
    state(&h).validate().expect("a valid view");

    // Removing the first makes the second the first; undo brings both back.
    let both = state(&h).surfaces();
    click_nth(&mut h, "remove", 0);
    let st = state(&h);
    assert_eq!(st.surfaces(), vec![both[1]]);
    assert!(st.more_isos.is_empty());
    // The last one left has no remove button.
    assert!(h.query_by_label("remove").is_none());
    undo(&mut h);
    assert_eq!(state(&h).surfaces(), both);
}

/// Steps the UI until the renderer has finished the current view.
fn refine(h: &mut Harness<'static, ViewerApp>) {
    let end = Instant::now() + Duration::from_secs(180);
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
fn a_view_with_planes_and_two_surfaces_renders_headless_to_the_same_pixels() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut h = harness(2);
    // Turned a little, so the planes are seen at an angle.
    {
        let app = h.state_mut();
        qbricks_viewer::app::orbit(&mut app.state.camera, app.pivot, 0.5, 0.3);
        app.resolution_scale = 0.3;
    }
    h.run_steps(2);
    click(&mut h, "Add surface");
    click(&mut h, "Add clip plane");
    click(&mut h, "Add slice");
    nudge(&mut h, "slice 1 opacity", Key::ArrowLeft, 4);
    // The slice across another axis than the clip plane.
    let axis = state(&h).slices[0].plane.axis().expect("an axis");
    let other = ["x", "y", "z"][(axis + 2) % 3];
    let n = h.get_all_by_label(other).count();
    click_nth(&mut h, other, n - 1);
    let st = state(&h);
    assert_eq!(
        (st.clip.len(), st.slices.len(), st.surfaces().len()),
        (1, 1, 2)
    );
    assert_ne!(st.clip[0].axis(), st.slices[0].plane.axis());
    refine(&mut h);
    let state_path = dir.path().join("view.json");
    h.state_mut().save_state(&state_path);
    let png = dir.path().join("window.png");
    h.state_mut().save_png(&png);
    assert!(h.state().error.is_none(), "{:?}", h.state().error);
    let saved = ViewState::load(&state_path).expect("the saved view");
    assert_eq!(saved.clip, st.clip);
    assert_eq!(saved.slices, st.slices);
    assert_eq!(saved.more_isos, st.more_isos);

    let render = |overlays: Option<&str>, out: &Path| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_qbricks-view"));
        c.arg("render")
            .arg(sample())
            .arg("--state")
            .arg(&state_path)
            .arg("-o")
            .arg(out);
        if let Some(o) = overlays {
            c.args(["--overlays", o]);
        }
        let out = c.output().expect("run qbricks-view");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let headless = dir.path().join("headless.png");
    render(None, &headless);
    let a = image::open(&png).expect("window png").to_rgb8();
    let b = image::open(&headless).expect("headless png").to_rgb8();
    assert_eq!(a.dimensions(), b.dimensions());
    assert!(
        a == b,
        "the window's image differs from the headless render"
    );
    // The picture has the box overlay, with the planes' outlines (the overlays' unit
    // tests check where they are drawn).
    let distinct: std::collections::HashSet<_> = a.pixels().map(|p| p.0).collect();
    assert!(distinct.len() > 20, "{} colours", distinct.len());
    let no_box = dir.path().join("no_box.png");
    render(Some("legend,axes,scale"), &no_box);
    let c = image::open(&no_box).expect("png").to_rgb8();
    assert!(a != c, "the box overlay drew nothing");
}
