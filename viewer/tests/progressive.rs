//! The window's progressive renderer, without a window: the refined frame equals the
//! headless render, the newest view always wins, a cancel stops a frame within a row.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use qbricks_viewer::dataset::Dataset;
use qbricks_viewer::mesh::{icosphere, Meshes};
use qbricks_viewer::progressive::{Job, Level, Progressive, ProgressiveOptions, Update};
use qbricks_viewer::render::{render, tiles, CancelToken, Renderer, Scene, TileResult};
use qbricks_viewer::sampling::Strategy;
use qbricks_viewer::testvol;
use qbricks_viewer::transfer::Mode;
use qbricks_viewer::view_state::ViewState;

fn field(p: [f64; 3]) -> f64 {
    (p[0] / 4.0).sin() * (p[1] / 5.0).cos() + 0.3 * (p[2] / 3.0).sin()
}

fn speed(p: [f64; 3]) -> f64 {
    0.5 + 0.5 * (p[0] / 9.0).sin()
}

fn dataset() -> Arc<Dataset> {
    let file = testvol::nested(16, [0.0; 3], &[("q", &field), ("speed", &speed)], 8);
    let view = testvol::open(&file).expect("open");
    Arc::new(Dataset::from_view(view, Instant::now()).expect("dataset"))
}

fn state(ds: &Dataset) -> ViewState {
    let mut s = ViewState::default_for_volume(ds.volume());
    s.width = 61;
    s.height = 37;
    s.set_iso(0.4);
    s.transfer.sigma = 0.05;
    s
}

