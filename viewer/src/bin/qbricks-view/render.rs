//! `qbricks-view render`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use format::output::QuietStdout;
use qbricks_viewer::film;
use qbricks_viewer::mesh::Meshes;
use qbricks_viewer::render::{FrameReport, Renderer, Scene};
use qbricks_viewer::view_state::{Overrides, ViewState};
use qbricks_viewer::volume::Volume;

/// The bundled sample, relative to the current directory.
pub const DEFAULT_FILE: &str = "data/wake_small.qbk";

#[derive(clap::Args)]
pub struct Args {
    /// Brick file to render [default: data/wake_small.qbk, relative to the current directory].
    pub file: Option<PathBuf>,
    /// Output PNG (written atomically). Required unless --pixel is given.
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// View state JSON to start from (flags override it).
    #[arg(long)]
    pub state: Option<PathBuf>,
    #[command(flatten)]
    pub view: Overrides,
    /// Worker threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write the effective view state to this JSON file.
    #[arg(long = "save-state")]
    pub save_state: Option<PathBuf>,
    /// Print timing and statistics as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Render this many times; `ms` is the median.
    #[arg(long, default_value_t = 1)]
    pub repeat: u32,
    /// Write a debug buffer instead of the shaded image: the shading normal, the depth,
    /// the finest contributing level or the colour-field value at the iso-surface.
    #[arg(long, value_enum)]
    pub aov: Option<qbricks_viewer::render::Aov>,
    /// Render only pixel X,Y and print its rays' region segments, samples and hits.
    #[arg(long)]
    pub pixel: Option<String>,
}

/// The file argument, or the bundled sample when it exists.
pub fn resolve_file(file: Option<PathBuf>) -> anyhow::Result<PathBuf> {
    match file {
        Some(f) => Ok(f),
        None => {
            let p = PathBuf::from(DEFAULT_FILE);
            if !p.exists() {
                bail!(
                    "{DEFAULT_FILE}: no such file (the default sample is looked up relative to \
                     the current directory; run from the repository root or pass FILE.qbk)"
                );
            }
            Ok(p)
        }
    }
}

pub fn open_volume(path: &Path) -> anyhow::Result<format::BrickFileView> {
    format::BrickFileView::open(path).map_err(anyhow::Error::from)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let path = resolve_file(args.file.clone())?;
    if args.output.is_none() && args.pixel.is_none() {
        bail!("expected -o OUT.png (or --pixel X,Y)");
    }
    if args.repeat == 0 {
        bail!("--repeat: expected at least 1, found 0");
    }

    // Open.
    let t_open = Instant::now();
    let view = open_volume(&path)?;
    let file = view.file();
    let vol = Volume::new(file).with_context(|| format!("{}", path.display()))?;
    let open_ms = t_open.elapsed().as_secs_f64() * 1e3;

    // View state: file or data-derived defaults, then flags.
    let mut state = match &args.state {
        Some(s) => ViewState::load(s)?,
        None => ViewState::default_for_volume(&vol),
    };
    let notes = args
        .view
        .apply(&mut state, args.state.is_some())
        .map_err(|m| anyhow::anyhow!(m))?;
    state
        .validate()
        .map_err(|m| anyhow::anyhow!("view state: {m}"))?;
    if let Some(p) = &args.save_state {
        state.save(p)?;
    }
    for n in notes {
        eprintln!("qbricks-view: note: {n}");
    }
    let meshes = if state.meshes.is_empty() {
        Meshes::empty()
    } else {
        Meshes::load(&state.meshes)?
    };
    let scene = Scene::new(&vol, &state, &meshes).with_context(|| format!("{}", path.display()))?;

    if args.threads == Some(0) {
        bail!("--threads: expected at least 1, found 0");
    }
    let renderer = Renderer::new(args.threads).context("starting worker threads")?;

    // One pixel, explained.
    if let Some(px) = &args.pixel {
        let (x, y) = parse_pixel(px, state.width, state.height)?;
        let trace = renderer.trace_pixel(&scene, x, y);
        writeln!(
            QuietStdout::new(),
            "{}",
            serde_json::to_string_pretty(&trace)?
        )?;
        if args.output.is_none() {
            return Ok(());
        }
    }

    let mut times = Vec::new();
    let mut frame = None;
    for _ in 0..args.repeat {
        let t = Instant::now();
        let f = match args.aov {
            Some(aov) => renderer.install(|| qbricks_viewer::render::render_aov(&scene, aov)),
            None => renderer.render(&scene),
        };
        times.push(t.elapsed().as_secs_f64() * 1e3);
        frame = Some(f);
    }
    let Some(frame) = frame else {
        bail!("nothing rendered");
    };
    times.sort_by(f64::total_cmp);
    let ms = times[times.len() / 2];
    if let Some(out) = &args.output {
        film::save_png(out, frame.width, frame.height, &frame.rgb)?;
    }
    if args.json {
        let report = FrameReport::new(&frame, &state, ms, open_ms, renderer.threads());
        writeln!(QuietStdout::new(), "{}", serde_json::to_string(&report)?)?;
    }
    Ok(())
}

fn parse_pixel(s: &str, w: u32, h: u32) -> anyhow::Result<(u32, u32)> {
    let bad = || anyhow::anyhow!("--pixel: expected X,Y inside {w}x{h}, found `{s}`");
    let (x, y) = s.split_once(',').ok_or_else(bad)?;
    let x: u32 = x.trim().parse().map_err(|_| bad())?;
    let y: u32 = y.trim().parse().map_err(|_| bad())?;
    if x >= w || y >= h {
        return Err(bad());
    }
    Ok((x, y))
}
