//! Any byte string opened as a `.qbk` must give a validated view or an error naming the
//! file, never a panic; and a view that validates must be safe to render. The viewer's
//! hot loops index the archive with `[]`, trusting `format::BrickFileView` validation for
//! every index they use, so a file that validates but panics here is a validation bug.
//!
//! The bytes are opened three times: with the checksum on and off, so that mutations of
//! the payload get past the checksum and reach bytecheck and the schema checks, and as
//! renders open files (`viewer::dataset::render_options`: the bricks, regions and tree
//! checked where the walk reads them, which must then read a damaged part as empty). A validated file is then walked the way the viewer walks it: every region,
//! its bricks, the reconstruction at its centre, point location, and a few rays per
//! sampling strategy, with small caps so that one input stays fast.
#![no_main]

use std::path::Path;

use format::{BrickFileView, OpenOptions};
use libfuzzer_sys::fuzz_target;
use viewer::sampling::{Params, Strategy, Tracer};
use viewer::transfer::{Band, Mode, PreIntegrated, Transfer};
use viewer::volume::Volume;

/// Regions walked per input (the seeds have a few hundred).
const MAX_REGIONS: usize = 4096;
/// Samples per cell width along a ray, at most, before we refuse to trace (a file with
/// a tiny cell width in a huge box is valid but would take minutes per ray, which tells
/// the fuzzer nothing).
const MAX_CELLS_ACROSS: f64 = 512.0;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.qbk");
    let checked = BrickFileView::from_bytes(path, data);
    let unchecked = BrickFileView::from_bytes_with(
        path,
        data,
        &OpenOptions {
            verify_checksum: false,
            ..OpenOptions::default()
        },
    );
    // As renders open it: the structure checked where the walk reads it.
    let on_use =
        BrickFileView::from_bytes_with(path, data, &viewer::dataset::render_options(false));
    for result in [checked, unchecked, on_use] {
        match result {
            Ok(view) => exercise(&view),
            Err(e) => {
                // The error names the file.
                assert!(e.to_string().contains("fuzz.qbk"), "{e}");
            }
        }
    }
});

fn exercise(view: &BrickFileView) {
    let file = view.file();
    // `qbricks-view info` on the same file.
    let _ = viewer::info::to_text(&viewer::info::info(view));
    let vol = match Volume::new(view) {
        Ok(v) => v,
        Err(_) => return,
    };
    let nf = vol.fields.len();
    for r in 0..vol.region_count().min(MAX_REGIONS) {
        let reg = vol.region(r);
        let _ = vol.region_brick_ids(r);
        let _ = vol.step_width(r as u32);
        let c: [f64; 3] = std::array::from_fn(|a| 0.5 * (reg.min[a] + reg.max[a]));
        let _ = vol.region_at(c);
        let _ = format::query::region_at(file, vol.to_world(c));
        for f in 0..nf {
            let _ = vol.range(r, f);
            let _ = vol.eval(r, c, f, Some(nf - 1));
            let _ = vol.eval_value(r, c, f);
            let _ = vol.shading_gradient(c, f);
            let _ = vol.sample(vol.to_world(c), f);
        }
    }
    if nf == 0 {
        // Nothing to render: the viewer refuses a field name the file does not have.
        return;
    }
    let lo = vol.bounds_min;
    let hi = vol.bounds_max;
    let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0f64, f64::max);
    let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
    // Rays from fixed points around the box through its centre, plus two through the
    // box's corners, in the local frame.
    let pad = extent.max(1.0);
    let origins: [[f64; 3]; 4] = [
        [lo[0] - pad, centre[1], centre[2]],
        [centre[0], hi[1] + pad, centre[2] + 0.25 * extent],
        [lo[0] - pad, lo[1] - pad, lo[2] - pad],
        centre,
    ];
    let ends: [[f64; 3]; 4] = [centre, centre, hi, [hi[0] + pad, lo[1], centre[2]]];
    for (o, e) in origins.iter().zip(ends.iter()) {
        let d: [f64; 3] = std::array::from_fn(|a| e[a] - o[a]);
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if !(n.is_finite() && n > 0.0) {
            continue;
        }
        let d = d.map(|x| x / n);
        let _ = format::query::ray_regions(file, vol.to_world(*o), d, 0.0, f64::INFINITY);
    }
    // Tracing costs samples per cell along the ray: only trace files whose box is a
    // bounded number of finest cells across (the seeds are, and so is every mutation of
    // their numbers that keeps the scale).
    if !(extent.is_finite() && extent / vol.finest_w <= MAX_CELLS_ACROSS) {
        return;
    }
    let field = 0;
    let (fmin, fmax) = (vol.fields[field].min as f64, vol.fields[field].max as f64);
    let iso = if (fmin + fmax).is_finite() {
        0.5 * (fmin + fmax)
    } else {
        0.0
    };
    let sigma = if (fmax - fmin).is_finite() && fmax > fmin {
        0.1 * (fmax - fmin)
    } else {
        1.0
    };
    // Mode, strategy, step, pre-integrated dvr opacity (the window's default).
    let runs = [
        (Mode::Iso, Strategy::Exact, 1.0, false),
        (Mode::Iso, Strategy::Uniform, 1.0, false),
        (Mode::Dvr, Strategy::Bisect, 1.0, false),
        (Mode::Dvr, Strategy::Uniform, 1.0, true),
    ];
    for (mode, strategy, step, preintegrated) in runs {
        for clip in [false, true] {
            let mut params = Params {
                strategy,
                step,
                tf: Transfer {
                    mode,
                    iso,
                    band: Band {
                        sigma,
                        peak_opacity: 1.6,
                        k: 2.0,
                    },
                },
                field,
                colour_field: Some(nf - 1),
                delta0: 0.5 * vol.finest_w,
                clip: None,
                preintegrated: None,
            };
            if clip {
                params.clip_to_active(&vol);
            }
            if preintegrated {
                params.preintegrated = PreIntegrated::new(&params.tf, params.delta0);
            }
            let accel = viewer::accel::Accel::new(params.accel_key());
            let mut tr = Tracer::new(&vol, &accel, params);
            for (o, e) in origins.iter().zip(ends.iter()) {
                let d: [f64; 3] = std::array::from_fn(|a| e[a] - o[a]);
                let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                if !(n.is_finite() && n > 0.0) {
                    continue;
                }
                let d = d.map(|x| x / n);
                match mode {
                    Mode::Iso => {
                        if let Some(hit) = tr.iso(*o, d, 0.0, f64::INFINITY, 0.37) {
                            let _ = vol.shading_gradient(hit.p, field);
                        }
                        let _ = tr.iso_occluded(*o, d, 0.0, 2.0 * pad + extent);
                    }
                    Mode::Dvr => {
                        let _ = tr.dvr(*o, d, 0.0, f64::INFINITY, 0.37, &mut |_, _| [1.0; 3]);
                        let _ = tr.transmittance(*o, d, 0.0, 2.0 * pad + extent);
                    }
                }
            }
        }
    }
}
