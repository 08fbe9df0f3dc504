//! Q accuracy of the bake on the synthetic sphere wake (nested boxes, exact Q known), and
//! the measurements reported for the bake issue (`--ignored`).
//!
//! Measure: `cargo test --release -p qbricks-lab --test flows wake:: -- --ignored --nocapture`

use std::collections::HashMap;

use crate::common::bake::{cells, field, sample, Cell};
use format::BrickFile;
use lab::analytic::{Flow, Wake};
use lab::synth::scene_grids;
use qbricks_preprocess::bake::{bake, BakeOptions};
use qbricks_preprocess::derive::Stencil;
use qbricks_preprocess::grid::AnyGrid;

fn baked(n0: u32, levels: u32, stencil: Stencil) -> BrickFile {
    let grids: Vec<AnyGrid> = scene_grids("wake", n0, levels)
        .expect("synth")
        .into_iter()
        .map(AnyGrid::Vec3s)
        .collect();
    let opts = BakeOptions {
        stencil,
        ..BakeOptions::default()
    };
    bake(grids, &opts).expect("bake").0
}

/// Cells of the wake where Q is smooth: away from the sphere surface, where the potential
/// flow jumps to zero velocity inside the sphere.
fn smooth(w: &Wake, p: [f64; 3], width: f64) -> bool {
    let d = (0..3)
        .map(|a| (p[a] - w.sphere_centre[a]).powi(2))
        .sum::<f64>()
        .sqrt();
    (d - w.sphere_radius).abs() > 3.0 * width
}

struct Errors {
    max: f64,
    rms: f64,
    p99: f64,
}

/// Errors over every `stride`-th leaf cell (the exact wake Q costs a sum over all vortex
/// particles, so the lean test samples).
fn q_errors(file: &BrickFile, flow: &Wake, stride: usize) -> Errors {
    let q = field(file, "q");
    let cs: Vec<Cell> = cells(file, q)
        .into_iter()
        .step_by(stride)
        .filter(|c| smooth(flow, c.centre, c.width))
        .collect();
    let mut exact: Vec<f64> = cs.iter().map(|c| flow.q(c.centre).abs()).collect();
    let (mut max, mut sum) = (0.0f64, 0.0);
    for c in &cs {
        let e = (c.value as f64 - flow.q(c.centre)).abs();
        max = max.max(e);
        sum += e * e;
    }
    exact.sort_by(f64::total_cmp);
    let p99 = exact[(exact.len() as f64 * 0.99) as usize];
    Errors {
        max,
        rms: (sum / cs.len() as f64).sqrt(),
        p99,
    }
}

/// Largest jump of Q across a level boundary beyond the exact change, over pairs of a leaf
/// cell and the coarser leaf cell across its face: `stored` compares the two cell values,
/// `reconstructed` the basis-method reconstruction at the fine cell centre and one fine
/// width across the face. Both relative to `p99`.
fn level_jumps(file: &BrickFile, flow: &Wake, p99: f64) -> (f64, f64, usize) {
    let q = field(file, "q");
    let cs = cells(file, q);
    let nlev = file.levels.len();
    // Lattice of each level from any of its cells.
    let mut anchor = vec![None; nlev];
    let mut maps: Vec<HashMap<[i64; 3], f32>> = vec![HashMap::new(); nlev];
    for c in &cs {
        let o = *anchor[c.level as usize].get_or_insert(c.centre);
        let key = [0, 1, 2].map(|a| ((c.centre[a] - o[a]) / c.width).round() as i64);
        maps[c.level as usize].insert(key, c.value);
    }
    let key_of = |l: usize, p: [f64; 3]| -> Option<[i64; 3]> {
        let o: [f64; 3] = anchor[l]?;
        let w = file.levels[l].cell_width;
        Some([0, 1, 2].map(|a| ((p[a] - o[a]) / w).round() as i64))
    };
    let (mut stored, mut recon, mut pairs) = (0.0f64, 0.0f64, 0usize);
    for c in &cs {
        let l = c.level as usize;
        if !smooth(flow, c.centre, 2.0 * c.width) {
            continue;
        }
        for a in 0..3 {
            for d in [-1.0, 1.0] {
                let mut p = c.centre;
                p[a] += d * c.width;
                if key_of(l, p).is_some_and(|k| maps[l].contains_key(&k)) {
                    continue;
                }
                let Some((m, qc)) = (l + 1..nlev).find_map(|m| {
                    let k = key_of(m, p)?;
                    maps[m].get(&k).map(|&v| (m, v))
                }) else {
                    continue;
                };
                let wm = file.levels[m].cell_width;
                let o = anchor[m].unwrap_or([0.0; 3]);
                let k = key_of(m, p).unwrap_or([0; 3]);
                let cc = [0, 1, 2].map(|i| o[i] + k[i] as f64 * wm);
                let ds = (qc - c.value) as f64 - (flow.q(cc) - flow.q(c.centre));
                stored = stored.max(ds.abs());
                if let (Some(b0), Some(b1)) = (sample(file, q, c.centre), sample(file, q, p)) {
                    let dr = (b1 - b0) - (flow.q(p) - flow.q(c.centre));
                    recon = recon.max(dr.abs());
                }
                pairs += 1;
            }
        }
    }
    (stored / p99, recon / p99, pairs)
}

/// Error at leaf-cell centres (away from the sphere surface) shrinks towards second order.
/// At n0 32 → 64 the finest cells are still 0.8σ → 0.4σ of the ring cores (σ = 0.08), so
/// the ratio is pre-asymptotic (measured: RMS 2.9, max 2.2; at 64 → 128: 3.75 and 3.3);
/// the clean second-order check on a smooth flow is in `bake_pipeline`.
#[test]
fn wake_q_error_shrinks_towards_second_order() {
    let flow = Wake::sample_scene();
    let e1 = q_errors(&baked(32, 3, Stencil::Central), &flow, 1);
    let e2 = q_errors(&baked(64, 3, Stencil::Central), &flow, 7);
    let (rmax, rrms) = (e1.max / e2.max, e1.rms / e2.rms);
    eprintln!(
        "n0 32: max {:.3e} rms {:.3e}; n0 64: max {:.3e} rms {:.3e}; ratios {rmax:.2} {rrms:.2}",
        e1.max, e1.rms, e2.max, e2.rms
    );
    assert!(rrms > 2.5, "RMS error ratio {rrms}");
    assert!(rmax > 1.8, "max error ratio {rmax}");
}

#[test]
#[ignore = "measurement: prints Q errors and level jumps at three resolutions"]
fn measure_q_error_and_level_jumps() {
    let flow = Wake::sample_scene();
    println!("stencil      n0  levels  cells     max/p99    rms/p99    jump_stored/p99  jump_recon/p99  pairs");
    for stencil in [Stencil::Central, Stencil::CrossLevel] {
        for n0 in [32, 64, 128] {
            let file = baked(n0, 3, stencil);
            let e = q_errors(&file, &flow, 1);
            let (js, jr, pairs) = level_jumps(&file, &flow, e.p99);
            println!(
                "{:<11} {n0:>4} {:>6} {:>9} {:>10.4} {:>10.5} {:>15.4} {:>15.4} {pairs:>7}",
                format!("{stencil:?}"),
                3,
                file.fields[0].values.len(),
                e.max / e.p99,
                e.rms / e.p99,
                js,
                jr
            );
        }
    }
}
