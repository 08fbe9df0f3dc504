//! Speed against error: render one view with every sampling strategy at several steps and
//! compare each image with a reference rendered far more finely.
//!
//! Users choose a strategy and a step by trading time for accuracy; this module measures
//! both on their own file and view. The reference is `uniform` at a tiny step (0.01 cell by
//! default) with the view's samples per pixel (jittered when more than one), so it is as close to the exact image
//! of the reconstructed field as the renderer can get; each run then reports its time
//! (median of repeats), the work per ray, the colour error (RMSE, PSNR) and the pixels whose
//! surface it missed or invented compared with the reference. The error is measured against
//! the reconstruction, not the analytic flow: what the data model costs is `accuracy`'s
//! question.

use std::path::Path;
use std::time::Instant;

use serde::Serialize;

use crate::chart::{Line, LogLogChart, PlotError};
use viewer::mesh::Meshes;
use viewer::render::{Frame, Renderer, Scene};
use viewer::sampling::Strategy;
use viewer::transfer::Mode;
use viewer::view_state::ViewState;
use viewer::volume::{Volume, VolumeError};

/// Step sizes (in local cell widths) every strategy is run at.
pub(crate) const STEPS: [f64; 5] = [2.0, 1.0, 0.5, 0.25, 0.1];

/// How the benchmark is run.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Step of the `uniform` reference, cells.
    pub reference_step: f64,
    /// Samples per pixel of the reference; `None`: the view's own, so the reference casts
    /// the same camera rays as every run and the error is the sampling along them. With
    /// more samples than the runs the error is dominated by anti-aliasing (at 160×100 on
    /// the sample, 8 jittered spp against 1 put every strategy and step at the same RMSE
    /// and a 10 % miss rate), which hides the differences the benchmark is for.
    pub reference_spp: Option<u32>,
    /// Frames per run; the reported time is their median.
    pub repeat: u32,
    /// Steps, cells.
    pub steps: Vec<f64>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            reference_step: 0.01,
            reference_spp: None,
            repeat: 3,
            steps: STEPS.to_vec(),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Volume(#[from] VolumeError),
    #[error(transparent)]
    Field(#[from] viewer::fields::UnknownField),
    /// The reference step breaks the bounds every view's step has (the same rule as
    /// `render --step`).
    #[error("--reference-step: {0}")]
    ReferenceStep(viewer::view_state::InvalidViewState),
    /// Some reference rays stopped before their end (a step too small for the length of
    /// a ray's segments): every error measured against it would be wrong.
    #[error(
        "--reference-step {step}: the reference was cut short on {segments} ray segment(s) \
         (too many samples per segment at this step); use a larger --reference-step"
    )]
    ReferenceTruncated { step: f64, segments: u64 },
    #[error("steps must be positive numbers")]
    Steps,
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// One strategy at one step.
#[derive(Debug, Clone, Serialize)]
pub struct Run {
    pub strategy: &'static str,
    /// Step, cells.
    pub step: f64,
    /// Wall time of one frame, median over the repeats, ms.
    pub ms: f64,
    /// Reconstructions per ray (camera and shadow rays).
    pub samples_per_ray: f64,
    /// Root mean square error of the linear RGB values (clamped to 0..=1) against the
    /// reference.
    pub rmse: f64,
    /// 10·log10(1/MSE), dB; `null` when the image equals the reference.
    pub psnr: Option<f64>,
    /// Of the pixels where the reference shows the surface (iso) or opacity (dvr), the
    /// share where this run does not.
    pub miss_rate: f64,
    /// Of the pixels where the reference shows background, the share where this run shows
    /// a surface.
    pub false_hit_rate: f64,
    pub mode: &'static str,
    /// Dvr opacity pre-integrated between samples (dvr runs come both ways).
    pub preintegrated: bool,
    /// Whether this is the view state's own strategy and step.
    pub is_default: bool,
    /// Whether no other run is both faster and more accurate.
    pub pareto: bool,
}

/// The reference image and which pixels show something in it.
#[derive(Debug, Clone)]
pub struct Reference {
    pub frame: Frame,
    pub ms: f64,
    pub spp: u32,
}

/// Whether a pixel shows the surface: at least half of its samples hit.
fn shows(hit_samples: u32, spp: u32) -> bool {
    2 * hit_samples >= spp.max(1) && hit_samples > 0
}

