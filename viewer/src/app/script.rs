//! The window driven without a user: `--screenshot` (let the image refine, save a
//! screenshot of the whole window, exit) and `--orbit-frames` (turn the camera a full
//! circle over N frames in the real window, let it refine, report frame rates).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use eframe::egui;
use serde::Serialize;

use crate::film;
use crate::progressive::{Level, Update};

/// What to do without a user, then close the window.
#[derive(Debug, Clone)]
pub enum Script {
    /// Wait until the image is refined (or `frames` UI frames passed), save a screenshot.
    Screenshot { out: PathBuf, frames: Option<u32> },
    /// Orbit a full turn over `frames` UI frames, let the image refine, report; then
    /// save a screenshot if `screenshot` is given.
    Orbit {
        frames: u32,
        screenshot: Option<PathBuf>,
    },
}

/// What `--orbit-frames N --json` prints.
#[derive(Debug, Clone, Default, Serialize)]
pub struct OrbitReport {
    /// Median rate of new preview images shown while orbiting, per second.
    pub preview_fps: f64,
    /// Median and largest time between UI frames while the renderer works, ms.
    pub ui_frame_ms_p50: f64,
    pub ui_frame_ms_max: f64,
    /// From the last orbit input to the refined full-resolution image on screen, ms.
    pub refine_ms: f64,
    /// Full-resolution render time of the refined image, ms.
    pub full_frame_ms: f64,
    /// Preview divisor at the end of the orbit (4: a quarter of the resolution).
    pub preview_scale: u32,
    /// Median and coarsest divisor of the previews shown while orbiting.
    pub preview_scale_p50: u32,
    pub preview_scale_max: u32,
    /// How many previews shown while orbiting had each divisor (`"3": 70, "4": 2`).
    pub preview_scale_counts: std::collections::BTreeMap<u32, u32>,
    /// UI frames of the orbit and preview images shown during it.
    pub orbit_frames: u32,
    pub previews_shown: u32,
    /// Views handed to the renderer in the whole run (one per orbit frame, plus the
    /// first): more means the window changes its own view without input.
    pub jobs: u64,
    /// Render image size (the central area) in pixels.
    pub window: [u32; 2],
    pub threads: usize,
    /// From the window's start (before its file is opened) to its first UI frame, ms:
    /// how long the window was unresponsive while it opened the file.
    pub first_ui_ms: f64,
    /// From the window's start to the camera framing the surface (the orbit starts
    /// then), ms.
    pub framed_ms: f64,
}

/// What the window should do before drawing a frame.
pub(crate) enum ScriptStep {
    Nothing,
    /// Turn the camera by this many radians about the pivot.
    Orbit(f64),
}

enum Phase {
    Orbiting { frame: u32 },
    Refining { since: Instant },
    Screenshot { waited: u32, requested: bool },
    Done,
}

pub(crate) struct ScriptRunner {
    script: Script,
    /// Where the screenshot goes, if one is taken.
    screenshot: Option<PathBuf>,
    phase: Phase,
    frames_seen: u32,
    intervals_ms: Vec<f64>,
    preview_times: Vec<Instant>,
    /// The divisor of each of those previews.
    preview_scales: Vec<f64>,
    report: OrbitReport,
    started: Instant,
}

/// Longest a script may wait for the image, so a broken render cannot hang CI.
const TIMEOUT: Duration = Duration::from_secs(120);

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

impl ScriptRunner {
    pub(crate) fn new(script: Script) -> ScriptRunner {
        let phase = match &script {
            Script::Orbit { .. } => Phase::Orbiting { frame: 0 },
            Script::Screenshot { .. } => Phase::Screenshot {
                waited: 0,
                requested: false,
            },
        };
        let screenshot = match &script {
            Script::Screenshot { out, .. } => Some(out.clone()),
            Script::Orbit { screenshot, .. } => screenshot.clone(),
        };
        ScriptRunner {
            script,
            screenshot,
            phase,
            frames_seen: 0,
            intervals_ms: Vec::new(),
            preview_times: Vec::new(),
            preview_scales: Vec::new(),
            report: OrbitReport::default(),
            started: Instant::now(),
        }
    }

    pub(crate) fn report_mut(&mut self) -> Option<&mut OrbitReport> {
        matches!(self.script, Script::Orbit { .. }).then_some(&mut self.report)
    }

