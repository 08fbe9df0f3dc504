//! Whole-image rendering: determinism across thread counts, sensible statistics.

use qbricks_viewer::mesh::Meshes;
use qbricks_viewer::render::{render, render_with_threads, Scene};
use qbricks_viewer::sampling::Strategy;
use qbricks_viewer::testvol;
use qbricks_viewer::transfer::Mode;
use qbricks_viewer::view_state::ViewState;
use qbricks_viewer::volume::Volume;

fn field(p: [f64; 3]) -> f64 {
    (p[0] / 4.0).sin() * (p[1] / 5.0).cos() + 0.3 * (p[2] / 3.0).sin()
}

fn speed(p: [f64; 3]) -> f64 {
    0.5 + 0.5 * (p[0] / 9.0).sin()
}

fn state_for(vol: &Volume) -> ViewState {
    let mut s = ViewState::default_for_volume(vol);
    s.width = 40;
    s.height = 32;
    s.iso = 0.4;
    s.transfer.sigma = 0.05;
    s
}

#[test]
fn same_pixels_whatever_the_thread_count() {
    let file = testvol::nested(16, [0.0; 3], &[("q", &field), ("speed", &speed)], 8);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    let meshes = Meshes::empty();
    for (mode, strategy, spp, shadows) in [
        (Mode::Iso, Strategy::Exact, 1, true),
        (Mode::Iso, Strategy::Uniform, 2, false),
        (Mode::Dvr, Strategy::Bisect, 2, true),
        (Mode::Dvr, Strategy::Paper, 1, false),
    ] {
        let mut st = state_for(&vol);
        st.mode = mode;
        st.strategy = strategy;
        st.spp = spp;
        st.shadows = shadows;
        st.seed = 7;
        let scene = Scene::new(&vol, &st, &meshes).expect("scene");
        let frames: Vec<_> = [1, 2, 3]
            .iter()
            .map(|&n| render_with_threads(&scene, n).expect("pool"))
            .collect();
        assert!(frames[0].hits > 0, "{mode:?} {strategy:?}: nothing hit");
        assert!(frames[0].stats.samples > 0);
        for f in &frames[1..] {
            assert_eq!(
                f, &frames[0],
                "{mode:?} {strategy:?}: differs between thread counts"
            );
        }
        // A different seed changes the jittered images (the jitter is really used).
        if spp > 1 {
            let mut st2 = st.clone();
            st2.seed = 8;
            let scene2 = Scene::new(&vol, &st2, &meshes).expect("scene");
            assert_ne!(render(&scene2).rgb, frames[0].rgb);
        }
    }
}

#[test]
fn iso_value_outside_the_data_hits_nothing_and_skips_everything() {
    let file = testvol::nested(8, [0.0; 3], &[("q", &field), ("speed", &speed)], 8);
    let view = testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    let meshes = Meshes::empty();
    for strategy in [
        Strategy::Exact,
        Strategy::Uniform,
        Strategy::Paper,
        Strategy::Bisect,
    ] {
        let mut st = state_for(&vol);
        st.iso = 100.0;
        st.strategy = strategy;
        let scene = Scene::new(&vol, &st, &meshes).expect("scene");
        let f = render(&scene);
        assert_eq!(f.hits, 0);
        assert_eq!(
            f.stats.samples, 0,
            "{strategy:?}: region bounds should skip every sample"
        );
        assert!(f.rgb.iter().all(|c| *c == st.background));
    }
}