/// Strategies that make sense in `mode`: `exact` only finds iso-surfaces (in dvr it would
/// sample as `uniform` or `bisect`, a duplicate run).
pub(crate) fn strategies(mode: Mode) -> Vec<Strategy> {
    Strategy::ALL
        .into_iter()
        .filter(|s| mode == Mode::Iso || *s != Strategy::Exact)
        .collect()
}

/// Every (strategy, step, pre-integrated) run of a benchmark of `state`: in dvr mode each
/// strategy and step both with and without pre-integration, to show what it buys.
pub fn plan(state: &ViewState, opts: &BenchOptions) -> Vec<(Strategy, f64, bool)> {
    let pre: &[bool] = match state.mode {
        Mode::Iso => &[false],
        Mode::Dvr => &[false, true],
    };
    strategies(state.mode)
        .into_iter()
        .flat_map(|s| {
            pre.iter()
                .flat_map(move |&p| opts.steps.iter().map(move |&st| (s, st, p)))
        })
        .collect()
}

fn render_median(
    renderer: &Renderer,
    vol: &Volume,
    state: &ViewState,
    meshes: &Meshes,
    repeat: u32,
) -> Result<(Frame, f64), BenchError> {
    let scene = Scene::new(vol, state, meshes)?;
    let timed = || {
        let t = Instant::now();
        let f = renderer.render(&scene);
        (f, t.elapsed().as_secs_f64() * 1e3)
    };
    // At least one render, so there always is a frame; the last one is kept.
    let (mut frame, ms) = timed();
    let mut times = vec![ms];
    for _ in 1..repeat {
        let (f, ms) = timed();
        times.push(ms);
        frame = f;
    }
    times.sort_by(f64::total_cmp);
    Ok((frame, times[times.len() / 2]))
}

/// Renders the reference: `uniform` at `opts.reference_step` with `opts.reference_spp`
/// samples per pixel (default: the view's), once.
pub(crate) fn reference(
    renderer: &Renderer,
    vol: &Volume,
    state: &ViewState,
    meshes: &Meshes,
    opts: &BenchOptions,
) -> Result<Reference, BenchError> {
    let mut st = state.clone();
    st.strategy = Strategy::Uniform;
    st.step = opts.reference_step;
    // Point-sampled: at the reference step both ways agree, and the reference must not
    // depend on the method it judges.
    st.preintegrated = false;
    st.spp = opts.reference_spp.unwrap_or(state.spp).max(1);
    st.validate().map_err(BenchError::ReferenceStep)?;
    let (frame, ms) = render_median(renderer, vol, &st, meshes, 1)?;
    if frame.stats.truncated_segments > 0 {
        return Err(BenchError::ReferenceTruncated {
            step: opts.reference_step,
            segments: frame.stats.truncated_segments,
        });
    }
    Ok(Reference {
        frame,
        ms,
        spp: st.spp,
    })
}

/// Colour and coverage differences of `frame` (rendered with `spp` samples per pixel)
/// against the reference: (rmse, psnr, miss rate, false-hit rate).
pub(crate) fn compare(
    reference: &Reference,
    frame: &Frame,
    spp: u32,
) -> (f64, Option<f64>, f64, f64) {
    let r = &reference.frame;
    let n = r.rgb.len().min(frame.rgb.len());
    let mut se = 0.0f64;
    for (a, b) in r.rgb[..n].iter().zip(&frame.rgb[..n]) {
        for c in 0..3 {
            let d = f64::from(a[c].clamp(0.0, 1.0)) - f64::from(b[c].clamp(0.0, 1.0));
            se += d * d;
        }
    }
    let mse = se / (3 * n.max(1)) as f64;
    let psnr = (mse > 0.0).then(|| -10.0 * mse.log10());
    let (mut surf, mut bg, mut miss, mut false_hit) = (0u64, 0u64, 0u64, 0u64);
    for i in 0..n.min(r.pixel_hits.len()).min(frame.pixel_hits.len()) {
        let want = shows(r.pixel_hits[i], reference.spp);
        let got = shows(frame.pixel_hits[i], spp);
        if want {
            surf += 1;
            miss += u64::from(!got);
        } else {
            bg += 1;
            false_hit += u64::from(got);
        }
    }
    let rate = |k: u64, of: u64| if of == 0 { 0.0 } else { k as f64 / of as f64 };
    (mse.sqrt(), psnr, rate(miss, surf), rate(false_hit, bg))
}