    /// Called at the start of a UI frame with the time since the previous one.
    pub(crate) fn before_frame(&mut self, interval: Option<Duration>) -> ScriptStep {
        self.frames_seen += 1;
        let working = matches!(self.phase, Phase::Orbiting { .. } | Phase::Refining { .. });
        if let (true, Some(d)) = (working, interval) {
            // The first interval includes window creation; count from the second frame.
            if self.frames_seen > 2 {
                self.intervals_ms.push(d.as_secs_f64() * 1e3);
            }
        }
        match (&self.phase, &self.script) {
            (Phase::Orbiting { .. }, Script::Orbit { frames, .. }) => {
                ScriptStep::Orbit(std::f64::consts::TAU / f64::from((*frames).max(1)))
            }
            _ => ScriptStep::Nothing,
        }
    }

    /// Called after the frame's UI was built. `received`: a new image was taken this
    /// frame; `shown`: the image on screen; `no_image`: the window has nothing to render
    /// (the file failed to open), so no refined image will ever come and the window as
    /// it is, with the error in its panel, is the final picture. Returns the report once
    /// done.
    pub(crate) fn after_frame(
        &mut self,
        ctx: &egui::Context,
        received: bool,
        shown: Option<&Update>,
        preview_scale: u32,
        no_image: bool,
        checked: bool,
    ) -> anyhow::Result<Option<OrbitReport>> {
        if self.started.elapsed() > TIMEOUT {
            anyhow::bail!(
                "the window did not finish its image within {} s",
                TIMEOUT.as_secs()
            );
        }
        let complete = shown.is_some_and(|u| u.complete);
        match &mut self.phase {
            Phase::Orbiting { frame } => {
                if received {
                    if let Some(Level::Preview { scale }) = shown.map(|u| u.level) {
                        self.preview_times.push(Instant::now());
                        self.preview_scales.push(f64::from(scale));
                    }
                }
                *frame += 1;
                let orbit_frames = match &self.script {
                    Script::Orbit { frames, .. } => *frames,
                    Script::Screenshot { .. } => 0,
                };
                if *frame >= orbit_frames {
                    self.report.orbit_frames = *frame;
                    self.report.preview_scale = preview_scale;
                    self.phase = Phase::Refining {
                        since: Instant::now(),
                    };
                }
            }
            Phase::Refining { since } => {
                if received && complete {
                    self.report.refine_ms = since.elapsed().as_secs_f64() * 1e3;
                    self.report.full_frame_ms = shown.map_or(0.0, |u| u.ms);
                    self.finish_report();
                    self.phase = match self.screenshot {
                        Some(_) => Phase::Screenshot {
                            waited: 0,
                            requested: false,
                        },
                        None => Phase::Done,
                    };
                }
            }
            Phase::Screenshot { waited, requested } => {
                let frames_limit = match &self.script {
                    Script::Screenshot {
                        frames: Some(n), ..
                    } => Some(*n),
                    _ => None,
                };
                *waited += 1;
                let ready = match frames_limit {
                    Some(n) => *waited >= n,
                    // Two frames, so the panel with the error has been drawn once whole.
                    None if no_image => *waited >= 2,
                    // One more frame after the refined image arrived, so it is on screen.
                    None => complete && !received,
                };
                if ready && checked && !*requested {
                    ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot(
                        egui::UserData::default(),
                    ));
                    *requested = true;
                }
                let image = ctx.input(|i| {
                    i.raw.events.iter().find_map(|e| match e {
                        egui::Event::Screenshot { image, .. } => Some(image.clone()),
                        _ => None,
                    })
                });
                if let (Some(image), Some(out)) = (image, &self.screenshot) {
                    save_screenshot(out, &image)?;
                    self.phase = Phase::Done;
                }
            }
            Phase::Done => {}
        }
        if matches!(self.phase, Phase::Done) && checked {
            return Ok(Some(self.report.clone()));
        }
        Ok(None)
    }

    fn finish_report(&mut self) {
        let mut iv = self.intervals_ms.clone();
        self.report.ui_frame_ms_max = iv.iter().copied().fold(0.0, f64::max);
        self.report.ui_frame_ms_p50 = median(&mut iv);
        let mut gaps: Vec<f64> = self
            .preview_times
            .windows(2)
            .map(|w| (w[1] - w[0]).as_secs_f64() * 1e3)
            .collect();
        let gap = median(&mut gaps);
        self.report.preview_fps = if gap > 0.0 { 1e3 / gap } else { 0.0 };
        self.report.previews_shown = self.preview_times.len() as u32;
        let mut scales = self.preview_scales.clone();
        self.report.preview_scale_max = scales.iter().copied().fold(0.0, f64::max) as u32;
        self.report.preview_scale_p50 = median(&mut scales) as u32;
        self.report.preview_scale_counts.clear();
        for &s in &self.preview_scales {
            *self
                .report
                .preview_scale_counts
                .entry(s as u32)
                .or_default() += 1;
        }
    }
}