/// Collects every update until the job completes.
fn run_to_completion(p: &Progressive, generation: u64) -> Vec<Update> {
    let mut seen = Vec::new();
    let end = Instant::now() + Duration::from_secs(60);
    loop {
        if let Some(u) = p.latest() {
            let done = u.complete;
            seen.push(u);
            if done {
                return seen;
            }
        }
        assert!(p.error().is_none(), "render failed: {:?}", p.error());
        assert!(Instant::now() < end, "job {generation} did not complete");
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn refined_frame_equals_headless_render_pixel_for_pixel() {
    let ds = dataset();
    let sphere = icosphere([16.0, 16.0, 16.0].into(), 3.0, 2);
    let meshes = Arc::new(Meshes::from_meshes(&[sphere]));
    let p = Progressive::new(
        ProgressiveOptions {
            threads: Some(2),
            ..ProgressiveOptions::default()
        },
        Box::new(|| {}),
    )
    .expect("start");
    for (mode, strategy, spp, shadows) in [
        (Mode::Iso, Strategy::Exact, 1, true),
        (Mode::Iso, Strategy::Bisect, 3, false),
        (Mode::Dvr, Strategy::Paper, 4, true),
    ] {
        let mut st = state(&ds);
        st.mode = mode;
        st.strategy = strategy;
        st.spp = spp;
        st.shadows = shadows;
        st.seed = 3;
        let generation = p.submit(Job {
            dataset: Arc::clone(&ds),
            meshes: Arc::clone(&meshes),
            state: st.clone(),
            preview: true,
        });
        let updates = run_to_completion(&p, generation);
        let last = updates.last().expect("an update");
        let want = render(&Scene::new(ds.volume(), &st, &meshes).expect("scene"));
        assert!(want.hits > 0, "{mode:?}: nothing hit");
        assert_eq!((last.width, last.height), (want.width, want.height));
        assert_eq!(
            *last.rgb, want.rgb,
            "{mode:?} {strategy:?} spp {spp}: refined frame differs from the headless render"
        );
        assert_eq!(last.counts.stats, want.stats);
        assert_eq!(last.samples, spp);
        // Previews (when one was seen before a newer image replaced it) are at the
        // smallest divisor or coarser, and come before every full-resolution image.
        let min = ProgressiveOptions::default().min_scale;
        for (i, u) in updates.iter().enumerate() {
            if let Level::Preview { scale } = u.level {
                assert!(scale >= min, "preview scale {scale}");
                assert_eq!(u.width, st.width.div_ceil(scale));
                assert!(updates[..i].iter().all(|v| v.level != Level::Full));
            }
        }
        assert!(p.preview_scale() >= min);
        // Sample waves arrive in order and every update belongs to this job.
        assert!(updates.iter().all(|u| u.generation == generation));
        let full: Vec<u32> = updates
            .iter()
            .filter(|u| u.level == Level::Full)
            .map(|u| u.samples)
            .collect();
        assert!(full.windows(2).all(|w| w[0] <= w[1]), "{full:?}");
    }
}

#[test]
fn newest_frame_always_wins() {
    let ds = dataset();
    let meshes = Arc::new(Meshes::empty());
    let notified = Arc::new(AtomicUsize::new(0));
    let n = Arc::clone(&notified);
    let p = Progressive::new(
        ProgressiveOptions {
            threads: Some(2),
            ..ProgressiveOptions::default()
        },
        Box::new(move || {
            n.fetch_add(1, Ordering::Relaxed);
        }),
    )
    .expect("start");
    let base = state(&ds);
    // A burst of views, as while dragging: each one supersedes the last.
    let mut last_generation = 0;
    let mut seen_generation = 0;
    for i in 0..20 {
        let mut st = base.clone();
        st.spp = 8; // slow enough that most jobs are cancelled mid-frame
        st.camera.eye[0] += f64::from(i) * 0.5;
        last_generation = p.submit(Job {
            dataset: Arc::clone(&ds),
            meshes: Arc::clone(&meshes),
            state: st,
            preview: true,
        });
        if let Some(u) = p.latest() {
            // Images never go back to an older view, and full-resolution images only
            // come for the newest one.
            assert!(u.generation >= seen_generation);
            assert!(u.generation <= last_generation);
            if u.level == Level::Full {
                assert_eq!(u.generation, last_generation);
            }
            seen_generation = u.generation;
        }
    }
    let updates = run_to_completion(&p, last_generation);
    assert!(updates
        .windows(2)
        .all(|w| w[0].generation <= w[1].generation));
    assert!(updates
        .iter()
        .filter(|u| u.level == Level::Full)
        .all(|u| u.generation == last_generation));
    assert!(p.wait_complete(last_generation, Duration::from_secs(10)));
    assert!(notified.load(Ordering::Relaxed) > 0, "never notified");
    let mut want_state = base.clone();
    want_state.spp = 8;
    want_state.camera.eye[0] += 19.0 * 0.5;
    let want = render(&Scene::new(ds.volume(), &want_state, &meshes).expect("scene"));
    assert_eq!(*updates.last().expect("update").rgb, want.rgb);
    // Nothing else arrives for a finished job.
    std::thread::sleep(Duration::from_millis(50));
    assert!(p.latest().is_none());
    assert!(p.idle());
}

#[test]
fn cancelled_frame_stops_within_one_tile_row() {
    let ds = dataset();
    let meshes = Meshes::empty();
    let mut st = state(&ds);
    st.width = 64;
    st.height = 64;
    st.spp = 64; // slow rows, so the canceller is always much faster than a row
    st.mode = Mode::Dvr;
    st.strategy = Strategy::Uniform;
    st.step = 0.05;
    let scene = Scene::new(ds.volume(), &st, &meshes).expect("scene");
    let renderer = Renderer::new(Some(1)).expect("pool");
    let all = tiles(st.width, st.height);
    let cancel = CancelToken::new();
    let delivered = Mutex::new(Vec::new());
    let sink = |r: TileResult| delivered.lock().expect("lock").push(r.tile);
    // Cancel while the second tile is half done (first tile: 16 rows).
    let rows_at_cancel = std::thread::scope(|s| {
        let c = cancel.clone();
        let watcher = s.spawn(move || {
            while c.rows_started() < 24 {
                std::hint::spin_loop();
            }
            c.cancel();
            c.rows_started()
        });
        let finished = renderer.render_tiles(&scene, &all, 0..st.spp, &cancel, &sink);
        assert!(!finished, "a cancelled frame reported success");
        watcher.join().expect("watcher")
    });
    let rows_after = cancel.rows_started() - rows_at_cancel;
    assert!(
        rows_after <= 1,
        "{rows_after} rows were started after the cancel (one worker)"
    );
    let delivered = delivered.into_inner().expect("lock");
    assert_eq!(
        delivered,
        vec![all[0]],
        "only the finished first tile is delivered"
    );

    // A token cancelled before the frame starts renders nothing.
    let cancel = CancelToken::new();
    cancel.cancel();
    let count = AtomicUsize::new(0);
    let sink = |_: TileResult| {
        count.fetch_add(1, Ordering::Relaxed);
    };
    assert!(!renderer.render_tiles(&scene, &all, 0..1, &cancel, &sink));
    assert_eq!(count.load(Ordering::Relaxed), 0);
    assert_eq!(cancel.rows_started(), 0);
}

#[test]
fn a_view_the_volume_cannot_render_is_reported_not_panicked() {
    let ds = dataset();
    let p = Progressive::new(ProgressiveOptions::default(), Box::new(|| {})).expect("start");
    let mut st = state(&ds);
    st.iso_field = "vorticity".into();
    let generation = p.submit(Job {
        dataset: Arc::clone(&ds),
        meshes: Arc::new(Meshes::empty()),
        state: st,
        preview: true,
    });
    assert!(!p.wait_complete(generation, Duration::from_secs(10)));
    let err = p.error().expect("an error");
    assert!(err.contains("vorticity"), "{err}");
}

/// Submits `n` previewed views of `ds` one after another, each to completion.
fn previews(p: &Progressive, ds: &Arc<Dataset>, n: usize) {
    let meshes = Arc::new(Meshes::empty());
    for i in 0..n {
        let mut st = state(ds);
        st.seed = i as u64;
        let generation = p.submit(Job {
            dataset: Arc::clone(ds),
            meshes: Arc::clone(&meshes),
            state: st,
            preview: true,
        });
        assert!(
            p.wait_complete(generation, Duration::from_secs(60)),
            "job {i}"
        );
    }
}

#[test]
fn previews_take_the_divisor_their_time_budget_allows() {
    let ds = dataset();
    let options = |preview_ms| ProgressiveOptions {
        threads: Some(2),
        preview_ms,
        min_scale: 2,
        max_scale: 5,
        ..ProgressiveOptions::default()
    };
    // No preview can take a picosecond: the coarsest divisor allowed.
    let slow = Progressive::new(options(1e-9), Box::new(|| {})).expect("start");
    previews(&slow, &ds, 3);
    assert_eq!(slow.preview_scale(), 5);
    // Every preview fits an hour: the finest.
    let fast = Progressive::new(options(3.6e6), Box::new(|| {})).expect("start");
    previews(&fast, &ds, 3);
    assert_eq!(fast.preview_scale(), 2);
}