/// Renders `strategy` at `step` and compares it with the reference.
#[allow(clippy::too_many_arguments)]
pub fn run(
    renderer: &Renderer,
    vol: &Volume,
    state: &ViewState,
    meshes: &Meshes,
    reference: &Reference,
    strategy: Strategy,
    step: f64,
    preintegrated: bool,
    repeat: u32,
) -> Result<Run, BenchError> {
    let mut st = state.clone();
    st.strategy = strategy;
    st.step = step;
    st.preintegrated = preintegrated;
    let (frame, ms) = render_median(renderer, vol, &st, meshes, repeat)?;
    let (rmse, psnr, miss_rate, false_hit_rate) = compare(reference, &frame, st.spp);
    Ok(Run {
        strategy: st.effective_strategy().as_str(),
        step,
        ms,
        samples_per_ray: frame.stats.samples as f64 / frame.rays.max(1) as f64,
        rmse,
        psnr,
        miss_rate,
        false_hit_rate,
        mode: st.mode.as_str(),
        preintegrated,
        is_default: state.effective_strategy() == st.effective_strategy()
            && state.preintegrated == preintegrated
            && (state.step - step).abs() <= 1e-12 * step.abs().max(1.0),
        pareto: false,
    })
}

/// Marks the runs no other run beats on both time and error (ties count as not beaten).
pub(crate) fn mark_pareto(runs: &mut [Run]) {
    let key: Vec<(f64, f64)> = runs.iter().map(|r| (r.ms, r.rmse)).collect();
    for (i, r) in runs.iter_mut().enumerate() {
        let (t, e) = key[i];
        r.pareto = !key
            .iter()
            .enumerate()
            .any(|(j, &(tj, ej))| j != i && tj <= t && ej <= e && (tj < t || ej < e));
    }
}

