//! `qbricks-view render 'out/frame_####.qbk' -o 'png/frame_####.png' [--frames A..B]`: every
//! frame with one view state and the sequence's fixed field ranges, one progress bar; a
//! frame that fails is named and the others go on. Which frames take their own iso value,
//! and where the one camera looks, is `qbricks_viewer::sequence_defaults`'s rule: this
//! file only says on stderr what it chose.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use files::output::QuietStdout;
use format::sequence::{gaps, FramePattern};
use qbricks_viewer::dataset::Dataset;
use qbricks_viewer::film;
use qbricks_viewer::mesh::Meshes;
use qbricks_viewer::overlay::{self, file_title};
use qbricks_viewer::render::{FrameReport, Renderer, Scene};
use qbricks_viewer::sequence::{self, output_pattern, RangeSource};
use qbricks_viewer::sequence_defaults::{self as defaults, FrameIso, Framed, IsoRule};
use qbricks_viewer::view_state::ViewState;
use ranks::Ranks;
use serde::{Deserialize, Serialize};

use crate::render::{check_files, check_frame_memory, fit_visible, render_frame, Args};

/// One line of `--json` per frame: the single-frame report, or the error.
#[derive(Serialize)]
struct FrameLine {
    frame: u64,
    file: String,
    output: String,
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    report: Option<FrameReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

/// Renders every frame of a sequence (in an MPI run, this rank's share; rank 0 reports).
pub fn run(args: &Args, path: &Path, pattern: FramePattern, ranks: &Ranks) -> anyhow::Result<()> {
    let Prepared {
        state,
        frames,
        own,
        out_pattern,
        meshes,
        renderer,
    } = ranks.agree(prepare(args, path, &pattern, ranks.is_root()))?;
    let shown = path.display().to_string();
    // This rank's frames, balanced by file size (all of them without MPI).
    let mine = ranks.share_files(frames.iter().map(|(_, p)| p.as_path()));
    // In a parallel run the ranks' bars would tear each other: lines only.
    let target = match ranks.is_parallel() {
        false => indicatif::ProgressDrawTarget::stderr(),
        true => indicatif::ProgressDrawTarget::hidden(),
    };
    let bar = indicatif::ProgressBar::with_draw_target(Some(mine.len() as u64), target);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{elapsed:>4} [{bar:30}] {pos}/{len} frames ({per_sec}, eta {eta}) {msg}",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    let mut stdout = QuietStdout::new();
    let mut done = Vec::new();
    for &i in &mine {
        let (frame, input) = &frames[i];
        bar.set_message(format!("frame {frame}"));
        let out = out_pattern.path(*frame);
        let own_iso = own.iter().find(|o| o.frame == *frame);
        let result = render_one(
            args,
            (*frame, input),
            &out,
            (&state, own_iso),
            &meshes,
            &renderer,
        );
        let line = FrameLine {
            frame: *frame,
            file: input.display().to_string(),
            output: out.display().to_string(),
            report: result.as_ref().ok().cloned(),
            error: result.as_ref().err().map(|e| format!("{e:#}")),
        };
        if let Err(e) = &result {
            // Errors name the file they are about (the frame, or its image).
            let msg = format!("qbricks-view: {e:#}");
            // A bar that does not draw (stderr not a terminal) drops its lines.
            if bar.is_hidden() {
                eprintln!("{msg}");
            } else {
                bar.println(msg);
            }
        }
        let json = serde_json::to_string(&line)?;
        // Alone, each frame's line as soon as it is rendered.
        if args.json && !ranks.is_parallel() {
            writeln!(stdout, "{json}")?;
        }
        done.push(FrameDone {
            frame: *frame,
            json,
            failed: result.is_err().then(|| input.display().to_string()),
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    // Every rank's frames at rank 0, which reports them in frame order.
    let Some(mut done) = ranks.gather(&done)? else {
        return Ok(());
    };
    done.sort_by_key(|d| d.frame);
    if args.json && ranks.is_parallel() {
        for d in &done {
            writeln!(stdout, "{}", d.json)?;
        }
    }
    let failed: Vec<&str> = done.iter().filter_map(|d| d.failed.as_deref()).collect();
    // The state only for a run that succeeded: nothing is written when a run fails.
    if let (Some(p), true) = (&args.save_state, failed.is_empty()) {
        state.save(p).with_context(|| "--save-state".to_string())?;
    }
    if !failed.is_empty() {
        bail!(
            "{shown}: {} of {} frames failed: {}",
            failed.len(),
            frames.len(),
            failed.join(", ")
        );
    }
    Ok(())
}

/// One rendered frame as the rank that rendered it reports it to rank 0: its `--json`
/// line, and its file when it failed.
#[derive(Serialize, Deserialize)]
struct FrameDone {
    frame: u64,
    json: String,
    failed: Option<String>,
}

/// Opens, renders and writes one frame (the image atomically, as a single render does),
/// with its own iso value when it has one.
fn render_one(
    args: &Args,
    (number, input): (u64, &Path),
    out: &Path,
    (state, own): (&ViewState, Option<&FrameIso>),
    meshes: &Meshes,
    renderer: &Renderer,
) -> anyhow::Result<FrameReport> {
    if !input.exists() {
        bail!("{}: no such file", input.display());
    }
    // The checksum is verified beside the frame (see `render::run`), before it is written.
    let options = qbricks_viewer::dataset::render_options(false);
    let data = Dataset::open_with(input, &options)?;
    let vol = data.volume();
    let (frame, ms, png, mine) =
        qbricks_viewer::dataset::beside_checksum(data.view(), !args.no_checksum, || {
            // `--colour-range visible` fits each frame's map to what that frame shows.
            let mine = if args.view.wants_visible_range() || own.is_some() {
                let mut mine = state.clone();
                if let Some(o) = own {
                    // A state file's band is the user's.
                    o.apply(&mut mine, args.state.is_none());
                }
                fit_visible(renderer, vol, &mut mine, meshes, &args.view)
                    .with_context(|| input.display().to_string())?;
                Some(mine)
            } else {
                None
            };
            let state = mine.as_ref().unwrap_or(state);
            let scene =
                Scene::new(vol, state, meshes).with_context(|| input.display().to_string())?;
            let (frame, ms) = render_frame(renderer, &scene, args);
            vol.check_structure(input)?;
            let title = args
                .title
                .clone()
                .unwrap_or_else(|| format!("{}  frame {number}", file_title(input)));
            let rgb8 = overlay::figure(&frame, state, vol, args.aov.is_some(), &title);
            let png = film::encode_png_rgb8(frame.width, frame.height, rgb8)
                .map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))?;
            anyhow::Ok((frame, ms, png, mine))
        })?;
    files::output::write_atomic(out, |f| f.write_all(&png))
        .with_context(|| out.display().to_string())?;
    Ok(FrameReport::new(
        &frame,
        mine.as_ref().unwrap_or(state),
        ms,
        data.open_ms,
        renderer.threads(),
    ))
}

/// What every frame of a sequence shares, checked before any frame is rendered.
struct Prepared {
    state: ViewState,
    frames: Vec<(u64, PathBuf)>,
    own: Vec<FrameIso>,
    out_pattern: FramePattern,
    meshes: Meshes,
    renderer: Renderer,
}

/// The one view state of a sequence, its frames and outputs, all checked; `tell`: say on
/// stderr what was chosen (rank 0 of a parallel run, which speaks for all).
fn prepare(
    args: &Args,
    path: &Path,
    pattern: &FramePattern,
    tell: bool,
) -> anyhow::Result<Prepared> {
    let note = |line: &str| {
        if tell {
            eprintln!("{line}");
        }
    };
    let shown = path.display().to_string();
    if args.pixel.is_some() {
        bail!("{shown}: --pixel explains one file's pixel; give one frame's file instead of the pattern");
    }
    let Some(output) = &args.output else {
        bail!("{shown}: expected -o with a frame pattern for the images (e.g. -o 'png/frame_####.png')");
    };
    let out_pattern = output_pattern(output).map_err(anyhow::Error::msg)?;
    let plan = sequence::plan(pattern, &shown, args.frames)?;
    let (frames, info) = (plan.frames, plan.info);
    // One view state for every frame: from --state, or from what the frames share (the
    // sequence's ranges), then the flags; the camera then frames the union of the frames'
    // iso surfaces (below), since the flow moves.
    let from_file = args.state.is_some();
    let mut state = match &args.state {
        Some(s) => ViewState::load(s)?,
        None => info.default_state(),
    };
    let notes = args
        .view
        .apply(&mut state, from_file)
        .map_err(anyhow::Error::msg)?;
    args.view
        .apply_fields(&mut state, &info.fields)
        .with_context(|| shown.clone())?;
    // Each frame's iso value: the shared one unless the rule gives the frame its own.
    let rule = IsoRule::new(args.view.iso.is_some(), from_file, args.iso_per_frame)?;
    let own = defaults::frame_isos(rule, &state, &info);
    // One camera for every frame, on the union of the iso surfaces of every frame of the
    // sequence (not only the rendered ones: a movie rendered in parts keeps one camera).
    let framed = (!from_file && !args.view.places_camera()).then(|| {
        let every: Vec<(u64, PathBuf)> = pattern
            .scan()
            .unwrap_or_default()
            .into_iter()
            .filter(|(f, _)| !plan.skipped.iter().any(|s| s.frame == *f))
            .collect();
        defaults::frame_surfaces(&mut state, &every, rule, &info)
    });
    state
        .validate()
        .map_err(|m| anyhow::anyhow!("view state: {m}"))?;
    // Every output against every input before any frame is rendered: the frames that
    // exist (not only those rendered: `-o 'f_1###.qbk'` names frame 1001 for frame 1), the
    // manifest, the state, the meshes.
    let existing = pattern.scan().unwrap_or_default();
    let manifest = pattern.manifest_path();
    let bricks = existing
        .iter()
        .chain(frames.iter())
        .map(|(f, p)| (format!("frame {f}"), p.as_path()))
        .chain(
            manifest
                .exists()
                .then(|| ("manifest".to_string(), manifest.as_path())),
        );
    let outputs: Vec<(u64, PathBuf)> = frames
        .iter()
        .map(|(f, _)| (*f, out_pattern.path(*f)))
        .collect();
    check_files(
        args,
        &state,
        bricks,
        outputs
            .iter()
            .map(|(f, p)| (format!("-o (frame {f})"), p.as_path())),
    )?;
    match &info.source {
        RangeSource::Manifest(m) => note(&format!(
            "qbricks-view: {shown}: field ranges of the whole sequence from {}",
            m.display()
        )),
        RangeSource::Frames(n) => note(&format!(
            "qbricks-view: {shown}: no manifest ({}), field ranges are the union of the {n} \
             frame(s)' own ranges",
            pattern.manifest_path().display()
        )),
    }
    note(&format!("qbricks-view: {shown}: {}", rule.describe(&state)));
    match framed {
        Some(Framed::Surfaces(n)) => note(&format!(
            "qbricks-view: {shown}: one camera for every frame, on the union of the iso \
             surfaces of {n} frame(s)"
        )),
        Some(Framed::Data) => note(&format!(
            "qbricks-view: {shown}: no frame has an iso surface at its value; the camera \
             frames the union of the frames' data"
        )),
        None => {}
    }
    for (frame, _) in &frames {
        if let Some(o) = own.iter().find(|o| o.frame == *frame) {
            note(&format!("qbricks-view: {o}"));
        } else if let Some(w) = info
            .frame(*frame)
            .and_then(|f| state.iso_outside_range(&f.fields))
        {
            note(&format!("qbricks-view: warning: frame {frame}: {w}"));
        }
    }
    for s in &plan.skipped {
        note(&format!("qbricks-view: warning: {s}"));
    }
    if args.frames.is_none() {
        // Skipped frames were named above: not missing as well.
        let mut numbers: Vec<u64> = frames
            .iter()
            .map(|f| f.0)
            .chain(plan.skipped.iter().map(|s| s.frame))
            .collect();
        numbers.sort_unstable();
        let missing = gaps(&numbers);
        if !missing.is_empty() {
            let list: Vec<String> = missing.iter().take(20).map(u64::to_string).collect();
            note(&format!(
                "qbricks-view: warning: {shown}: {} frame(s) missing: {}{}",
                missing.len(),
                list.join(", "),
                if missing.len() > 20 { ", …" } else { "" }
            ));
        }
    }
    check_frame_memory(state.width, state.height)?;
    for n in notes {
        note(&format!("qbricks-view: note: {n}"));
    }
    let meshes = if state.meshes.is_empty() {
        Meshes::empty()
    } else {
        Meshes::load(&state.meshes)?
    };
    let renderer = Renderer::new(args.threads).context("starting worker threads")?;
    if !out_pattern.dir().as_os_str().is_empty() {
        std::fs::create_dir_all(out_pattern.dir()).with_context(|| {
            format!(
                "{}: cannot create the directory",
                out_pattern.dir().display()
            )
        })?;
    }

    Ok(Prepared {
        state,
        frames,
        own,
        out_pattern,
        meshes,
        renderer,
    })
}