/// Writes a window screenshot as a PNG (atomically, like every image we write).
fn save_screenshot(path: &std::path::Path, image: &egui::ColorImage) -> anyhow::Result<()> {
    let [w, h] = image.size;
    let rgb: Vec<[f32; 3]> = image
        .pixels
        .iter()
        .map(|c| [c.r(), c.g(), c.b()].map(|v| f32::from(v) / 255.0))
        .collect();
    film::save_png(path, w as u32, h as u32, &rgb)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs one UI frame of `runner` and returns its result and whether it asked for a
    /// screenshot.
    fn frame(
        runner: &mut ScriptRunner,
        ctx: &egui::Context,
        events: Vec<egui::Event>,
        no_image: bool,
        checked: bool,
    ) -> (anyhow::Result<Option<OrbitReport>>, bool) {
        let mut result = None;
        let input = egui::RawInput {
            events,
            ..egui::RawInput::default()
        };
        let out = ctx.run_ui(input, |ui| {
            result = Some(runner.after_frame(ui.ctx(), false, None, 1, no_image, checked));
        });
        let asked = out.viewport_output.values().any(|v| {
            v.commands
                .iter()
                .any(|c| matches!(c, egui::ViewportCommand::Screenshot(_)))
        });
        (result.expect("frame ran"), asked)
    }

    #[test]
    fn a_window_without_an_image_saves_its_screenshot_without_waiting_for_one() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("shot.png");
        let mut runner = ScriptRunner::new(Script::Screenshot {
            out: out.clone(),
            frames: None,
        });
        let ctx = egui::Context::default();
        let (first, asked) = frame(&mut runner, &ctx, Vec::new(), true, true);
        assert!(matches!(first, Ok(None)) && !asked);
        let (second, asked) = frame(&mut runner, &ctx, Vec::new(), true, true);
        assert!(matches!(second, Ok(None)) && asked);
        let image = egui::ColorImage::new([4, 3], vec![egui::Color32::RED; 12]);
        let shot = egui::Event::Screenshot {
            viewport_id: egui::ViewportId::ROOT,
            user_data: egui::UserData::default(),
            image: std::sync::Arc::new(image),
        };
        let (third, _) = frame(&mut runner, &ctx, vec![shot], true, true);
        assert!(matches!(third, Ok(Some(_))));
        let saved = image::open(&out).expect("a PNG").to_rgb8();
        assert_eq!(saved.dimensions(), (4, 3));
    }

    #[test]
    fn a_window_with_an_image_coming_waits_for_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut runner = ScriptRunner::new(Script::Screenshot {
            out: dir.path().join("shot.png"),
            frames: None,
        });
        let ctx = egui::Context::default();
        for _ in 0..5 {
            let (result, asked) = frame(&mut runner, &ctx, Vec::new(), false, true);
            assert!(matches!(result, Ok(None)) && !asked);
        }
    }

    /// While the file's checksum is being verified (beside the first frames) a script asks
    /// for no screenshot and reports nothing, however long it waits; once it passed, it
    /// goes on as it would have.
    #[test]
    fn a_script_writes_nothing_before_the_checksum_passed() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("shot.png");
        let mut runner = ScriptRunner::new(Script::Screenshot {
            out: out.clone(),
            frames: None,
        });
        let ctx = egui::Context::default();
        for _ in 0..5 {
            let (result, asked) = frame(&mut runner, &ctx, Vec::new(), true, false);
            assert!(matches!(result, Ok(None)) && !asked);
        }
        let (result, asked) = frame(&mut runner, &ctx, Vec::new(), true, true);
        assert!(matches!(result, Ok(None)) && asked);
        assert!(!out.exists());
    }
}