/// Runs the whole benchmark: the reference, then every pair of [`plan`], calling
/// `progress` after each render with a short label of what was done.
pub fn bench(
    renderer: &Renderer,
    vol: &Volume,
    state: &ViewState,
    meshes: &Meshes,
    opts: &BenchOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<(Reference, Vec<Run>), BenchError> {
    if opts.steps.iter().any(|s| !(*s > 0.0 && s.is_finite())) {
        return Err(BenchError::Steps);
    }
    let reference = reference(renderer, vol, state, meshes, opts)?;
    progress("reference");
    let mut runs = Vec::new();
    for (strategy, step, pre) in plan(state, opts) {
        runs.push(run(
            renderer,
            vol,
            state,
            meshes,
            &reference,
            strategy,
            step,
            pre,
            opts.repeat,
        )?);
        progress(&format!(
            "{strategy} {step}{}",
            if pre { " pre-integrated" } else { "" }
        ));
    }
    mark_pareto(&mut runs);
    Ok((reference, runs))
}

/// Colours of the strategies' lines (uniform, paper, bisect, exact; lighter when
/// pre-integrated).
fn strategy_colour(name: &str) -> [u8; 3] {
    match name {
        "uniform" => [31, 119, 180],
        "paper" => [255, 127, 14],
        "bisect" => [44, 160, 44],
        "uniform+pre" => [120, 180, 230],
        "paper+pre" => [250, 190, 120],
        "bisect+pre" => [130, 210, 130],
        _ => [214, 39, 40],
    }
}

/// Name of a run's line in the plot.
fn line_name(r: &Run) -> String {
    if r.preintegrated {
        format!("{}+pre", r.strategy)
    } else {
        r.strategy.to_string()
    }
}

/// RMSE against ms per frame, both axes logarithmic, one line per strategy through its
/// steps; the view's default run is circled.
pub(crate) fn chart(runs: &[Run], title: &str) -> LogLogChart {
    let mut names: Vec<String> = Vec::new();
    for r in runs {
        let n = line_name(r);
        if !names.contains(&n) {
            names.push(n);
        }
    }
    let lines = names
        .into_iter()
        .map(|name| {
            // In step order (coarse to fine), so each line follows one strategy's steps.
            let mut steps: Vec<&Run> = runs.iter().filter(|r| line_name(r) == name).collect();
            steps.sort_by(|a, b| b.step.total_cmp(&a.step));
            Line {
                colour: strategy_colour(&name),
                points: steps.iter().map(|r| (r.ms, r.rmse)).collect(),
                name,
            }
        })
        .collect();
    LogLogChart {
        title: title.to_string(),
        x_desc: "ms per frame",
        y_desc: "RMSE vs reference",
        x_label: |v| format!("{v:.0}"),
        lines,
        rings: runs
            .iter()
            .filter(|r| r.is_default)
            .map(|r| (r.ms, r.rmse))
            .collect(),
        empty_range: [(1.0, 10.0), (1e-3, 1e-1)],
        pad: 1.3,
    }
}

/// Writes [`chart`] to `path` atomically, 900×600 pixels.
pub fn save_plot(path: &Path, runs: &[Run], title: &str) -> Result<(), BenchError> {
    Ok(chart(runs, title).save(path, (900, 600))?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use viewer::sampling::Stats;

    fn frame(rgb: Vec<[f32; 3]>, hits: Vec<u32>) -> Frame {
        Frame {
            width: rgb.len() as u32,
            height: 1,
            depth: vec![f32::INFINITY; rgb.len()],
            surface_values: vec![f32::NAN; rgb.len()],
            rgb,
            pixel_hits: hits,
            stats: Stats::default(),
            rays: 0,
            hits: 0,
        }
    }

    #[test]
    fn compare_counts_misses_and_false_hits() {
        let reference = Reference {
            frame: frame(
                vec![[1.0; 3], [1.0; 3], [0.0; 3], [0.0; 3]],
                vec![4, 3, 0, 1],
            ),
            ms: 0.0,
            spp: 4,
        };
        // Pixel 0 kept, pixel 1 missed, pixel 2 invented, pixel 3 background in both.
        let got = frame(
            vec![[1.0; 3], [0.0; 3], [0.5; 3], [0.0; 3]],
            vec![1, 0, 1, 0],
        );
        let (rmse, psnr, miss, false_hit) = compare(&reference, &got, 1);
        assert_eq!(miss, 0.5);
        assert_eq!(false_hit, 0.5);
        let want = ((1.0 + 0.25) / 4.0f64).sqrt();
        assert!((rmse - want).abs() < 1e-12, "{rmse} vs {want}");
        let p = psnr.expect("images differ");
        assert!((p - (-10.0 * (want * want).log10())).abs() < 1e-9);
        let (rmse, psnr, ..) = compare(&reference, &reference.frame, 4);
        assert_eq!((rmse, psnr), (0.0, None));
    }

    #[test]
    fn pareto_front_drops_dominated_runs() {
        let mk = |ms, rmse| Run {
            strategy: "uniform",
            step: 1.0,
            ms,
            samples_per_ray: 0.0,
            rmse,
            psnr: None,
            miss_rate: 0.0,
            false_hit_rate: 0.0,
            mode: "iso",
            preintegrated: false,
            is_default: false,
            pareto: false,
        };
        let mut runs = vec![mk(1.0, 0.5), mk(2.0, 0.1), mk(3.0, 0.2), mk(2.0, 0.1)];
        mark_pareto(&mut runs);
        let front: Vec<bool> = runs.iter().map(|r| r.pareto).collect();
        assert_eq!(front, [true, true, false, true]);
    }

    #[test]
    fn plot_is_a_png_of_the_requested_size() {
        let mk = |s: &'static str, ms, rmse| Run {
            strategy: s,
            step: 1.0,
            ms,
            samples_per_ray: 1.0,
            rmse,
            psnr: Some(20.0),
            miss_rate: 0.0,
            false_hit_rate: 0.0,
            mode: "iso",
            preintegrated: false,
            is_default: s == "exact",
            pareto: false,
        };
        let runs = [
            mk("uniform", 3.0, 0.1),
            mk("uniform", 9.0, 0.02),
            mk("exact", 5.0, 0.01),
        ];
        let png = chart(&runs, "test").png((320, 200)).expect("plot");
        let img = image::load_from_memory(&png).expect("decodes").to_rgb8();
        assert_eq!(img.dimensions(), (320, 200));
        // Something besides the white background was drawn.
        assert!(img.pixels().any(|p| p.0 != [255, 255, 255]));
    }

    #[test]
    fn exact_only_in_iso_mode() {
        assert!(strategies(Mode::Iso).contains(&Strategy::Exact));
        assert!(!strategies(Mode::Dvr).contains(&Strategy::Exact));
    }
}
