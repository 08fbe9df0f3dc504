//! What the overlays add to a picture: `overlay::annotate` (legend, axes, outline box and
//! scale bar, the box depth-tested) on a finished 8-bit image, at 640×480, 1024² and 4K.
//! Run: `cargo bench -p qbricks-viewer --bench overlay`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use qbricks_viewer::camera::{Camera, Projection};
use qbricks_viewer::overlay;
use qbricks_viewer::view_state::ViewState;
use qbricks_viewer::volume::Volume;

fn overlays(c: &mut Criterion) {
    let file = qbricks_viewer::testvol::nested(8, [0.0; 3], &[("q", &|p: [f64; 3]| p[0])], 8);
    let view = qbricks_viewer::testvol::open(&file).expect("open");
    let vol = Volume::new(&view).expect("volume");
    let bounds = overlay::data_bounds(&vol);
    let mut state = ViewState::default_for_volume(&vol);
    state.camera = Camera {
        eye: [30.0, -20.0, 25.0],
        look_at: [8.0, 8.0, 8.0],
        up: [0.0, 0.0, 1.0],
        projection: Projection::Perspective { fov_deg: 40.0 },
    };
    let mut group = c.benchmark_group("overlay::annotate");
    for (w, h) in [(640u32, 480u32), (1024, 1024), (3840, 2160)] {
        let n = (w * h) as usize;
        // A surface at distance 30 everywhere: every outline pixel is depth-tested.
        let depth = vec![30.0f32; n];
        let base = vec![40u8; 3 * n];
        group.bench_with_input(
            BenchmarkId::from_parameter(format!("{w}x{h}")),
            &(),
            |b, _| {
                b.iter_batched_ref(
                    || base.clone(),
                    |px| overlay::annotate(px, w, h, &state, Some(bounds), Some(&depth), Some("t")),
                    criterion::BatchSize::LargeInput,
                )
            },
        );
    }
    group.finish();
}

criterion_group! {
    name = benches;
    // No plots: criterion's charts need system fonts a headless machine may lack.
    config = Criterion::default().without_plots();
    targets = overlays
}
criterion_main!(benches);
