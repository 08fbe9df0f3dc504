//! `qbricks-view render`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use qbricks_viewer::camera::Projection;
use qbricks_viewer::mesh::{MeshInstance, Meshes};
use qbricks_viewer::render::{self, effective_strategy, Scene};
use qbricks_viewer::sampling::Strategy;
use qbricks_viewer::transfer::Mode;
use qbricks_viewer::view_state::ViewState;
use qbricks_viewer::volume::Volume;
use qbricks_viewer::{film, probe};

/// The bundled sample, relative to the current directory.
pub const DEFAULT_FILE: &str = "data/wake_small.qbk";

#[derive(clap::Args)]
pub struct Args {
    /// Brick file to render [default: data/wake_small.qbk, relative to the current directory].
    pub file: Option<PathBuf>,
    /// Output PNG (written atomically). Required unless --pixel is given.
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// Image width in pixels.
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels.
    #[arg(long)]
    pub height: Option<u32>,
    /// View state JSON to start from (flags override it).
    #[arg(long)]
    pub state: Option<PathBuf>,
    /// Render mode.
    #[arg(long, value_enum)]
    pub mode: Option<Mode>,
    /// Iso value of the iso field.
    #[arg(long, allow_hyphen_values = true)]
    pub iso: Option<f64>,
    /// Sampling strategy (`exact` is for iso mode; in dvr it samples as `bisect`).
    #[arg(long, value_enum)]
    pub strategy: Option<Strategy>,
    /// Sample step in units of the local cell width.
    #[arg(long, allow_hyphen_values = true)]
    pub step: Option<f64>,
    /// Jittered rays per pixel.
    #[arg(long)]
    pub spp: Option<u32>,
    /// Shadow rays towards every light (through meshes and the volume).
    #[arg(long)]
    pub shadows: bool,
    /// OBJ mesh, optionally placed: PATH[@x,y,z,scale]. Repeatable; replaces the state's meshes.
    #[arg(long = "mesh")]
    pub meshes: Vec<String>,
    /// Camera position x,y,z (world units).
    #[arg(long, allow_hyphen_values = true)]
    pub eye: Option<String>,
    /// Point the camera looks at, x,y,z.
    #[arg(long = "look-at", allow_hyphen_values = true)]
    pub look_at: Option<String>,
    /// Camera up vector x,y,z.
    #[arg(long, allow_hyphen_values = true)]
    pub up: Option<String>,
    /// Orthographic projection with this view width (world units).
    #[arg(long, conflicts_with = "fov")]
    pub ortho: Option<f64>,
    /// Perspective projection with this vertical field of view (degrees).
    #[arg(long)]
    pub fov: Option<f64>,
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

fn parse_vec(name: &str, s: &str) -> anyhow::Result<[f64; 3]> {
    probe::parse_xyz(s).map_err(|e| anyhow::anyhow!("--{name}: {e}"))
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

    // View state: file, defaults, then flags.
    let mut state = match &args.state {
        Some(s) => ViewState::load(s)?,
        None => ViewState::default_for_volume(&vol),
    };
    apply_flags(&mut state, &args)?;
    if args.state.is_none() {
        // Data-derived defaults follow the flags: the default lights stay over the
        // viewer's shoulder when the camera is moved, and the dvr band keeps the seed
        // report's width relative to an iso value given on the command line.
        state.lights = qbricks_viewer::shading::default_lights(&state.camera);
        if args.iso.is_some() && state.iso != 0.0 {
            state.transfer.sigma = 0.08 * state.iso.abs();
        }
    }
    state
        .validate()
        .map_err(|m| anyhow::anyhow!("view state: {m}"))?;
    if let Some(p) = &args.save_state {
        state.save(p)?;
    }
    if state.mode == Mode::Dvr && state.strategy == Strategy::Exact && args.strategy.is_none() {
        // The default strategy (exact) is for iso mode; a dvr request without an explicit
        // strategy gets the one dvr uses anyway, without a note.
        state.strategy = Strategy::Bisect;
    } else if state.mode == Mode::Dvr && state.strategy == Strategy::Exact {
        eprintln!(
            "qbricks-view: note: `exact` is an iso-surface strategy; dvr samples as `bisect`"
        );
    }
    let meshes = if state.meshes.is_empty() {
        Meshes::empty()
    } else {
        Meshes::load(&state.meshes)?
    };
    let scene = Scene::new(&vol, &state, &meshes).with_context(|| format!("{}", path.display()))?;

    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = args.threads {
        if n == 0 {
            bail!("--threads: expected at least 1, found 0");
        }
        builder = builder.num_threads(n);
    }
    let pool = builder.build().context("starting worker threads")?;

    // One pixel, explained.
    if let Some(px) = &args.pixel {
        let (x, y) = parse_pixel(px, state.width, state.height)?;
        let trace = pool.install(|| render::trace_pixel(&scene, x, y));
        println!("{}", serde_json::to_string_pretty(&trace)?);
        if args.output.is_none() {
            return Ok(());
        }
    }

    let mut times = Vec::new();
    let mut frame = None;
    for _ in 0..args.repeat {
        let t = Instant::now();
        let f = pool.install(|| render::render(&scene));
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
        let rays = frame.rays.max(1);
        let j = serde_json::json!({
            "ms": ms,
            "open_ms": open_ms,
            "rays": frame.rays,
            "samples_per_ray": frame.stats.samples as f64 / rays as f64,
            "segments_per_ray": frame.stats.segments as f64 / rays as f64,
            "skipped_per_ray": frame.stats.skipped as f64 / rays as f64,
            "mrays_per_s": frame.rays as f64 / (ms * 1e3),
            "hit_fraction": frame.hits as f64 / rays as f64,
            "width": frame.width,
            "height": frame.height,
            "strategy": effective_strategy(state.mode, state.strategy).as_str(),
            "mode": state.mode.as_str(),
            "threads": pool.current_num_threads(),
        });
        println!("{j}");
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

fn apply_flags(state: &mut ViewState, args: &Args) -> anyhow::Result<()> {
    if let Some(v) = args.width {
        state.width = v;
    }
    if let Some(v) = args.height {
        state.height = v;
    }
    if let Some(v) = args.mode {
        state.mode = v;
    }
    if let Some(v) = args.iso {
        state.iso = v;
    }
    if let Some(v) = args.strategy {
        state.strategy = v;
    }
    if let Some(v) = args.step {
        state.step = v;
    }
    if let Some(v) = args.spp {
        state.spp = v;
    }
    if args.shadows {
        state.shadows = true;
    }
    if !args.meshes.is_empty() {
        state.meshes = args
            .meshes
            .iter()
            .map(|m| MeshInstance::parse(m).map_err(|e| anyhow::anyhow!("--mesh: {e}")))
            .collect::<anyhow::Result<_>>()?;
    }
    if let Some(s) = &args.eye {
        state.camera.eye = parse_vec("eye", s)?;
    }
    if let Some(s) = &args.look_at {
        state.camera.look_at = parse_vec("look-at", s)?;
    }
    if let Some(s) = &args.up {
        state.camera.up = parse_vec("up", s)?;
    }
    if let Some(w) = args.ortho {
        state.camera.projection = Projection::Orthographic { width: w };
    }
    if let Some(f) = args.fov {
        state.camera.projection = Projection::Perspective { fov_deg: f };
    }
    Ok(())
}
